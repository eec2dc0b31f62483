"""The :class:`MotorDriver` contract: the stateful half of every protocol driver.

One driver instance serves every motor of its protocol on one bus (DJI packs four ESCs into
one frame; CANopen has one SYNC per bus).  The loop calls it with plain values and gets frames
back; it never touches the bus itself, so it stays testable without threads or a clock (the
caller passes ``now_s``, monotonic seconds).

The contract is a template, as python-can's ``BusABC.recv`` wraps ``_recv_internal``: the public
methods do once what every protocol needs (the count, finiteness and range of the setpoints,
malformed-frame counting, liveness, fault flags, the controller-side protection step) and call
small hooks a protocol implements (:meth:`~MotorDriver._command`, :meth:`~MotorDriver._on_frame`,
:meth:`~MotorDriver._enable`, :meth:`~MotorDriver._poll`, :meth:`~MotorDriver._ready_state`).
:meth:`~MotorDriver.claims` declares the protocol's frames: dispatch, receive filters and labels
come from it (:mod:`gateway.drive.claims`).  Protocol keys are a :class:`~gateway.drive.options.
DriverOptions`.  Simulators are registered apart (:mod:`gateway.sim.registry`).
"""

from __future__ import annotations

import abc
import collections
from typing import TYPE_CHECKING, ClassVar, Generic, TypeVar, cast

from gateway.core.errors import DecodeError
from gateway.core.options import OptionSpec
from gateway.core.protection import ProtectionState, WatchdogPolicy
from gateway.core.types import DriveFault, DriveState, MotorConfig, MotorStatus, WheelFeedback
from gateway.drive.guard import FailedProtections, fault_text, may_arm, stated_protection
from gateway.drive.liveness import Liveness
from gateway.drive.options import CONTROLLER_TIMEOUT_OPTION, DriverOptions, check_bus_wide
from gateway.drive.setpoints import bounds, check_motors, check_node_id, count_error, setpoint_error

__all__ = ["CONTROLLER_TIMEOUT_OPTION", "MotorDriver", "OptionSpec"]

if TYPE_CHECKING:
    from collections.abc import Mapping, Sequence

    from gateway.core.protection import Protection
    from gateway.core.types import Frame
    from gateway.drive.claims import FrameClaim
    from gateway.drive.filters import CanFilter
    from gateway.drive.traffic import Traffic

OptT = TypeVar("OptT", bound=DriverOptions)


class MotorDriver(abc.ABC, Generic[OptT]):
    """Stateful protocol driver for a group of motors on one bus (see the module's doc).

    :param motors: the motors this driver serves, in the order the loop passes setpoints.
    :raises ConfigError: if a node ID is out of range or used twice, a protocol key is bad, or
        the motors disagree on a key of :attr:`BUS_WIDE`.
    """

    #: The protocol keys of a motor block (validated into :attr:`opts`).
    Options: ClassVar[type[DriverOptions]] = DriverOptions
    #: Protocol keys accepted in a motor block, with their specs (derived from :attr:`Options`).
    OPTIONS: ClassVar[Mapping[str, OptionSpec]] = DriverOptions.specs()
    #: Keys every motor of one bus must agree on (e.g. a firmware family).
    BUS_WIDE: ClassVar[tuple[str, ...]] = ()
    #: Valid node IDs for this protocol (inclusive).
    NODE_ID_RANGE: ClassVar[tuple[int, int]] = (0, 0x3F)
    #: The only bitrates the controllers can talk at (bit/s; empty: any the bus may have).
    BITRATES: ClassVar[tuple[int, ...]] = ()
    #: The streams whose silence makes a motor OFFLINE (each younger than ``liveness_s``
    #: while alive); stream 0 is the feedback (:meth:`store_feedback`), the others are
    #: reported to :attr:`live` (:meth:`Liveness.heard`).
    LIVENESS_STREAMS: ClassVar[tuple[str, ...]] = ("feedback",)
    #: The liveness stream of the speed when it comes apart from the position (``None``: with
    #: it): a report's feedback age is the older of the two (the feedback has the position's).
    SPEED_STREAM: ClassVar[int | None] = None
    #: How to switch each liveness stream on, by name (:meth:`Liveness.silence`'s hints).
    STREAM_HINTS: ClassVar[Mapping[str, str]] = {}
    #: Whether this driver closes the wheels' speed loop on the host from the feedback it
    #: decodes (DJI).  Holding such a wheel at zero speed needs that feedback, so on a fault
    #: about the feedback or the tracking the gateway releases these motors instead.
    HOST_SPEED_LOOP: ClassVar[bool] = False
    #: Whether this driver also commands steering actuators (motors with
    #: :attr:`~gateway.core.types.MotorRole.STEER`): armed in position control, commanded with
    #: a steering angle, reporting that angle (absolute, from ``zero_rad``) as feedback.
    STEERING: ClassVar[bool] = False
    #: Whether this driver writes its controllers' protection itself (:attr:`Guard.CONFIGURED`
    #: motors report :meth:`protection_state` and :meth:`protection_failure`).
    CONFIGURES_PROTECTION: ClassVar[bool] = False
    #: The reason a malformed frame is counted under (:attr:`rejected`; ``status`` shows it).
    MALFORMED: ClassVar[str] = "malformed"
    #: The protocol's name in messages (protection, labels, errors).
    PROTOCOL: ClassVar[str] = "CAN"
    #: What the controller does when its stated timeout expires (:meth:`protection`).
    TIMEOUT_ACTION: ClassVar[str] = "as configured on the controller"
    #: How to set the controller's timeout, for the warning when it is not stated.
    TIMEOUT_FIX: ClassVar[str] = ("set a command timeout on the controller with its vendor's "
                                  "tool and state it as controller_timeout_s")

    def __init_subclass__(cls, **kwargs: object) -> None:
        super().__init_subclass__(**kwargs)
        if "Options" in cls.__dict__ and "OPTIONS" not in cls.__dict__:
            cls.OPTIONS = cls.Options.specs()

    def __init__(self, motors: Sequence[MotorConfig]) -> None:
        self.motors: tuple[MotorConfig, ...] = tuple(motors)
        check_motors(self.motors, self.STEERING, self.validate_node_id)
        #: Every motor's validated protocol keys, in :attr:`motors` order.
        self.opts: tuple[OptT, ...] = tuple(
            cast("OptT", self.Options.from_block(m.options, f"motor {m.wheel!r}"))
            for m in self.motors
        )
        check_bus_wide(self.motors, self.opts, self.BUS_WIDE, self.PROTOCOL)
        self._index = {m.node_id: i for i, m in enumerate(self.motors)}
        n = len(self.motors)
        self._feedback: list[WheelFeedback | None] = [None] * n
        self._faults: list[DriveFault] = [DriveFault.NONE] * n
        self._detail: list[str] = [""] * n
        self._armed: list[bool] = [False] * n
        #: The controller-side protections that failed, per motor.
        self._failed = FailedProtections(n)
        #: What to do when a protection it configures is not confirmed (the drive set passes
        #: ``gateway.controller_watchdog``).
        self.watchdog_policy = WatchdogPolicy.REQUIRED
        #: Commands sent that the controller will not follow as given, by reason (a VESC
        #: speed below its minimum ERPM, say); shown in ``status``.
        self.command_counts: collections.Counter[str] = collections.Counter()
        #: Frames of this protocol that were rejected, by reason.
        self.rejected: collections.Counter[str] = collections.Counter()
        #: The last rejection's detail per reason (a fixed set: garbage cannot grow it).
        self.last_rejection: dict[str, str] = {}
        #: When each motor's liveness streams were last heard (:attr:`LIVENESS_STREAMS`).
        self.live = Liveness(n, self.LIVENESS_STREAMS, [o.liveness_s for o in self.opts])
        self._heard_s = self.live.oldest
        #: Per motor, the largest setpoint :meth:`command` passes (``setpoints.bounds``).
        self.bounds: tuple[float, ...] = bounds(self.motors)
        #: Per motor, wheel to motor side: ``gear_ratio * sign`` (motor = wheel * scale).
        self.motor_scale: tuple[float, ...] = tuple(m.gear_ratio * m.sign for m in self.motors)

    # ----------------------------------------------------------------- configuration

    @classmethod
    def validate_options(cls, raw: Mapping[str, object], where: str) -> dict[str, object]:
        """Validate a motor block's protocol keys ``raw`` (those not common to every driver)
        and fill in defaults; ``where`` (``"robot.yaml: wheels[0].motor"``) starts the
        messages.  Raises :class:`ConfigError` for an unknown, missing or bad key."""
        return cls.Options.validate(raw, where)

    @classmethod
    def node_id_range(cls, options: Mapping[str, object] | None = None) -> tuple[int, int]:
        """Valid node IDs (inclusive) for a motor block with these protocol keys."""
        return cls.NODE_ID_RANGE

    @classmethod
    def validate_node_id(cls, node_id: int, where: str,
                         options: Mapping[str, object] | None = None) -> None:
        """Check a node ID against :meth:`node_id_range` of the motor block's validated
        protocol keys ``options`` (ODrive widens it with 29-bit identifiers); raises
        :class:`ConfigError` if it is out of range."""
        check_node_id(node_id, where, cls.node_id_range(options))

    # ----------------------------------------------------------------- the template

    def command(self, setpoints: Sequence[float], now_s: float) -> list[Frame]:
        """Command frames for this cycle.

        :param setpoints: one per motor, in :attr:`motors` order: the wheel speed in rad/s for
            a drive motor, the steering angle in rad (from the neutral plane angle,
            counter-clockwise positive) for a steering actuator (:attr:`STEERING` drivers).
        :raises EncodeError: for a number of setpoints other than the number of motors, a
            setpoint that is not finite, or a speed beyond the motor's ``max_rpm``; nothing is
            encoded then.
        """
        bounds = self.bounds
        if len(setpoints) != len(bounds):
            raise count_error(self.motors, len(setpoints), self.PROTOCOL)
        for value, bound in zip(setpoints, bounds):  # noqa: B905 - lengths checked above
            if not -bound <= value <= bound:  # also false for NaN
                raise setpoint_error(self.motors, setpoints, self.PROTOCOL)
        return self._command(setpoints, now_s)

    @abc.abstractmethod
    def _command(self, setpoints: Sequence[float], now_s: float) -> list[Frame]:
        """Hook of :meth:`command`: the frames for setpoints the base has checked."""

    def on_frame(self, frame: Frame) -> bool:
        """Take one received frame; return whether it belonged to this driver.  A malformed
        frame of this protocol (the hook raises :class:`DecodeError`) is counted in
        :attr:`rejected` under :attr:`MALFORMED`, never raised."""
        try:
            return self._on_frame(frame)
        except DecodeError as err:
            self.reject(self.MALFORMED, err)
            return True

    @abc.abstractmethod
    def _on_frame(self, frame: Frame) -> bool:
        """Hook of :meth:`on_frame`: take a frame, or return ``False`` if it is not ours; raise
        :class:`DecodeError` for a malformed frame of ours."""

    def enable(self, now_s: float) -> list[Frame]:
        """Start the enable sequence (clear errors, select velocity mode, or position mode for
        a steering actuator, arm; sequences that wait for answers go on through :meth:`poll`
        and :meth:`on_frame`); the last enable's protection faults are forgotten first.

        :raises IllegalTransitionError: if a controller cannot be enabled now (no frame is sent).
        """
        frames = self._enable(now_s)  # may raise before anything is forgotten
        for i in range(len(self.motors)):
            self.clear_protection_fault(i)
        self._failed.restart()
        return frames

    @abc.abstractmethod
    def _enable(self, now_s: float) -> list[Frame]:
        """Hook of :meth:`enable`: the frames that start the enable sequence."""

    def enable_failed(self) -> list[int]:
        """The motors whose enable sequence ended without arming them (here: a protection
        failed under ``REQUIRED``): waiting changes nothing until the next :meth:`enable`."""
        return [i for i, why in enumerate(self._failed.why) if why]

    @abc.abstractmethod
    def disable(self, now_s: float) -> list[Frame]:
        """Frames that command zero speed and disarm where the protocol can (a steering
        actuator is released where it stands)."""

    def poll(self, now_s: float) -> list[Frame]:
        """Housekeeping frames due at ``now_s`` (requests, sequence steps, SYNC); a protection
        that failed is reported (:meth:`protection_fault`), once per enable (``guard``)."""
        frames = self._poll(now_s)
        if self.CONFIGURES_PROTECTION:
            for i in self._failed.newly_failed(now_s, self.protection_state):
                self.protection_fault(i, self.protection_failure(i))
        return frames

    def _poll(self, now_s: float) -> list[Frame]:
        """Hook of :meth:`poll` (default: nothing to send)."""
        return []

    @abc.abstractmethod
    def claims(self) -> tuple[FrameClaim, ...]:
        """The frames of this driver's motors (:mod:`gateway.drive.claims`): every frame
        :meth:`on_frame` takes must be claimed with ``receive=True``; the frames it only sends
        are claimed with ``receive=False`` (for the labels)."""

    def message_name(self, arbitration_id: int, is_extended_id: bool) -> str | None:
        """The protocol's name of a claimed frame's message (``Get_Encoder_Estimates``), for
        labels; ``None`` when the protocol has none for it."""
        return None

    def receive_filters(self) -> tuple[CanFilter, ...]:
        """The kernel receive filters of the frames :meth:`on_frame` takes (from
        :meth:`claims`; the built-in drivers are checked against random frames for it)."""
        return tuple(dict.fromkeys(c.as_filter() for c in self.claims() if c.receive))

    def traffic(self, rate_hz: float) -> Traffic | None:
        """The periodic frames beyond :meth:`command`'s (the budget takes those from
        :meth:`preview_command`) of these motors at loop rate ``rate_hz``: the controllers'
        own, the driver's other ones (:mod:`gateway.drive.traffic`); ``None``: undeclared."""
        return None

    def preview_command(self, setpoints: Sequence[float]) -> list[Frame]:
        """The frames :meth:`command` would send for these setpoints from a freshly enabled
        driver with no feedback (pure; for ``wheelgate frames`` and tests): a fresh instance's;
        drivers whose frames depend on feedback override it and say what they assume."""
        fresh = type(self)(self.motors)
        fresh.enable(0.0)
        return fresh.command(setpoints, 0.0)

    # ----------------------------------------------------------------- protection

    def protection(self, index: int) -> Protection:
        """Motor ``index``'s controller-side protection (:mod:`gateway.core.protection`).
        The default, for protocols that cannot set a timeout over CAN: :attr:`Guard.STATED`
        from ``controller_timeout_s`` (:data:`CONTROLLER_TIMEOUT_OPTION`), else
        :attr:`Guard.UNSTATED` with :attr:`TIMEOUT_FIX`; other drivers override this."""
        return stated_protection(self.PROTOCOL, self.TIMEOUT_ACTION, self.TIMEOUT_FIX, getattr(
            self.opts[index], "controller_timeout_s", None) or 0.0)

    def doubts(self) -> tuple[str, ...]:
        """What the driver doubts in a valid configuration (``check`` and ``run`` warn)."""
        return ()

    def uncontrolled_band(self, index: int) -> tuple[float, float] | None:
        """The wheel speeds (rad/s, ``(low, high)``: every ``low < |speed| < high``) that motor
        ``index``'s controller does not speed-control (a VESC below its minimum ERPM stops the
        motor instead); ``None`` (the default) for none.  ``ik`` and ``check`` report it and
        the tracking check expects a stopped wheel there."""
        return None

    def protection_state(self, index: int) -> ProtectionState:
        """Where the configuring of motor ``index``'s protection stands (drivers with
        :attr:`CONFIGURES_PROTECTION` override this)."""
        return ProtectionState.NOT_APPLICABLE

    def protection_failure(self, index: int) -> str:
        """Why motor ``index``'s protection failed (what came back), for the fault text."""
        return "not confirmed"

    def may_arm(self, index: int) -> bool:
        """Whether motor ``index`` may be armed as far as its protection goes: confirmed, not
        configured by this driver, or failed under :attr:`WatchdogPolicy.WARN`."""
        return may_arm(self.protection_state(index), self.watchdog_policy)

    def protection_fault(self, index: int, why: str) -> None:
        """Record that motor ``index``'s protection could not be confirmed: a FAULT
        (:attr:`DriveFault.WATCHDOG`) naming the motor, the protocol and the fix under
        :attr:`WatchdogPolicy.REQUIRED`, which stays whatever the controller reports until
        :meth:`clear_protection_fault` (a new enable); a warning under ``WARN``."""
        m = self.motors[index]
        text = fault_text(m.wheel, self.PROTOCOL, m.node_id, why, self.protection(index).fix)
        if self._failed.fail(index, text, self.watchdog_policy):
            self.set_fault(index, self._faults[index], self._detail[index])

    def clear_protection_fault(self, index: int) -> None:
        """Forget motor ``index``'s protection fault (a new enable tries again)."""
        if self._failed.why[index]:
            self._failed.why[index] = ""
            self.set_fault(index, self._faults[index] & ~DriveFault.WATCHDOG, "")

    # ----------------------------------------------------------------- shared state

    def reject(self, reason: str, err: DecodeError | None = None) -> None:
        """Count a rejected frame under ``reason``."""
        self.rejected[reason] += 1
        if err is not None:
            self.last_rejection[reason] = str(err)

    def index_of(self, node_id: int) -> int | None:
        """The position of ``node_id`` in :attr:`motors`, or ``None``."""
        return self._index.get(node_id)

    def store_feedback(self, index: int, feedback: WheelFeedback, stream: int | None = 0) -> None:
        """Record new feedback for motor ``index``, and stream ``stream`` heard at its time
        (``None``: the caller reports the streams to :attr:`live`)."""
        self._feedback[index] = feedback
        if stream is not None:
            self.live.heard(index, stream, feedback.timestamp_s)

    def set_fault(self, index: int, faults: DriveFault, detail: str = "") -> None:
        """Record motor ``index``'s fault flags (NONE clears); a protection fault stays in them."""
        if self._failed.why[index]:
            faults |= DriveFault.WATCHDOG
            detail = self._failed.merged(index, detail)
        self._faults[index] = faults
        self._detail[index] = detail

    def set_armed(self, index: int, armed: bool) -> None:
        """Record whether motor ``index`` is armed."""
        self._armed[index] = armed

    def is_armed(self, index: int) -> bool:
        """Whether motor ``index`` is armed."""
        return self._armed[index]

    def faults(self, index: int) -> DriveFault:
        """The fault flags of motor ``index``."""
        return self._faults[index]

    def detail(self, index: int) -> str:
        """The fault text of motor ``index`` (empty when healthy)."""
        return self._detail[index]

    def feedback(self, index: int) -> WheelFeedback | None:
        """Latest feedback of motor ``index``."""
        return self._feedback[index]

    def feedbacks(self) -> list[WheelFeedback | None]:
        """Latest feedback of every motor, in :attr:`motors` order (a new list)."""
        return self._feedback[:]

    def state(self, index: int, now_s: float) -> DriveState:
        """What the driver believes of motor ``index`` at ``now_s``: OFFLINE while a liveness
        stream is silent, FAULT while fault flags are set, else :meth:`_ready_state`."""
        return self.states(now_s)[index]

    def states(self, now_s: float) -> list[DriveState]:
        """:meth:`state` of every motor, in one call."""
        limits, faults, ready = self.live.limits, self._faults, self._ready_state
        return [DriveState.OFFLINE if t is None or now_s - t > limits[i]
                else DriveState.FAULT if faults[i] else ready(i)
                for i, t in enumerate(self._heard_s)]

    def troubled(self, now_s: float) -> bool:
        """Whether any motor is OFFLINE or FAULT at ``now_s`` (asked every cycle, cheaply)."""
        return not self.live.all_alive(now_s) or any(self._faults)

    def _ready_state(self, index: int) -> DriveState:
        """Hook of :meth:`state` for a live motor without faults: ENABLED if armed, else
        DISABLED (drivers with an enable sequence add ENABLING)."""
        return DriveState.ENABLED if self._armed[index] else DriveState.DISABLED

    def status(self, now_s: float) -> tuple[MotorStatus, ...]:
        """A snapshot of every motor, for reports."""
        return tuple(
            MotorStatus(m.wheel, m.node_id, st, self._faults[i], self._detail[i],
                        None if fb is None
                        else self.live.age(i, fb.timestamp_s, self.SPEED_STREAM, now_s), fb,
                        "" if st is not DriveState.OFFLINE
                        else self.live.silence(i, now_s, self.STREAM_HINTS))
            for i, (m, fb, st) in enumerate(
                zip(self.motors, self._feedback, self.states(now_s), strict=True))
        )
