"""The stateful CiA 402 driver: enable sequences, command RPDOs, SYNC, feedback and faults.

Why not ``canopen.BaseNode402``: the gateway loop calls this driver with an explicit ``now_s``
and sends what it returns, and it must never block.  ``BaseNode402`` blocks on every SDO and
while it waits for each state (``TIMEOUT_SWITCH_STATE_SINGLE``), its ``op_mode`` setter catches
SDO errors and only logs them, ``setup_pdos()`` guards with ``assert`` (a substring test at
that), and its string-keyed state machine has no unit tests.  So the sequence is our own
non-blocking state machine (:mod:`drivers.cia402.sequence`) over pure frame builders
(:mod:`drivers.cia402.codec`); ``canopen`` only serves as an independent cross-check in tests.

Per node, :meth:`Cia402Driver.enable` starts: NMT pre-operational; RPDO (controlword +
target velocity) and two TPDOs (statusword + position, statusword + velocity) remapped by SDO
with each PDO switched off meanwhile; the unused TPDOs switched off; transmission type 1 (every
SYNC) when ``sync`` is on, else 255 with an event timer; producer heartbeat (0x1017); mode of
operation 3 (profile velocity) and a read-back of 0x6061 until it says 3; NMT start; then the
controlword walk (fault reset if FAULT, shutdown, switch on, enable operation) in the RPDO,
each step confirmed by the statusword.  :meth:`Cia402Driver.disable` keeps ENABLE OPERATION
with target 0 until the drive reports speed 0 (statusword bit 12, at most 1 s), then sends
SHUTDOWN (to READY TO SWITCH ON: power stage off), so the wheel is braked by the drive's own
profile deceleration rather than left to coast at speed.

SYNC (0x080) goes out once per bus: after the RPDOs of every :meth:`command` call, and from
:meth:`poll` every 10 ms while :meth:`command` is not being called (enable sequence, disabled
drives), so TPDO feedback and liveness never stop.

**Steering actuators** (:attr:`Cia402Driver.STEERING`) run in cyclic synchronous position mode
(CSP, 0x6060 = 8) with the target position 0x607A in their command RPDO; why CSP, and how each
cycle's target is built, is in :mod:`drivers.cia402.targets`.  A steering actuator's stop is
SHUTDOWN at once.

**Controller-side protection** (:mod:`drivers.cia402.protection`): :meth:`Cia402Driver.poll`
sends the gateway's heartbeat; the enable sequence writes each drive's heartbeat consumer
(0x1016:01) and abort connection option code (0x6007) and reads both back before NMT start.

Reference: CiA 301 and CiA 402 (https://www.can-cia.org/can-knowledge/cia402-series).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar

from drivers.cia402.codec import (
    Cia402Codec,
    Emergency,
    FeedbackKind,
    Heartbeat,
    PdoFeedback,
    make_sync,
    position_to_raw,
)
from drivers.cia402.enums import CobBase, Controlword, NmtState, State
from drivers.cia402.faults import describe_emcy, emcy_faults, is_error_reset
from drivers.cia402.options import DEFAULT_LIVENESS_S, OPTIONS, NodeOptions
from drivers.cia402.protection import FIX, HostHeartbeat, describe, host_settings
from drivers.cia402.sdo import SdoResponse
from drivers.cia402.sequence import NodeSequencer, Phase
from drivers.cia402.sim import Cia402Simulator
from drivers.cia402.steps import configuration_steps
from drivers.cia402.targets import raw_targets, target_counts, wrap_delta
from gateway.core.errors import DecodeError
from gateway.core.protection import ProtectionState, WatchdogPolicy
from gateway.core.types import DriveFault, DriveState, WheelFeedback
from gateway.drive.driver import MotorDriver, OptionSpec
from gateway.drive.filters import CanFilter

if TYPE_CHECKING:
    from collections.abc import Mapping, Sequence

    from gateway.core.protection import Protection
    from gateway.core.types import Frame, MotorConfig

__all__ = ["Cia402Driver", "wrap_delta"]

log = logging.getLogger(__name__)

_ENABLING = frozenset({Phase.CONFIGURING, Phase.AWAIT_STATUS, Phase.WALKING})
#: The controlword of every command RPDO, as a plain int (make_rpdo's quick check).
_ENABLE_OPERATION = int(Controlword.ENABLE_OPERATION)


@dataclass(slots=True)
class _Node:
    opts: NodeOptions
    seq: NodeSequencer
    last_seen_s: float | None = None
    nmt: NmtState | None = None
    emcy: Emergency | None = None
    counts: int = 0
    last_raw: int | None = None
    velocity_rad_s: float = 0.0
    #: A steering actuator (cyclic synchronous position): absolute position, target in RPDO.
    steer: bool = False
    #: Steering: the target position of the last RPDO (counts, unwrapped); ``None`` while not
    #: armed, so the next armed cycle starts from the measured position.
    setpoint: float | None = None
    #: Steering: when :attr:`setpoint` last moved (s).
    setpoint_s: float = 0.0
    restart_pending: bool = False
    boot_restarts: int = 0


class Cia402Driver(MotorDriver):
    """CANopen CiA 402 drives in profile velocity mode (steering actuators: cyclic synchronous
    position mode), one instance per bus.

    :param motors: the motors, each with ``driver: cia402`` and a node ID 1..127.
    :raises ConfigError: for a bad option, a node ID out of range or used twice, motors that
        disagree on the gateway's heartbeat, or a drive with the gateway's node ID.
    """

    OPTIONS: ClassVar[Mapping[str, OptionSpec]] = OPTIONS
    NODE_ID_RANGE: ClassVar[tuple[int, int]] = (1, 127)
    DEFAULT_LIVENESS_S: ClassVar[float] = DEFAULT_LIVENESS_S
    #: SYNC period of :meth:`poll` while :meth:`command` is not called (s).
    SYNC_FALLBACK_PERIOD_S: ClassVar[float] = 0.01
    #: Boot-up messages during one enable sequence that restart it; one more is a failure.
    MAX_BOOT_RESTARTS: ClassVar[int] = 3
    STEERING: ClassVar[bool] = True
    #: Longest time one cycle's steering target may advance over (s): a late or resumed cycle
    #: does not turn into a jump the drive cannot follow.
    SLEW_MAX_DT_S: ClassVar[float] = 0.05
    PROTOCOL: ClassVar[str] = "CiA 402"
    TIMEOUT_FIX: ClassVar[str] = FIX

    def __init__(self, motors: Sequence[MotorConfig]) -> None:
        super().__init__(motors)
        opts = [NodeOptions.from_motor(m) for m in self.motors]
        pairs = list(zip(self.motors, opts, strict=True))
        #: The gateway's heartbeat, which every drive's consumer (0x1016) watches.
        self.host = HostHeartbeat(host_settings(self.motors, opts))
        self.codec = Cia402Codec({m.node_id: o.layout for m, o in pairs})
        #: Whether this driver produces SYNC (any motor with ``sync: true``).
        self.sync_enabled = any(o.sync for o in opts)
        self._nodes = [
            _Node(o, NodeSequencer(m.node_id, f'node {m.node_id} ("{m.wheel}")', self.codec,
                                   configuration_steps(m.node_id, o), position=o.position_mode),
                  steer=o.position_mode)
            for m, o in pairs
        ]
        #: Indices of the steering actuators in :attr:`motors`.
        self._steering = tuple(i for i, node in enumerate(self._nodes) if node.steer)
        #: Each steering actuator's speed limit in position units per second (``max_rpm``).
        self._slew = tuple(m.max_rpm / 60.0 * o.counts_per_rev for m, o in pairs)
        self._last_sync_s: float | None = None
        #: Each motor's ``max_wheel_rad_s`` (a computed property), for :meth:`command`.
        self._limits = tuple(m.max_wheel_rad_s for m in self.motors)
        #: Each motor's options, and whether it is a steering actuator, for :meth:`command`.
        self._kinds = tuple((node.opts, node.steer) for node in self._nodes)
        #: Each motor's (sign, gear ratio, zero), for the feedback's motor-to-wheel conversion
        #: (``zero_rad`` of a steering actuator, 0 for a drive motor).
        self._wheel_side = tuple(
            (m.sign, m.gear_ratio, m.zero_rad if m.steering else 0.0) for m in self.motors
        )

    # ----------------------------------------------------------------- hooks

    def enable(self, now_s: float) -> list[Frame]:
        """Start the enable sequence of every node that is not already armed."""
        out: list[Frame] = []
        required = self.watchdog_policy is WatchdogPolicy.REQUIRED
        for i, node in enumerate(self._nodes):
            if node.seq.phase is not Phase.ARMED:
                node.boot_restarts = 0
                node.restart_pending = False
                self.clear_protection_fault(i)
                node.seq.protection_required = required
                out += node.seq.start(now_s)
            self._refresh(i)
        return out

    def disable(self, now_s: float) -> list[Frame]:
        """Target 0 with ENABLE OPERATION now; :meth:`poll` sends SHUTDOWN at speed 0."""
        out: list[Frame] = []
        for i, node in enumerate(self._nodes):
            out += node.seq.stop(now_s)
            self._refresh(i)
        if out and self.sync_enabled:
            out.append(self._sync(now_s))
        return out

    def command(self, wheel_rad_s: Sequence[float], now_s: float) -> list[Frame]:
        """One command RPDO per armed node, then one SYNC if ``sync`` is on.

        A steering actuator's target moves toward the commanded angle by at most ``max_rpm``
        since the previous cycle (see the module docstring).

        :param wheel_rad_s: in :attr:`motors` order, wheel speeds in rad/s, and steering
            angles in rad for steering actuators.
        :raises EncodeError: for a wrong count, a speed that is not finite or beyond
            ``max_rpm``, an angle that is not finite; no frame is built then.
        """
        raws = self._raws(wheel_rad_s)
        nodes = self._nodes
        for i in self._steering:
            node = nodes[i]
            if node.seq.phase is Phase.ARMED:
                raws[i] = self._slew_to(i, node, wheel_rad_s[i], now_s)
        out = [
            self.codec.rpdo(m.node_id, _ENABLE_OPERATION, raw)
            for m, node, raw in zip(self.motors, nodes, raws, strict=True)
            if node.seq.phase is Phase.ARMED
        ]
        if self.sync_enabled:
            out.append(self._sync(now_s))
        return out

    def preview_command(self, wheel_rad_s: Sequence[float]) -> list[Frame]:
        """The RPDO of every node as if armed, then SYNC if ``sync`` is on (pure).

        A freshly enabled driver has no position to start a steering slew from, so a steering
        actuator's RPDO carries the commanded angle's own target position.

        :raises EncodeError: as :meth:`command`.
        """
        raws = self._raws(wheel_rad_s)
        out = [self.codec.rpdo(m.node_id, _ENABLE_OPERATION, raw)
               for m, raw in zip(self.motors, raws, strict=True)]
        if self.sync_enabled:
            out.append(make_sync())
        return out

    def _raws(self, wheel_rad_s: Sequence[float]) -> list[int]:
        """Every motor's RPDO target (:func:`~drivers.cia402.targets.raw_targets`).

        :raises EncodeError: as :meth:`command`.
        """
        return raw_targets(self.motors, self._kinds, self._limits, wheel_rad_s)

    def _slew_to(self, i: int, node: _Node, angle: float, now_s: float) -> int:
        """This cycle's target position of armed steering actuator ``i`` (int32, wrapped)."""
        target = target_counts(self.motors[i], node.opts, angle)
        if node.setpoint is None:  # just armed: start where the drive stands
            node.setpoint, node.setpoint_s = float(node.counts), now_s
        dt = min(max(now_s - node.setpoint_s, 0.0), self.SLEW_MAX_DT_S)
        step = self._slew[i] * dt
        node.setpoint += min(max(target - node.setpoint, -step), step)
        node.setpoint_s = now_s
        return position_to_raw(node.setpoint, f"target position for node {node.seq.node_id}")

    def poll(self, now_s: float) -> list[Frame]:
        """The gateway's heartbeat when due, enable/stop sequence steps, deadlines, and the
        fallback SYNC."""
        out = self.host.poll(now_s)
        for i, node in enumerate(self._nodes):
            if node.restart_pending:
                node.restart_pending = False
                if node.seq.phase in _ENABLING:
                    out += node.seq.start(now_s)
            was = node.seq.phase
            out += node.seq.poll(now_s)
            if was is not Phase.ARMED and node.seq.phase is Phase.ARMED:
                node.emcy = None  # the drive reached OPERATION ENABLED: no fault is active
            self._check_protection(i)
            self._refresh(i)
        if self.sync_enabled and (
            self._last_sync_s is None
            or now_s - self._last_sync_s >= self.SYNC_FALLBACK_PERIOD_S - 1e-9
        ):
            out.append(self._sync(now_s))
        return out

    def receive_filters(self) -> tuple[CanFilter, ...]:
        """The COB-IDs of our nodes that the codec decodes: the feedback TPDOs, EMCY, SDO
        responses and heartbeats (11-bit, exact)."""
        return tuple(CanFilter.exact(i, False) for i in sorted(self.codec.received_ids))

    def on_frame(self, frame: Frame) -> bool:
        """Take a frame: TPDO feedback, heartbeat, EMCY or SDO response of one of our nodes."""
        try:
            msg = self.codec.decode(frame)
        except DecodeError as err:
            self.reject("malformed CiA 402 frame", err)
            i = self.index_of(frame.arbitration_id - CobBase.SDO_TX)
            if i is not None and not frame.is_extended_id:
                self._nodes[i].seq.on_sdo_error(err, frame.timestamp_s)
                self._check_protection(i)
                self._refresh(i)
            return True
        if msg is None:
            return False
        i = self._index.get(msg.node_id)  # index_of, inlined (every frame)
        if i is None:  # not reached: the codec only knows our nodes
            return False
        node = self._nodes[i]
        now_s = frame.timestamp_s
        node.last_seen_s = now_s
        if isinstance(msg, PdoFeedback):
            self._on_feedback(i, msg, now_s)
        elif isinstance(msg, Heartbeat):
            self._on_heartbeat(i, msg)
        elif isinstance(msg, Emergency):
            self._on_emcy(i, msg)
        elif isinstance(msg, SdoResponse):
            if not node.seq.on_sdo(msg, now_s):
                self.reject("unexpected SDO response")
            self._check_protection(i)
        self._refresh(i)
        return True

    @classmethod
    def make_simulator(cls, motor: MotorConfig) -> Cia402Simulator:
        """A simulated CiA 402 drive for ``motor``."""
        return Cia402Simulator(motor)

    # ----------------------------------------------------------------- protection

    def protection(self, index: int) -> Protection:
        """:attr:`~gateway.core.protection.Guard.CONFIGURED`: the drive's heartbeat consumer and
        abort connection option (:mod:`drivers.cia402.protection`)."""
        return describe(self._nodes[index].opts)

    def protection_state(self, index: int) -> ProtectionState:
        """PENDING until 0x1016:01 and 0x6007 read back as written (CONFIRMED), FAILED if
        not."""
        return self._nodes[index].seq.protection

    def _check_protection(self, i: int) -> None:
        why = self._nodes[i].seq.take_protection_error()
        if why:
            self.protection_fault(i, why)

    # ----------------------------------------------------------------- state

    def state(self, index: int, now_s: float) -> DriveState:
        """OFFLINE after ``liveness_s`` of silence; else FAULT, ENABLING, ENABLED or DISABLED."""
        node = self._nodes[index]
        if node.last_seen_s is None or now_s - node.last_seen_s > node.opts.liveness_s:
            return DriveState.OFFLINE
        phase = node.seq.phase
        if phase is Phase.FAILED:
            return DriveState.FAULT
        if phase in _ENABLING:
            return DriveState.ENABLING
        if node.emcy is not None or node.seq.state in (State.FAULT, State.FAULT_REACTION_ACTIVE):
            return DriveState.FAULT
        return DriveState.ENABLED if phase is Phase.ARMED else DriveState.DISABLED

    def drive_state(self, index: int) -> State | None:
        """The CiA 402 state from motor ``index``'s latest statusword (``None`` if unknown)."""
        return self._nodes[index].seq.state

    def phase(self, index: int) -> Phase:
        """Where motor ``index``'s enable/stop sequence stands."""
        return self._nodes[index].seq.phase

    # ----------------------------------------------------------------- internals

    def _sync(self, now_s: float) -> Frame:
        self._last_sync_s = now_s
        return make_sync()

    def _on_feedback(self, i: int, msg: PdoFeedback, now_s: float) -> None:
        node = self._nodes[i]
        seq = node.seq
        seq.on_status(msg.statusword)
        # Every TPDO: motor to wheel side as MotorConfig.motor_to_wheel_rad_s (x * sign / gear)
        # with the per-motor constants from __init__.
        sign, gear, zero = self._wheel_side[i]
        if msg.kind is FeedbackKind.POSITION:
            if node.last_raw is not None:
                node.counts += wrap_delta(node.last_raw, msg.value)
            elif node.steer:
                node.counts = msg.value  # absolute: zero_rad is in the drive's own frame
            node.last_raw = msg.value
            if node.steer:
                seq.hold = msg.value
        else:
            node.velocity_rad_s = node.opts.units_to_rad_s(msg.value) * sign / gear
        if node.last_raw is not None:
            position = (node.opts.counts_to_rad(node.counts) - zero) * sign / gear
            self._feedback[i] = WheelFeedback(position, node.velocity_rad_s, now_s)
        state = seq.state
        if state is State.OPERATION_ENABLED:
            return  # the steady state: nothing to check below
        if seq.phase is Phase.ARMED and state is not None:
            text = f"statusword 0x{msg.statusword:04X} reports {state.label}"
            if state in (State.FAULT, State.FAULT_REACTION_ACTIVE):
                seq.fail(text, DriveFault.CONTROLLER)
            else:
                seq.fail(f"drive left OPERATION ENABLED: {text}", DriveFault.CONTROLLER)

    def _on_heartbeat(self, i: int, msg: Heartbeat) -> None:
        node = self._nodes[i]
        node.nmt = msg.state
        seq = node.seq
        if msg.state is NmtState.BOOT_UP:
            if seq.protection is ProtectionState.CONFIRMED:
                seq.protection = ProtectionState.PENDING  # the drive forgot its consumer
            # The counter may restart: a drive motor continues from the current angle, a
            # steering actuator takes the next position as absolute (and not as a target).
            node.last_raw = None
            if node.steer:
                seq.hold = None
            if seq.phase in _ENABLING:
                node.boot_restarts += 1
                if node.boot_restarts > self.MAX_BOOT_RESTARTS:
                    seq.fail(f"rebooted {node.boot_restarts} times during the enable sequence",
                             DriveFault.COMMUNICATION)
                else:
                    log.info("%s: boot-up during the enable sequence, restarting it", seq.label)
                    node.restart_pending = True
            elif seq.phase in (Phase.ARMED, Phase.STOPPING):
                seq.fail("rebooted (boot-up message); its configuration is lost",
                         DriveFault.COMMUNICATION)
        elif seq.phase is Phase.ARMED and msg.state is not NmtState.OPERATIONAL:
            seq.fail(f"heartbeat reports NMT {msg.state.name}; PDOs have stopped",
                     DriveFault.COMMUNICATION)

    def _on_emcy(self, i: int, msg: Emergency) -> None:
        node = self._nodes[i]
        text = describe_emcy(msg.code, msg.register, msg.data)
        if is_error_reset(msg.code):
            log.info("%s: %s", node.seq.label, text)
            node.emcy = None
            return
        log.warning("%s: %s", node.seq.label, text)
        node.emcy = msg
        if node.seq.phase in (Phase.ARMED, Phase.STOPPING):
            node.seq.fail(text, emcy_faults(msg.code, msg.register))

    def _refresh(self, i: int) -> None:
        """Publish node ``i``'s fault flags, detail and armed flag to the base."""
        node = self._nodes[i]
        seq, emcy = node.seq, node.emcy
        if emcy is None and seq.phase is Phase.ARMED and seq.state is State.OPERATION_ENABLED:
            # A running drive, after nearly every TPDO: what the general path below gives for
            # it (no fault, armed), without walking its cases.
            self._faults[i] = DriveFault.NONE
            self._detail[i] = ""
            self._armed[i] = True
            return
        if seq.phase is not Phase.ARMED:
            node.setpoint = None  # a steering actuator's next armed cycle starts afresh
        flags, detail = DriveFault.NONE, ""
        emcy_text = "" if emcy is None else describe_emcy(emcy.code, emcy.register, emcy.data)
        if seq.phase is Phase.FAILED:
            # A failed protection: the base's text (protection_fault) names the fix too.
            flags, detail = seq.error_flags, "" if seq.halted_by_protection else seq.error
            if emcy is not None and emcy_text not in detail:
                flags |= emcy_faults(emcy.code, emcy.register)
                detail = f"{detail}; last {emcy_text}"
        elif seq.phase in _ENABLING:
            pass
        elif emcy is not None:
            flags, detail = emcy_faults(emcy.code, emcy.register), f"{seq.label}: {emcy_text}"
        elif seq.state in (State.FAULT, State.FAULT_REACTION_ACTIVE):
            flags = DriveFault.CONTROLLER
            detail = f"{seq.label}: statusword 0x{seq.statusword or 0:04X} reports FAULT"
        self.set_fault(i, flags, detail)
        self.set_armed(i, seq.phase is Phase.ARMED)
