"""One motor of the CiA 402 driver: what the driver knows of its drive, what each message the
drive sends does to that, and the target of its command RPDO.

:class:`Axis` is the one record per motor of :class:`~drivers.cia402.driver.Cia402Driver`: its
enable/stop sequence (:mod:`drivers.cia402.sequence`), the NMT state of its last heartbeat, its
active EMCY, its position counter (int32 readings of 0x6064 unwrapped modulo 2^32,
:func:`~drivers.cia402.targets.wrap_delta`) and, for a steering actuator, the target position
that slews toward the commanded angle (:mod:`drivers.cia402.targets`).  Its methods are the
receive side of the driver: a feedback TPDO (:meth:`Axis.on_pdo`), a heartbeat or boot-up
(:meth:`Axis.on_heartbeat`), an EMCY (:meth:`Axis.on_emcy`); and what the driver reports of the
motor (:meth:`Axis.fault`).

Reference: CiA 301 (heartbeat, boot-up, EMCY) and CiA 402 (statusword, 0x6064, 0x606C).
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from drivers.cia402.codec import INT32_RANGE, position_to_raw, velocity_to_raw
from drivers.cia402.enums import NmtState, State, state_from_statusword
from drivers.cia402.faults import describe_emcy, emcy_faults, is_error_reset
from drivers.cia402.phase import Phase
from drivers.cia402.targets import target_counts
from gateway.core.errors import DecodeError
from gateway.core.protection import ProtectionState
from gateway.core.types import DriveFault, WheelFeedback
from gateway.drive.liveness import still_comes

if TYPE_CHECKING:
    from drivers.cia402.codec import Emergency
    from drivers.cia402.options import Cia402Options
    from drivers.cia402.sequence import NodeSequencer
    from gateway.core.types import MotorConfig

log = logging.getLogger(__name__)

#: The phases of an enable sequence under way (the motor is ENABLING).
ENABLING = frozenset({Phase.CONFIGURING, Phase.AWAIT_STATUS, Phase.WALKING})
#: States that are a fault of the drive.
_FAULT_STATES = (State.FAULT, State.FAULT_REACTION_ACTIVE)
_TWO_PI = 2.0 * math.pi
_RPM_PER_RAD_S = 60.0 / (2.0 * math.pi)
_RAD_S_PER_RPM = 2.0 * math.pi / 60.0
_I32_MIN, _I32_MAX = INT32_RANGE
_HALF_SPAN, _SPAN = 1 << 31, 1 << 32


@dataclass(slots=True)
class Axis:
    """One motor of the driver.

    :param motor: its motor block.
    :param opts: its protocol keys.
    :param seq: its enable/stop sequence.
    :param rpdo_id: the COB-ID of its command RPDO.
    """

    motor: MotorConfig
    opts: Cia402Options
    seq: NodeSequencer
    rpdo_id: int
    #: A steering actuator (cyclic synchronous position): absolute position, target in RPDO.
    steer: bool = field(init=False)
    #: Motor to wheel side (``MotorConfig.motor_to_wheel_rad_s``: x * sign / gear), and the
    #: steering zero (``zero_rad``; 0 for a drive motor).
    sign: float = field(init=False)
    gear: float = field(init=False)
    zero: float = field(init=False)
    #: Wheel speed (rad/s) to device velocity units: ``gear * sign``, RPM per rad/s,
    #: ``velocity_factor``, as ``rad_s_to_units(wheel_to_motor_rad_s(w))`` multiplies them.
    scale: float = field(init=False)
    #: A steering actuator's speed limit in position units per second (``max_rpm``).
    slew: float = field(init=False)
    nmt: NmtState | None = None
    emcy: Emergency | None = None
    counts: int = 0
    last_raw: int | None = None
    #: When the position TPDO behind :attr:`counts` came (s): the feedback's time (a velocity
    #: TPDO refreshes the speed only).
    position_s: float = 0.0
    #: When any frame of the node last came (s; ``None``: none yet).
    heard_s: float | None = None
    velocity_rad_s: float = 0.0
    #: Steering: the target position of the last RPDO (counts, unwrapped); ``None`` while not
    #: armed, so the next armed cycle starts from the measured position.
    setpoint: float | None = None
    #: Steering: when :attr:`setpoint` last moved (s).
    setpoint_s: float = 0.0
    restart_pending: bool = False
    boot_restarts: int = 0
    #: Whether the driver's base holds "armed, no fault" for this motor (the steady state).
    published: bool = False

    def __post_init__(self) -> None:
        m, opts = self.motor, self.opts
        self.steer = m.steering
        self.sign, self.gear = m.sign, m.gear_ratio
        self.zero = m.zero_rad if m.steering else 0.0
        self.scale = m.gear_ratio * m.sign
        self.slew = m.max_rpm / 60.0 * opts.counts_per_rev

    # ----------------------------------------------------------------- command targets

    def velocity_raw(self, wheel_rad_s: float) -> int:
        """The target velocity (device units, int32) for a wheel speed the base has checked.

        :raises EncodeError: if it does not fit the int32 of 0x60FF.
        """
        units = wheel_rad_s * self.scale * _RPM_PER_RAD_S * self.opts.velocity_factor
        raw = round(units) if math.isfinite(units) else None
        if raw is None or not _I32_MIN <= raw <= _I32_MAX:
            # velocity_to_raw raises; its message is only built on this path.
            raw = velocity_to_raw(units, f"target velocity for node {self.motor.node_id}")
        return raw

    def position_raw(self, angle: float) -> int:
        """The target position (int32, wrapped) of steering angle ``angle`` itself."""
        return position_to_raw(target_counts(self.motor, self.opts, angle),
                               f"target position for node {self.motor.node_id}")

    def slew_to(self, angle: float, now_s: float, max_dt_s: float) -> int:
        """This cycle's target position of an armed steering actuator (int32, wrapped): from
        the last one toward ``angle`` by at most ``max_rpm`` times the time since (at most
        ``max_dt_s``), from the measured position when just armed."""
        target = target_counts(self.motor, self.opts, angle)
        if self.setpoint is None:  # just armed: start where the drive stands
            self.setpoint, self.setpoint_s = float(self.counts), now_s
        dt = min(max(now_s - self.setpoint_s, 0.0), max_dt_s)
        step = self.slew * dt
        self.setpoint += min(max(target - self.setpoint, -step), step)
        self.setpoint_s = now_s
        return position_to_raw(self.setpoint, f"target position for node {self.motor.node_id}")

    def silence(self, now_s: float, liveness_s: float) -> str:
        """An armed drive whose position TPDO is older than ``liveness_s`` while its other
        frames still come (:func:`~gateway.drive.liveness.still_comes`, the rule of the other
        protocols' streams): what it sends and what not, for its fault's message; "" otherwise."""
        heard = self.heard_s
        if (self.seq.phase is not Phase.ARMED or heard is None or now_s - heard > liveness_s
                or not still_comes(heard, self.position_s, liveness_s)):
            return ""
        return (f"sends its other frames but no position TPDO (statusword and position actual "
                f"value 0x6064; none for {now_s - self.position_s:.3f} s)")

    # ----------------------------------------------------------------- received

    def on_pdo(self, position: bool, statusword: int, value: int,
               now_s: float) -> WheelFeedback | None:
        """A feedback TPDO: statusword and position actual value (``position``) or velocity
        actual value.  The wheel's feedback, once a position came (else ``None``).

        :raises DecodeError: for a statusword whose bits match no drive state (nothing of the
            PDO is taken: neither its value nor, by the caller, the node's liveness).
        """
        seq = self.seq
        if statusword != seq.statusword:  # (the state follows from the word alone)
            if state_from_statusword(statusword) is None:
                raise DecodeError(
                    f"node {self.motor.node_id}: TPDO statusword 0x{statusword:04X} matches no "
                    "CiA 402 drive state (0x6041 bits 0-3, 5, 6); expected one of the state "
                    "machine's patterns, the PDO is not taken")
            seq.on_status(statusword)
        sign, gear = self.sign, self.gear
        if position:
            last = self.last_raw
            if last is not None:  # targets.wrap_delta written out: the int32 counter's step
                self.counts += (value - last + _HALF_SPAN) % _SPAN - _HALF_SPAN
            elif self.steer:
                self.counts = value  # absolute: zero_rad is in the drive's own frame
            self.last_raw = value
            self.position_s = now_s
            if self.steer:
                seq.hold = value
        else:
            self.velocity_rad_s = value / self.opts.velocity_factor * _RAD_S_PER_RPM * sign / gear
        fb = None
        if self.last_raw is not None:
            rad = self.counts * _TWO_PI / self.opts.counts_per_rev
            fb = WheelFeedback((rad - self.zero) * sign / gear, self.velocity_rad_s,
                               self.position_s)
        state = seq.state
        if state is State.OPERATION_ENABLED or state is None or seq.phase is not Phase.ARMED:
            return fb  # (the steady state first)
        text = f"statusword 0x{statusword:04X} reports {state.label}"
        if state in _FAULT_STATES:
            seq.fail(text, DriveFault.CONTROLLER)
        else:
            seq.fail(f"drive left OPERATION ENABLED: {text}", DriveFault.CONTROLLER)
        return fb

    def on_heartbeat(self, state: NmtState, max_boot_restarts: int) -> None:
        """A heartbeat: a boot-up restarts an enable sequence under way (at most
        ``max_boot_restarts`` times) and ends an armed one; any NMT state but OPERATIONAL
        ends an armed one (its PDOs have stopped)."""
        self.nmt = state
        seq = self.seq
        if state is NmtState.BOOT_UP:
            if seq.protection is ProtectionState.CONFIRMED:
                seq.protection = ProtectionState.PENDING  # the drive forgot its consumer
            # The counter may restart: a drive motor continues from the current angle, a
            # steering actuator takes the next position as absolute (and not as a target).
            self.last_raw = None
            if self.steer:
                seq.hold = None
            if seq.phase in ENABLING:
                self.boot_restarts += 1
                if self.boot_restarts > max_boot_restarts:
                    seq.fail(f"rebooted {self.boot_restarts} times during the enable sequence",
                             DriveFault.COMMUNICATION)
                else:
                    log.info("%s: boot-up during the enable sequence, restarting it", seq.label)
                    self.restart_pending = True
            elif seq.phase in (Phase.ARMED, Phase.STOPPING):
                seq.fail("rebooted (boot-up message); its configuration is lost",
                         DriveFault.COMMUNICATION)
        elif seq.phase is Phase.ARMED and state is not NmtState.OPERATIONAL:
            seq.fail(f"heartbeat reports NMT {state.name}; PDOs have stopped",
                     DriveFault.COMMUNICATION)

    def on_emcy(self, msg: Emergency) -> None:
        """An EMCY: the active fault (ending a running sequence), or an error reset."""
        seq = self.seq
        text = describe_emcy(msg.code, msg.register, msg.data)
        if is_error_reset(msg.code):
            log.info("%s: %s", seq.label, text)
            self.emcy = None
            return
        log.warning("%s: %s", seq.label, text)
        self.emcy = msg
        if seq.phase in (Phase.ARMED, Phase.STOPPING):
            seq.fail(text, emcy_faults(msg.code, msg.register))

    # ----------------------------------------------------------------- reported

    def running(self) -> bool:
        """Armed, in OPERATION ENABLED, no EMCY: the steady state."""
        seq = self.seq
        return (self.emcy is None and seq.phase is Phase.ARMED
                and seq.state is State.OPERATION_ENABLED)

    def fault(self) -> tuple[DriveFault, str]:
        """The fault flags and text of the motor (``NONE, ""`` while enabling)."""
        seq, emcy = self.seq, self.emcy
        emcy_text = "" if emcy is None else describe_emcy(emcy.code, emcy.register, emcy.data)
        if seq.phase is Phase.FAILED:
            # A failed protection: the base's text (protection_fault) names the fix too.
            flags, detail = seq.error_flags, "" if seq.halted_by_protection else seq.error
            if emcy is not None and emcy_text not in detail:
                flags |= emcy_faults(emcy.code, emcy.register)
                detail = f"{detail}; last {emcy_text}"
            return flags, detail
        if seq.phase in ENABLING:
            return DriveFault.NONE, ""
        if emcy is not None:
            return emcy_faults(emcy.code, emcy.register), f"{seq.label}: {emcy_text}"
        if seq.state in _FAULT_STATES:
            return (DriveFault.CONTROLLER,
                    f"{seq.label}: statusword 0x{seq.statusword or 0:04X} reports FAULT")
        return DriveFault.NONE, ""
