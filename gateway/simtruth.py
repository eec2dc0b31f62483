"""The simulated robot's true pose, integrated beside its simulated controllers.

Where the gateway's odometry is computed from the encoder frames it receives, the truth is
computed from the simulators' exact shaft angles (and the steering actuators' exact angles),
every simulator step, by an odometry of its own: what the robot really did.  ``wheelgate sim``
reports it, so a gateway in another process can be checked against it, and the end-to-end
tests compare the two.  Pure: the caller passes the times.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from gateway.kinematics import Odometry

if TYPE_CHECKING:
    from collections.abc import Sequence

    from gateway.config import GatewayConfig
    from gateway.drives import DriveSet
    from gateway.sim import DeviceSimulator


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
        #: Steered wheels that no actuator turns: their angle is not simulated, so the truth
        #: is unknown for a robot that has any.
        self.unsimulated = tuple(w.name for i, w in enumerate(config.model.wheels)
                                 if w.steered and i not in actuated)
        self.odometry = Odometry(config.model)

    @property
    def available(self) -> bool:
        """Whether the pose can be known (every steered wheel has a simulated actuator)."""
        return not self.unsimulated

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
        if self.available:
            self.odometry.update(self.positions(), now_s, self.steer())

    def snapshot(self, t_s: float, steps: int = 0, late_steps: int = 0) -> dict[str, object]:
        """The state as a JSON-able mapping (the ``state`` line of ``wheelgate sim``)."""
        st = self.odometry.state
        devices = []
        for sim in self.sims:
            m = sim.motor
            devices.append({
                "name": m.wheel, "driver": m.driver, "node_id": m.node_id,
                "armed": sim.model.armed,
                "wheel_rad_s": None if m.steering else sim.wheel_velocity_rad_s,
                "wheel_rad": None if m.steering else sim.wheel_position_rad,
                "steer_rad": sim.steer_rad if m.steering else None,
            })
        return {
            "t": t_s,
            "pose": ({"x": st.pose.x_m, "y": st.pose.y_m, "theta": st.pose.theta_rad}
                     if self.available else None),
            "distance": st.distance_m if self.available else None,
            "steps": steps, "late_steps": late_steps, "devices": devices,
        }


def state_line(state: dict[str, object]) -> str:
    """One compact line of a :meth:`SimTruth.snapshot`."""
    pose = state["pose"]
    head = f"sim t={state['t']:.1f}s"
    if isinstance(pose, dict):
        head += (f" pose x={pose['x']:+.3f} y={pose['y']:+.3f} "
                 f"th={math.degrees(pose['theta']):+.1f}deg")
    parts = [head]
    devices = state["devices"]
    assert isinstance(devices, list)
    for d in devices:
        if d["steer_rad"] is not None:
            value = f"{round(math.degrees(d['steer_rad']), 1) + 0.0:+.1f}deg"
        else:
            value = f"{round(d['wheel_rad_s'], 2) + 0.0:+.2f} rad/s"
        parts.append(f"{d['name']} {value} {'armed' if d['armed'] else 'idle'}")
    return " | ".join(parts)
