"""The motors of one robot grouped by protocol: one driver instance per driver name.

:class:`DriveSet` is what the loop and the CLI talk to: it takes every wheel's speed in model
order, hands each driver the speeds of its own motors and returns all frames of the cycle in
one list (moteus' "build all, then send once"), so no two wheels act on commands from different
cycles.

Steering actuators (``steering:`` blocks) join the driver of their protocol, after its drive
motors: a driver serves every motor of its protocol on the bus, whatever each one does (DJI packs
four ESCs into one frame, CANopen has one SYNC per bus).  Their setpoint is the steering angle of
the first wheel they turn (wheels steered together share it; through an Ackermann linkage, the
virtual middle wheel's angle, :mod:`gateway.core.linkage`), and their feedback is the measured
angle,
which the odometry uses in place of the commanded one (:meth:`DriveSet.measured_steer`).
"""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING, Any, TypeVar

from gateway.core.errors import GatewayError
from gateway.core.linkage import virtual_angle, wheel_angle
from gateway.drive.claims import FrameRouter
from gateway.drive.registry import get_driver_class

if TYPE_CHECKING:
    from collections.abc import Callable, Sequence

    from gateway.core.protection import Protection
    from gateway.core.settings import GatewayConfig
    from gateway.core.types import DriveState, Frame, MotorConfig, MotorStatus, WheelFeedback
    from gateway.drive.driver import MotorDriver
    from gateway.drive.filters import CanFilter
    from gateway.drive.traffic import Stream, Traffic

log = logging.getLogger(__name__)
_T = TypeVar("_T")


class DriveSet:
    """Every driven wheel's driver, and every steering actuator's.

    :param config: the validated configuration.
    :raises DriverNotFoundError: if a driver cannot be loaded.
    """

    def __init__(self, config: GatewayConfig) -> None:
        self.config = config
        n = len(config.motors)
        # Setpoint slots: 0..n-1 are the wheels' speeds (model order), n + k the steering angle
        # of actuator k.
        slots: list[MotorConfig | None] = [*config.motors, *config.steering]
        groups: dict[str, list[int]] = {}
        for i, motor in enumerate(slots):
            if motor is not None:
                groups.setdefault(motor.driver, []).append(i)
        #: (driver, setpoint slots) pairs: a slot below the number of wheels is that wheel's
        #: speed (model order); slot ``wheels + k`` is steering actuator ``k``'s angle.
        self.groups: tuple[tuple[MotorDriver[Any], tuple[int, ...]], ...] = tuple(
            (
                get_driver_class(name)([m for m in (slots[i] for i in idx) if m is not None]),
                tuple(idx),
            )
            for name, idx in groups.items()
        )
        for drv, _ in self.groups:
            drv.watchdog_policy = config.loop.controller_watchdog
        #: Who owns a received frame, from every driver's claims.
        self._router: FrameRouter[MotorDriver[Any]] = FrameRouter(
            (drv, drv.claims()) for drv, _ in self.groups
        )
        #: ``(identifier, extended)`` -> the owning driver's ``on_frame``, for every exactly
        #: claimed identifier: the loop's per-frame dispatch (:meth:`on_frame` for the rest).
        self.takers: dict[tuple[int, bool], Callable[[Frame], bool]] = {
            key: drv.on_frame for key, drv in self._router.exact().items()
        }
        index = config.model.index
        #: Per steering actuator, the model indices of the wheels it turns.
        self.steered_by: tuple[tuple[int, ...], ...] = tuple(
            tuple(index(w) for w in a.steers) for a in config.steering
        )
        wheels = config.model.wheels
        #: Per steering actuator, ``None`` (direct) or, for an Ackermann linkage, the axle's
        #: x and each of its wheels' y (m, body frame).
        self._linkage: tuple[tuple[float, tuple[float, ...]] | None, ...] = tuple(
            (wheels[ix[0]].x, tuple(wheels[i].y for i in ix)) if a.linkage == "ackermann"
            else None
            for a, ix in zip(config.steering, self.steered_by, strict=True)
        )
        #: The wheels the last :meth:`disable` could not build a stop for (a driver failed).
        self.unstopped: tuple[str, ...] = ()
        #: Whether any driver closes its speed loop on the host (see MotorDriver).
        self.host_speed_loop = any(drv.HOST_SPEED_LOOP for drv, _ in self.groups)
        #: The longest ``liveness_s`` of any motor (0.0 without motors): how long the
        #: odometry's whole rounds wait for a wheel (:class:`gateway.core.odom_feed.OdomFeed`).
        self.liveness_s = max((drv.live.liveness_s for drv, _ in self.groups), default=0.0)
        flat = [i for _, idx in self.groups for i in idx]
        #: The one driver, when it has every wheel in model order and nothing else (the
        #: per-cycle calls go straight to it); else ``None``.
        self._only = (self.groups[0][0] if len(self.groups) == 1 and flat == list(range(n))
                      else None)
        #: Positions in the drivers' concatenated status that give model order (``None``:
        #: already in model order), so :meth:`status` needs no sort per cycle.
        self._status_order: tuple[int, ...] | None = (
            None if flat == sorted(flat) else tuple(sorted(range(len(flat)), key=flat.__getitem__))
        )

    def steer_setpoints(self, steer_rad: Sequence[float | None]) -> list[float]:
        """Every steering actuator's setpoint for these wheel angles (model order)."""
        out = []
        for ix, link in zip(self.steered_by, self._linkage, strict=True):
            if link is None:
                out.append(steer_rad[ix[0]] or 0.0)
                continue
            # Every wheel of an inverse-kinematics solve gives the same virtual angle, except
            # when a wheel stopped at its limit (a twist too slow to slip beyond the
            # tolerance): then the smallest keeps every wheel within its limits.
            candidates = [virtual_angle(steer_rad[i] or 0.0, link[0], y)
                          for i, y in zip(ix, link[1], strict=True)]
            out.append(min(candidates, key=abs))
        return out

    def wheel_angles(self, actuator: int, angle: float) -> list[tuple[int, float]]:
        """(model index, steering angle) of every wheel that steering actuator ``actuator``
        turns, with the actuator at ``angle`` (rad)."""
        ix, link = self.steered_by[actuator], self._linkage[actuator]
        if link is None:
            return [(i, angle) for i in ix]
        return [(i, wheel_angle(angle, link[0], y)) for i, y in zip(ix, link[1], strict=True)]

    def _split(
        self, wheel_rad_s: Sequence[float], steer_rad: Sequence[float | None] | None
    ) -> list[Sequence[float]]:
        setpoints = list(wheel_rad_s)
        if self.steered_by:
            if steer_rad is None:
                raise ValueError(
                    f"Expected the wheels' steering angles for the {len(self.steered_by)} "
                    f"steering actuators, but got None."
                )
            setpoints.extend(self.steer_setpoints(steer_rad))
        return [[setpoints[i] for i in idx] for _, idx in self.groups]

    def enable(self, now_s: float) -> list[Frame]:
        """Enable frames of every driver, or none: when a driver refuses, those before it are
        disabled again (their enable frames are never sent, so their controllers stay as they
        were) and the refusal is raised.

        :raises IllegalTransitionError: from the driver that refuses.
        """
        out: list[Frame] = []
        for k, (drv, _) in enumerate(self.groups):
            try:
                out.extend(drv.enable(now_s))
            except GatewayError:
                for before, _ in self.groups[:k]:
                    before.disable(now_s)
                raise
        return out

    def disable(self, now_s: float) -> list[Frame]:
        """Zero-speed and disarm frames of every driver.

        The stop is the one step that must reach every motor it can: a driver that fails to
        build its frames (a defect, whatever it raises) is logged with the wheels it leaves
        without a stop (kept in :attr:`unstopped`), and the other drivers' frames still go
        out.
        """
        out: list[Frame] = []
        unstopped: list[str] = []
        for drv, _ in self.groups:
            try:
                out.extend(drv.disable(now_s))
            except Exception:  # see the docstring; logged with its traceback
                log.exception("%s could not build the stop of %s; the other drivers' stop "
                              "goes out", type(drv).__name__,
                              ", ".join(repr(m.wheel) for m in drv.motors))
                unstopped.extend(m.wheel for m in drv.motors)
        self.unstopped = tuple(unstopped)
        return out

    def command(
        self,
        wheel_rad_s: Sequence[float],
        now_s: float,
        steer_rad: Sequence[float | None] | None = None,
    ) -> list[Frame]:
        """This cycle's frames for every wheel (model order, rad/s) and steering actuator.

        :param steer_rad: every wheel's steering angle (model order, ``None`` for wheels not
            steered); needed when there are steering actuators.
        """
        if self._only is not None:
            return self._only.command(wheel_rad_s, now_s)
        out: list[Frame] = []
        setpoints = self._split(wheel_rad_s, steer_rad)
        for (drv, _), values in zip(self.groups, setpoints, strict=True):
            out.extend(drv.command(values, now_s))
        return out

    def preview(
        self, wheel_rad_s: Sequence[float], steer_rad: Sequence[float | None] | None = None
    ) -> list[Frame]:
        """The frames for these speeds and angles with every driver freshly enabled and no
        feedback (what ``wheelgate frames`` prints)."""
        out: list[Frame] = []
        setpoints = self._split(wheel_rad_s, steer_rad)
        for (drv, _), values in zip(self.groups, setpoints, strict=True):
            out.extend(drv.preview_command(values))
        return out

    def traffic(self, rate_hz: float | None = None) -> Traffic:
        """Every driver's periodic frames at loop rate ``rate_hz`` (else ``gateway.rate_hz``;
        :mod:`gateway.drive.traffic`): its commands every cycle
        (:meth:`MotorDriver.preview_command` of standing wheels, steering actuators at their
        neutral angles), then what it declares (:meth:`MotorDriver.traffic`), or that it
        declares nothing."""
        from gateway.drive.traffic import Sender, Traffic, frame_streams  # noqa: PLC0415 - check and run only

        rate = self.config.loop.rate_hz if rate_hz is None else rate_hz
        streams: list[Stream] = []
        unknown: list[str] = []
        zeros = [0.0] * len(self.config.motors)
        steer = [0.0] * len(self.config.model.wheels) if self.steered_by else None
        for (drv, _), values in zip(self.groups, self._split(zeros, steer), strict=True):
            streams += frame_streams(drv.preview_command(values), rate, drv.message_name,
                                     Sender.GATEWAY, f"every cycle (gateway.rate_hz {rate:g})")
            declared = drv.traffic(rate)
            if declared is None:
                unknown.append(f"the frames of the {drv.PROTOCOL} controllers (their driver "
                               f"declares none)")
            else:
                streams += declared.streams
                unknown += declared.unknown
        return Traffic(tuple(streams), tuple(unknown))

    def poll(self, now_s: float) -> list[Frame]:
        """Housekeeping frames of every driver."""
        if self._only is not None:
            return self._only.poll(now_s)
        return [f for drv, _ in self.groups for f in drv.poll(now_s)]

    def on_frame(self, frame: Frame) -> bool:
        """Give a received frame to the driver that claims it (:mod:`gateway.drive.claims`):
        one dictionary lookup, whatever the number of drivers.

        :return: whether a driver took it.
        """
        drv = self._router.owner(frame.arbitration_id, frame.is_extended_id)
        return drv is not None and drv.on_frame(frame)

    def receive_filters(self) -> tuple[CanFilter, ...]:
        """The receive filters of every driver (:meth:`MotorDriver.receive_filters`), in
        driver order without repeats: whatever :meth:`on_frame` would give a driver passes."""
        return tuple(dict.fromkeys(f for drv, _ in self.groups for f in drv.receive_filters()))

    def protections(self) -> list[tuple[str, Protection]]:
        """Every motor's controller-side protection (:mod:`gateway.core.protection`), labelled
        ``motor 'wheel' (driver node N)``, in the drivers' order."""
        return [
            (f"motor {m.wheel!r} ({m.driver} node {m.node_id})", drv.protection(i))
            for drv, _ in self.groups
            for i, m in enumerate(drv.motors)
        ]

    def doubts(self) -> list[str]:
        """What the drivers doubt in the configuration (:meth:`MotorDriver.doubts`)."""
        return [d for drv, _ in self.groups for d in drv.doubts()]

    def uncontrolled_bands(self) -> list[tuple[float, float] | None]:
        """Per wheel (model order; ``None`` for a passive wheel or none), the speeds its
        controller does not speed-control (:meth:`MotorDriver.uncontrolled_band`)."""
        out: list[tuple[float, float] | None] = [None] * len(self.config.motors)
        for drv, idx in self.groups:
            for i, slot in enumerate(idx):  # the driver's motors are its slots, in order
                if slot < len(out):
                    out[slot] = drv.uncontrolled_band(i)
        return out

    def status(self, now_s: float) -> list[MotorStatus]:
        """Every motor's status: the drive motors in model order of their wheels, then the
        steering actuators in the order of the ``steering:`` blocks.  For reports and fault
        messages; the loop reads :meth:`states` and :meth:`motor_feedback` every cycle."""
        out: list[MotorStatus] = []
        for drv, idx in self.groups:
            statuses = drv.status(now_s)
            if len(statuses) != len(idx):
                raise ValueError(
                    f"{type(drv).__name__}.status returned {len(statuses)} motors, "
                    f"expected {len(idx)}"
                )
            out.extend(statuses)
        return self._in_status_order(out)

    def troubled(self, now_s: float) -> bool:
        """Whether any motor may be OFFLINE or FAULT (:meth:`MotorDriver.troubled`)."""
        if self._only is not None:
            return self._only.troubled(now_s)
        return any(drv.troubled(now_s) for drv, _ in self.groups)

    def states(self, now_s: float) -> list[DriveState]:
        """Every motor's state (:meth:`MotorDriver.state`), in the order of :meth:`status`,
        without building a status per motor (the supervisor reads it when :meth:`troubled`)."""
        out: list[DriveState] = []
        for drv, _ in self.groups:
            out += drv.states(now_s)
        return self._in_status_order(out)

    def enable_failed(self) -> list[int]:
        """The motors whose enable sequence failed (:meth:`MotorDriver.enable_failed`), as
        positions in the order of :meth:`status`."""
        failed: list[bool] = []
        for drv, idx in self.groups:
            mine = drv.enable_failed()
            failed += [i in mine for i in range(len(idx))]
        return [j for j, f in enumerate(self._in_status_order(failed)) if f]

    def _in_status_order(self, per_driver: list[_T]) -> list[_T]:
        """Values of every motor, driver by driver, in the order of :meth:`status`."""
        order = self._status_order
        return per_driver if order is None else [per_driver[k] for k in order]

    def motor_feedback(self) -> list[WheelFeedback | None]:
        """Every motor's latest feedback (:meth:`MotorDriver.feedback`; ``None``: none yet),
        in the order of :meth:`status`."""
        if self._only is not None:
            return self._only.feedbacks()
        out: list[WheelFeedback | None] = []
        for drv, _ in self.groups:
            out += drv.feedbacks()
        return self._in_status_order(out)

    def feedback_by_wheel(self) -> list[WheelFeedback | None]:
        """The latest feedback of every wheel in model order (``None``: passive or none yet)."""
        if self._only is not None:
            # One driver for every wheel, in model order: its motors are the wheels.
            return self._only.feedbacks()
        out = self._slot_feedback()
        return out[: len(self.config.motors)] if self.steered_by else out

    def steer_feedback(self) -> list[WheelFeedback | None]:
        """The latest feedback of every steering actuator (``None``: none yet)."""
        return self._slot_feedback()[len(self.config.motors):]

    def _slot_feedback(self) -> list[WheelFeedback | None]:
        """The latest feedback of every setpoint slot (the wheels, then the actuators)."""
        out: list[WheelFeedback | None] = [None] * (len(self.config.motors) + len(self.steered_by))
        for drv, idx in self.groups:
            for i, fb in zip(idx, drv.feedbacks(), strict=True):
                out[i] = fb
        return out

    def measured_steer(
        self, commanded: tuple[float | None, ...]
    ) -> tuple[float | None, ...]:
        """Every wheel's steering angle: measured by its actuator where it has one that has
        reported, else ``commanded`` (returned as is when no actuator has reported)."""
        if not self.steered_by:
            return commanded
        out: list[float | None] | None = None
        for k, fb in enumerate(self.steer_feedback()):
            if fb is None:
                continue
            if out is None:
                out = list(commanded)
            for i, angle in self.wheel_angles(k, fb.position_rad):
                out[i] = angle
        return commanded if out is None else tuple(out)

    def all_motors(self) -> list[MotorConfig]:
        """Every motor, driver by driver (the order :func:`gateway.sim.registry.simulators_for`
        gets them in for a robot's simulated controllers)."""
        return [m for drv, _ in self.groups for m in drv.motors]
