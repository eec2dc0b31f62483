"""The :class:`MotorDriver` ABC: the stateful half of every protocol driver.

One driver instance serves every motor of its protocol on one bus (DJI packs four ESCs into
one frame; CANopen has one SYNC per bus).  The loop calls it with plain values and gets frames
back; it never touches the bus itself, so it stays testable without threads or a clock (the
caller passes ``now_s``, monotonic seconds).

Per cycle the loop calls :meth:`MotorDriver.command` with every wheel's speed and sends all the
frames of all drivers as one burst.  Received frames go to :meth:`MotorDriver.on_frame`.
:meth:`MotorDriver.poll` returns housekeeping frames (RTR requests, enable-sequence steps, SYNC)
and evaluates liveness.
"""

from __future__ import annotations

import abc
import collections
import logging
from typing import TYPE_CHECKING, ClassVar

from gateway.core.errors import ConfigError, DecodeError
from gateway.core.options import OptionSpec, validate_block
from gateway.core.protection import Guard, Protection, ProtectionState, WatchdogPolicy
from gateway.core.types import DriveFault, DriveState, MotorConfig, MotorStatus, WheelFeedback

__all__ = ["CONTROLLER_TIMEOUT_OPTION", "MotorDriver", "OptionSpec"]

#: The common ``controller_timeout_s`` key of protocols that cannot set their controller's
#: timeout over CAN: the timeout that was set with the vendor's tool, as a statement.
CONTROLLER_TIMEOUT_OPTION = OptionSpec(
    float,
    0.0,
    minimum=0.0,
    maximum=60.0,
    help="the command timeout set on the controller with the vendor's tool (s), after which "
    "it stops the motor by itself; 0: not stated",
)

if TYPE_CHECKING:
    from collections.abc import Mapping, Sequence

    from gateway.core.types import Frame
    from gateway.drive.filters import CanFilter
    from gateway.sim.device import DeviceSimulator

log = logging.getLogger(__name__)


class MotorDriver(abc.ABC):
    """Stateful protocol driver for a group of motors on one bus.

    Subclasses fill in the hooks; the base keeps feedback, liveness, fault flags and the
    counters of rejected frames so every protocol reports them the same way.

    :param motors: the motors this driver serves, in the order the loop passes speeds.
    :raises ConfigError: if a node ID is out of range or used twice.
    """

    #: Protocol keys accepted in a motor block, with their specs.
    OPTIONS: ClassVar[Mapping[str, OptionSpec]] = {}
    #: Valid node IDs for this protocol (inclusive).
    NODE_ID_RANGE: ClassVar[tuple[int, int]] = (0, 0x3F)
    #: Feedback older than this marks a motor OFFLINE (s); overridable by the ``liveness_s`` key.
    DEFAULT_LIVENESS_S: ClassVar[float] = 0.25
    #: Whether this driver closes the wheels' speed loop on the host from the feedback it
    #: decodes (DJI).  Holding such a wheel at zero speed needs that feedback, so on a fault
    #: about the feedback or the tracking the gateway releases these motors instead.
    HOST_SPEED_LOOP: ClassVar[bool] = False
    #: Whether this driver also commands steering actuators (motors with
    #: :attr:`~gateway.core.types.MotorRole.STEER`): armed in position control, commanded with a
    #: steering angle, reporting that angle (absolute, from ``zero_rad``) as feedback.
    STEERING: ClassVar[bool] = False
    #: The protocol's name in messages about controller-side protection.
    PROTOCOL: ClassVar[str] = "CAN"
    #: What the controller does when its stated timeout expires (:meth:`protection`).
    TIMEOUT_ACTION: ClassVar[str] = "as configured on the controller"
    #: How to set the controller's timeout, for the warning when it is not stated.
    TIMEOUT_FIX: ClassVar[str] = (
        "set a command timeout on the controller with its vendor's tool and state it as "
        "controller_timeout_s"
    )

    def __init__(self, motors: Sequence[MotorConfig]) -> None:
        self.motors: tuple[MotorConfig, ...] = tuple(motors)
        owners: dict[int, str] = {}
        for m in self.motors:
            if m.steering and not self.STEERING:
                raise ConfigError(
                    f"motor {m.wheel!r}: the {m.driver} driver does not command steering "
                    f"actuators"
                )
            where = f"motor {m.wheel!r}.node_id"
            self.validate_node_id(m.node_id, where, m.options)
            if m.node_id in owners:
                raise ConfigError(
                    f"{where}: node {m.node_id} is already used by wheel {owners[m.node_id]!r}"
                )
            owners[m.node_id] = m.wheel
        self._index = {m.node_id: i for i, m in enumerate(self.motors)}
        n = len(self.motors)
        self._feedback: list[WheelFeedback | None] = [None] * n
        self._faults: list[DriveFault] = [DriveFault.NONE] * n
        self._detail: list[str] = [""] * n
        self._armed: list[bool] = [False] * n
        #: Per motor, why its controller-side protection failed under REQUIRED ("" if not).
        self._protection_failed: list[str] = [""] * n
        #: What to do when a protection this driver configures is not confirmed; the drive
        #: set passes the configuration's ``gateway.controller_watchdog``.
        self.watchdog_policy = WatchdogPolicy.REQUIRED
        #: Commands this driver sent that the controller will not follow as given, by reason
        #: (e.g. a VESC speed below its minimum ERPM); shown in ``status``.
        self.command_counts: collections.Counter[str] = collections.Counter()
        #: Frames of this protocol that were rejected, by reason.
        self.rejected: collections.Counter[str] = collections.Counter()
        #: The detail of the last rejection of each reason (the counter's keys are a fixed
        #: set, so garbage traffic cannot grow it).
        self.last_rejection: dict[str, str] = {}
        live = self.motors[0].options.get("liveness_s") if n else None
        #: Feedback older than this (s) marks a motor OFFLINE.
        self.liveness_s = (
            float(live)
            if isinstance(live, (int, float)) and not isinstance(live, bool)
            else self.DEFAULT_LIVENESS_S
        )

    # ----------------------------------------------------------------- configuration

    @classmethod
    def validate_options(cls, raw: Mapping[str, object], where: str) -> dict[str, object]:
        """Validate a motor block's protocol keys and fill in defaults.

        :param raw: the keys of the motor block that are not common to every driver.
        :param where: file and key path for messages, e.g. ``"robot.yaml: wheels[0].motor"``.
        :raises ConfigError: for an unknown key, a missing required key or a bad value.
        """
        return validate_block(raw, cls.OPTIONS, where, "protocol keys for this driver")

    @classmethod
    def node_id_range(cls, options: Mapping[str, object] | None = None) -> tuple[int, int]:
        """Valid node IDs (inclusive) for a motor block with these protocol keys."""
        return cls.NODE_ID_RANGE

    @classmethod
    def validate_node_id(
        cls, node_id: int, where: str, options: Mapping[str, object] | None = None
    ) -> None:
        """Check a node ID against :meth:`node_id_range`.

        :param options: the motor block's validated protocol keys (some protocols widen the
            range, e.g. ODrive with 29-bit identifiers).
        :raises ConfigError: if it is out of range.
        """
        lo, hi = cls.node_id_range(options)
        if not lo <= node_id <= hi:
            raise ConfigError(f"{where}: expected int {lo}..{hi}, got {node_id!r}")

    # ----------------------------------------------------------------- hooks

    @abc.abstractmethod
    def enable(self, now_s: float) -> list[Frame]:
        """Start the enable sequence (clear errors, select velocity mode, or position mode for
        a steering actuator, arm).

        Sequences that wait for answers go on through :meth:`poll` and :meth:`on_frame`.
        """

    @abc.abstractmethod
    def disable(self, now_s: float) -> list[Frame]:
        """Frames that command zero speed and disarm where the protocol can (a steering
        actuator is released where it stands)."""

    @abc.abstractmethod
    def command(self, wheel_rad_s: Sequence[float], now_s: float) -> list[Frame]:
        """Command frames for this cycle.

        :param wheel_rad_s: one setpoint per motor, in :attr:`motors` order: the wheel speed in
            rad/s for a drive motor, the steering angle in rad (from the neutral plane angle,
            counter-clockwise positive) for a steering actuator (:attr:`STEERING` drivers).
        :raises EncodeError: if a setpoint cannot be encoded (the loop limits speeds first).
        """

    @abc.abstractmethod
    def on_frame(self, frame: Frame) -> bool:
        """Take one received frame.

        :return: whether the frame belonged to this driver.  Malformed frames of this protocol
            are counted in :attr:`rejected` and never raise.
        """

    def receive_filters(self) -> tuple[CanFilter, ...] | None:
        """The identifiers this driver's :meth:`on_frame` takes (feedback, replies, the
        controllers' own messages), as receive filters: the kernel drops everything else
        before the gateway sees it (:mod:`gateway.drive.filters`).

        Every frame :meth:`on_frame` would claim must pass them; the built-in drivers are
        checked for that against random frames.  ``None`` (the default) declares nothing:
        the gateway then opens its bus unfiltered.
        """
        return None

    def preview_command(self, wheel_rad_s: Sequence[float]) -> list[Frame]:
        """The frames :meth:`command` would send for these setpoints from a freshly
        enabled driver with no feedback (pure; for ``wheelgate frames`` and tests).

        The default runs a fresh instance; drivers whose frames depend on feedback override it
        and document what they assume.
        """
        fresh = type(self)(self.motors)
        fresh.enable(0.0)
        return fresh.command(wheel_rad_s, 0.0)

    def poll(self, now_s: float) -> list[Frame]:
        """Housekeeping frames due at ``now_s`` (requests, sequence steps, SYNC)."""
        return []

    @classmethod
    @abc.abstractmethod
    def make_simulator(cls, motor: MotorConfig) -> DeviceSimulator:
        """A device simulator that speaks the device side of this protocol for ``motor``."""

    # ----------------------------------------------------------------- protection

    def protection(self, index: int) -> Protection:
        """Motor ``index``'s controller-side protection (:mod:`gateway.core.protection`).

        The default is for protocols that cannot set a timeout over CAN: :attr:`Guard.STATED`
        from the motor's ``controller_timeout_s`` key (:data:`CONTROLLER_TIMEOUT_OPTION`),
        else :attr:`Guard.UNSTATED` with :attr:`TIMEOUT_FIX`.  Drivers that configure it
        themselves, or whose controllers have none, override this.
        """
        stated = self.motors[index].options.get("controller_timeout_s")
        if isinstance(stated, (int, float)) and not isinstance(stated, bool) and stated > 0:
            return Protection(
                Guard.STATED,
                float(stated),
                self.TIMEOUT_ACTION,
                "set on the controller outside wheelgate; stated by controller_timeout_s "
                "(not verifiable over CAN)",
            )
        return Protection(
            Guard.UNSTATED,
            None,
            "unknown",
            f"not stated: nothing known stops this {self.PROTOCOL} motor if wheelgate dies",
            self.TIMEOUT_FIX,
        )

    def uncontrolled_band(self, index: int) -> tuple[float, float] | None:
        """The wheel speeds (rad/s, ``(low, high)``: every ``low < |speed| < high``) that motor
        ``index``'s controller does not speed-control (a VESC below its minimum ERPM stops the
        motor instead); ``None`` (the default) for none.  ``ik`` and ``check`` report it and
        the tracking check expects a stopped wheel there."""
        return None

    def protection_state(self, index: int) -> ProtectionState:
        """Where the configuring of motor ``index``'s protection stands (drivers with
        :attr:`Guard.CONFIGURED` protection override this)."""
        return ProtectionState.NOT_APPLICABLE

    def protection_fault(self, index: int, why: str) -> None:
        """Record that motor ``index``'s protection could not be confirmed: a FAULT
        (:attr:`DriveFault.WATCHDOG`) naming the motor, the protocol and the fix under
        :attr:`WatchdogPolicy.REQUIRED`; a warning under :attr:`WatchdogPolicy.WARN`.

        The fault stays, whatever the controller reports, until
        :meth:`clear_protection_fault` (a new enable).
        """
        m = self.motors[index]
        fix = self.protection(index).fix
        text = (
            f"motor {m.wheel!r} ({self.PROTOCOL} node {m.node_id}): controller watchdog not "
            f"confirmed: {why}" + (f"; fix: {fix}" if fix else "")
        )
        if self.watchdog_policy is WatchdogPolicy.REQUIRED:
            log.error("%s; not arming it (gateway.controller_watchdog: required)", text)
            self._protection_failed[index] = text
            self.set_fault(index, self._faults[index], self._detail[index])
        else:
            log.warning("%s; arming it anyway (gateway.controller_watchdog: warn)", text)

    def clear_protection_fault(self, index: int) -> None:
        """Forget motor ``index``'s protection fault (a new enable tries again)."""
        if self._protection_failed[index]:
            self._protection_failed[index] = ""
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

    def store_feedback(self, index: int, feedback: WheelFeedback) -> None:
        """Record new feedback for motor ``index``."""
        self._feedback[index] = feedback

    def set_fault(self, index: int, faults: DriveFault, detail: str = "") -> None:
        """Record the fault flags (``DriveFault.NONE`` clears) of motor ``index``; a
        protection fault (:meth:`protection_fault`) stays in them."""
        failed = self._protection_failed[index]
        if failed:
            faults |= DriveFault.WATCHDOG
            detail = failed if not detail or detail == failed else f"{failed}; {detail}"
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

    def feedback(self, index: int) -> WheelFeedback | None:
        """Latest feedback of motor ``index``."""
        return self._feedback[index]

    def state(self, index: int, now_s: float) -> DriveState:
        """What the driver believes of motor ``index`` at ``now_s``."""
        fb = self._feedback[index]
        if fb is None or now_s - fb.timestamp_s > self.liveness_s:
            return DriveState.OFFLINE
        if self._faults[index]:
            return DriveState.FAULT
        return DriveState.ENABLED if self._armed[index] else DriveState.DISABLED

    def status(self, now_s: float) -> tuple[MotorStatus, ...]:
        """A snapshot of every motor."""
        # Called every cycle: locals and positional construction (no per-field keywords).
        state, feedback, faults, detail = self.state, self._feedback, self._faults, self._detail
        out = []
        for i, m in enumerate(self.motors):
            fb = feedback[i]
            out.append(
                MotorStatus(
                    m.wheel,
                    m.node_id,
                    state(i, now_s),
                    faults[i],
                    detail[i],
                    None if fb is None else now_s - fb.timestamp_s,
                    fb,
                )
            )
        return tuple(out)
