"""The simulated robot's true pose, integrated beside its simulated controllers.

Where the gateway's odometry is computed from the encoder frames it receives, the truth is
computed from the simulators' exact shaft angles (and the steering actuators' exact angles),
every simulator step, by an odometry of its own: what the robot really did.  ``wheelgate sim``
reports it, so a gateway in another process can be checked against it, and the end-to-end
tests compare the two.  A robot with steered wheels that no simulated actuator turns has a
truth only when its other wheels fix the twist on their own, as in a replayed log
(:func:`gateway.core.steer_log.fixed_subset`).  Pure: the caller passes the times.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

from gateway.core.kinematics.odometry import Odometry
from gateway.core.numfmt import fixed
from gateway.core.steer_log import fixed_subset

if TYPE_CHECKING:
    from collections.abc import Sequence

    from gateway.core.settings import GatewayConfig
    from gateway.drive.driveset import DriveSet
    from gateway.sim.device import DeviceSimulator


class SimTruth:
    """Ground truth of a simulated robot.

    :param config: the robot.
    :param drives: its drive set (for the steering actuators' linkages).
    :param sims: the device simulators, as :meth:`DriveSet.simulators` made them.
    """

    def __init__(self, config: GatewayConfig, drives: DriveSet,
                 sims: Sequence[DeviceSimulator]) -> None:
        self.config = config
        self.drives = drives
        self.sims = tuple(sims)
        index = {s.motor.wheel: k for k, s in enumerate(self.sims) if not s.motor.steering}
        #: Per wheel (model order), the simulator that turns it (``None``: passive).
        self.wheel_sims = [index.get(w.name) for w in config.model.wheels]
        #: Per simulator of a steering actuator, its index in ``config.steering``.
        self.actuators = [(k, config.steering.index(s.motor))
                          for k, s in enumerate(self.sims) if s.motor.steering]
        actuated = {i for _, a in self.actuators for i in drives.steered_by[a]}
        #: Steered wheels that no actuator turns (castors, wheels steered outside the
        #: gateway): their angle is not simulated.
        self.unsimulated = tuple(w.name for i, w in enumerate(config.model.wheels)
                                 if w.steered and i not in actuated)
        #: With such wheels, the wheels that are not steered when they fix the twist on their
        #: own (the differential drive with a castor): the truth is then theirs, exactly.
        self.fixed: tuple[int, ...] | None = None
        model = config.model
        if self.unsimulated:
            subset = fixed_subset(config)
            if subset is not None:
                self.fixed, model = subset
        self.odometry = Odometry(model)

    @property
    def available(self) -> bool:
        """Whether the pose can be known: every steered wheel has a simulated actuator, or the
        wheels that are not steered fix the twist without them."""
        return not self.unsimulated or self.fixed is not None

    def positions(self) -> list[float | None]:
        """Every wheel's true angle (model order; ``None``: passive)."""
        return [None if k is None else self.sims[k].wheel_position_rad for k in self.wheel_sims]

    def steer(self) -> tuple[float | None, ...] | None:
        """Every wheel's true steering angle (``None`` per wheel not steered)."""
        if not self.actuators:
            return None
        out: list[float | None] = [0.0 if w.steered else None for w in self.config.model.wheels]
        for k, a in self.actuators:
            for i, angle in self.drives.wheel_angles(a, self.sims[k].steer_rad):
                out[i] = angle
        return tuple(out)

    def update(self, now_s: float) -> None:
        """Integrate the motion since the last update (call it after every simulator step)."""
        if self.fixed is not None:
            positions = self.positions()
            self.odometry.update([positions[i] for i in self.fixed], now_s)
        elif not self.unsimulated:
            self.odometry.update(self.positions(), now_s, self.steer())

    def snapshot(self, t_s: float, steps: int = 0, late_steps: int = 0) -> dict[str, object]:
        """The state as a JSON-able mapping (the ``state`` line of ``wheelgate sim``).

        Per device: ``armed``; ``wheel_rad_s`` and ``wheel_rad``, its output shaft's speed and
        angle (the motor's through gear ratio and sign: a wheel's, or a steering actuator's
        shaft); ``steer_rad``, a steering actuator's steering angle (``None`` for a drive
        motor).  ``pose`` and ``distance`` are ``None`` when the truth is not
        :attr:`available`.
        """
        st = self.odometry.state
        devices = []
        for sim in self.sims:
            m = sim.motor
            devices.append({
                "name": m.wheel, "node_id": m.node_id, "armed": sim.model.armed,
                "wheel_rad_s": sim.wheel_velocity_rad_s + 0.0,
                "wheel_rad": sim.wheel_position_rad + 0.0,
                "steer_rad": sim.steer_rad + 0.0 if m.steering else None,
            })
        return {
            "t": t_s,
            "pose": ({"x": st.pose.x_m + 0.0, "y": st.pose.y_m + 0.0,
                      "theta": st.pose.theta_rad + 0.0} if self.available else None),
            "distance": st.distance_m if self.available else None,
            "steps": steps, "late_steps": late_steps, "devices": devices,
        }


def state_line(state: dict[str, Any], prefix: str = "sim") -> str:
    """One compact line of a :meth:`SimTruth.snapshot`: time, pose (``unknown`` without the
    truth), then per device its wheel speed, or a steering actuator's angle, and whether it
    is armed."""
    pose = state["pose"]
    head = f"{prefix} t={state['t']:.1f}s pose "
    if pose is None:
        head += "unknown"
    else:
        head += (f"x={fixed(pose['x'], 3, sign=True)} y={fixed(pose['y'], 3, sign=True)} "
                 f"th={fixed(math.degrees(pose['theta']), 1, sign=True)}deg")
    parts = [head]
    for d in state["devices"]:
        if d["steer_rad"] is not None:
            value = f"{fixed(math.degrees(d['steer_rad']), 1, sign=True)}deg"
        else:
            value = f"{fixed(d['wheel_rad_s'], 2)} rad/s"
        parts.append(f"{d['name']} {value} {'armed' if d['armed'] else 'idle'}")
    return " | ".join(parts)
