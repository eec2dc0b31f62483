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

SYNC (0x080) goes out once per bus: after the RPDOs of every :meth:`~Cia402Driver.command`
call, and from :meth:`~Cia402Driver.poll` every 10 ms while :meth:`~Cia402Driver.command` is not
being called (enable sequence, disabled drives), so TPDO feedback and liveness never stop.

Each motor is one :class:`~drivers.cia402.axis.Axis`, which also takes what its node sends (the
receive side).  A node is alive while any of its frames (heartbeat, TPDO, EMCY, SDO response)
is younger than ``liveness_s``; armed, while its position TPDO is: a drive whose position TPDO
stopped while its velocity TPDO and heartbeat go on would leave the odometry frozen under a
wheel that turns (the tracking check sees the velocity, nothing else the position); its fault
says so (:meth:`Axis.silence`).  The frames are claimed by COB-ID (:meth:`Cia402Driver.claims`,
the CiA 301 predefined connection set: function code << 7 | node ID).

**Steering actuators** (:attr:`Cia402Driver.STEERING`) run in cyclic synchronous position mode
(CSP, 0x6060 = 8) with the target position 0x607A in their command RPDO; why CSP, and how each
cycle's target is built, is in :mod:`drivers.cia402.targets`.  A steering actuator's stop is
SHUTDOWN at once.

**Controller-side protection** (:mod:`drivers.cia402.protection`): :meth:`~Cia402Driver.poll`
sends the gateway's heartbeat; the enable sequence writes each drive's heartbeat consumer
(0x1016:01), abort connection option code (0x6007) and error behaviour (0x1029:01 = 0: NMT
PRE-OPERATIONAL at the heartbeat event; optional) and reads them back before NMT start
(:attr:`Cia402Driver.CONFIGURES_PROTECTION`); when that fails,
:meth:`~gateway.drive.driver.MotorDriver.may_arm` decides whether the drive is enabled anyway.
It then reads the quick stop option code (0x605A), which :meth:`~Cia402Driver.protection`
reports as the action (a warning where the motor would coast).  After a heartbeat event the
drive is PRE-OPERATIONAL: its heartbeat or EMCY ends the armed sequence, and the next
:meth:`~Cia402Driver.enable` configures it again, ending with NMT start.

Reference: CiA 301 and CiA 402 (https://www.can-cia.org/can-knowledge/cia402-series).
"""

from __future__ import annotations

import dataclasses
import functools
from typing import TYPE_CHECKING, ClassVar

from drivers.cia402.axis import ENABLING, Axis
from drivers.cia402.codec import (
    PDO_STRUCT,
    Cia402Codec,
    Emergency,
    Heartbeat,
    Received,
    cob_name,
    make_rpdo,
    make_sync,
)
from drivers.cia402.enums import CobBase, Controlword, ObjectIndex, State
from drivers.cia402.options import Cia402Options, check_steering
from drivers.cia402.phase import Phase
from drivers.cia402.protection import FIX, HostHeartbeat, describe, host_settings
from drivers.cia402.sdo import SdoResponse
from drivers.cia402.sequence import NodeSequencer
from drivers.cia402.steps import configuration_steps
from gateway.core.errors import DecodeError
from gateway.core.types import DriveFault, DriveState
from gateway.drive.claims import FrameClaim
from gateway.drive.driver import MotorDriver

if TYPE_CHECKING:
    from collections.abc import Mapping, Sequence

    from gateway.core.protection import Protection, ProtectionState
    from gateway.core.types import Frame, MotorConfig, MotorStatus
    from gateway.drive.traffic import Traffic

__all__ = ["Cia402Driver"]

#: The controlword of every command RPDO, as a plain int (make_rpdo's quick check).
_ENABLE_OPERATION = int(Controlword.ENABLE_OPERATION)
_PDO_SIZE = PDO_STRUCT.size
_PDO_UNPACK = PDO_STRUCT.unpack
_POSITION, _VELOCITY = Received.POSITION, Received.VELOCITY
_ARMED = Phase.ARMED
_QUICK_STOP_OPTION = (ObjectIndex.QUICK_STOP_OPTION_CODE, 0)
_RUNNING = State.OPERATION_ENABLED


class Cia402Driver(MotorDriver[Cia402Options]):
    """CANopen CiA 402 drives in profile velocity mode (steering actuators: cyclic synchronous
    position mode), one instance per bus.

    :param motors: the motors, each with ``driver: cia402`` and a node ID 1..127.
    :raises ConfigError: for a bad option, a node ID out of range or used twice, motors that
        disagree on the gateway's heartbeat, a drive with the gateway's
        node ID, or a steering actuator without SYNC or with a ``zero_rad`` out of range.
    """

    Options = Cia402Options
    #: One gateway heartbeat (node and period) per bus.
    BUS_WIDE: ClassVar[tuple[str, ...]] = ("host_node_id", "host_heartbeat_s")
    NODE_ID_RANGE: ClassVar[tuple[int, int]] = (1, 127)
    LIVENESS_STREAMS: ClassVar[tuple[str, ...]] = ("any frame; armed, the position TPDO",)
    #: SYNC period of :meth:`poll` while :meth:`command` is not called (s).
    SYNC_FALLBACK_PERIOD_S: ClassVar[float] = 0.01
    #: Boot-up messages during one enable sequence that restart it; one more is a failure.
    MAX_BOOT_RESTARTS: ClassVar[int] = 3
    STEERING: ClassVar[bool] = True
    #: Longest time one cycle's steering target may advance over (s): a late or resumed cycle
    #: does not turn into a jump the drive cannot follow.
    SLEW_MAX_DT_S: ClassVar[float] = 0.05
    MALFORMED: ClassVar[str] = "malformed CiA 402 frame"
    PROTOCOL: ClassVar[str] = "CiA 402"
    TIMEOUT_FIX: ClassVar[str] = FIX
    CONFIGURES_PROTECTION: ClassVar[bool] = True

    def __init__(self, motors: Sequence[MotorConfig]) -> None:
        super().__init__(motors)
        pairs = list(zip(self.motors, self.opts, strict=True))
        for m, o in pairs:
            if m.steering:
                check_steering(m, o)
        #: The gateway's heartbeat, which every drive's consumer (0x1016) watches.
        self.host = HostHeartbeat(host_settings(self.motors, self.opts))
        self.codec = Cia402Codec({m.node_id: o.layout for m, o in pairs})
        #: Whether this driver produces SYNC (any motor with ``sync: true``).
        self.sync_enabled = any(o.sync for o in self.opts)
        #: One record per motor, in :attr:`motors` order.
        self._axes = tuple(
            Axis(m, o, NodeSequencer(m.node_id, f'node {m.node_id} ("{m.wheel}")', self.codec,
                                     configuration_steps(m.node_id, o, position=m.steering),
                                     position=m.steering,
                                     may_arm=functools.partial(self.may_arm, i),
                                     timeout_s=o.response_timeout_s),
                 self.codec.rpdo_ids[m.node_id])
            for i, (m, o) in enumerate(pairs)
        )
        index = {m.node_id: i for i, m in enumerate(self.motors)}
        #: COB-ID -> (motor index, what it carries), of every frame :meth:`on_frame` takes.
        self._rx = {cob: (index[node], kind) for cob, (node, kind) in self.codec.receivers.items()}
        self._claims = self._declare()
        self._last_sync_s: float | None = None
        #: Whether this instance only previews (:meth:`preview_command`).
        self._preview = False

    @classmethod
    def validate_options(cls, raw: Mapping[str, object], where: str) -> dict[str, object]:
        """The keys of a motor block, checked one by one and against each other
        (:meth:`Cia402Options.from_block <drivers.cia402.options.Cia402Options.from_block>`);
        raises :class:`ConfigError` naming the key, what was expected and what came."""
        values = super().validate_options(raw, where)
        Cia402Options.from_block(values, where)  # the checks across keys
        return values

    # ----------------------------------------------------------------- hooks

    def _enable(self, now_s: float) -> list[Frame]:
        """Start the enable sequence of every node not armed, or armed but silent (OFFLINE:
        a drive whose heartbeat event went unheard is PRE-OPERATIONAL and needs the NMT
        start); QUICK STOP (and a SYNC) first to a node that may be enabled."""
        stops: list[Frame] = []
        out: list[Frame] = []
        for i, axis in enumerate(self._axes):
            if axis.seq.phase is not Phase.ARMED or not self.live.alive(i, now_s):
                axis.boot_restarts = 0
                axis.restart_pending = False
                stops += axis.seq.quick_stop()
                out += axis.seq.start(now_s)
            self._refresh(i)
        if stops and self.sync_enabled:
            stops.append(self._sync(now_s))
        return stops + out

    def disable(self, now_s: float) -> list[Frame]:
        """Target 0 with ENABLE OPERATION now; :meth:`poll` sends SHUTDOWN at speed 0."""
        out: list[Frame] = []
        for i, axis in enumerate(self._axes):
            out += axis.seq.stop(now_s)
            self._refresh(i)
        if out and self.sync_enabled:
            out.append(self._sync(now_s))
        return out

    def _command(self, setpoints: Sequence[float], now_s: float) -> list[Frame]:
        """One command RPDO per armed node, then one SYNC if ``sync`` is on.

        A steering actuator's target moves toward the commanded angle by at most ``max_rpm``
        since the previous cycle (:mod:`drivers.cia402.targets`).

        :raises EncodeError: for a target velocity beyond the int32 of 0x60FF.
        """
        if self._preview:
            return self._preview_frames(setpoints)
        out = []
        for axis, value in zip(self._axes, setpoints):  # noqa: B905 - the base checked
            if axis.seq.phase is _ARMED:
                raw = (axis.slew_to(value, now_s, self.SLEW_MAX_DT_S) if axis.steer
                       else axis.velocity_raw(value))
                out.append(make_rpdo(axis.rpdo_id, _ENABLE_OPERATION, raw))
        if self.sync_enabled:
            out.append(self._sync(now_s))
        return out

    def preview_command(self, setpoints: Sequence[float]) -> list[Frame]:
        """The RPDO of every node as if armed, then SYNC if ``sync`` is on (pure).

        A freshly enabled driver has no position to start a steering slew from, so a steering
        actuator's RPDO carries the commanded angle's own target position.

        :raises EncodeError: as :meth:`command`.
        """
        fresh = type(self)(self.motors)
        fresh._preview = True
        return fresh.command(setpoints, 0.0)

    def _preview_frames(self, setpoints: Sequence[float]) -> list[Frame]:
        out = [make_rpdo(axis.rpdo_id, _ENABLE_OPERATION,
                         axis.position_raw(value) if axis.steer else axis.velocity_raw(value))
               for axis, value in zip(self._axes, setpoints, strict=True)]
        if self.sync_enabled:
            out.append(make_sync())
        return out

    def _poll(self, now_s: float) -> list[Frame]:
        """The gateway's heartbeat when due, enable/stop sequence steps, deadlines, and the
        fallback SYNC."""
        out = self.host.poll(now_s)
        for i, axis in enumerate(self._axes):
            seq = axis.seq
            if (seq.phase is _ARMED and axis.published and seq.state is _RUNNING
                    and axis.emcy is None and not axis.restart_pending):
                # The steady state (Axis.running, published): the sequence has no step to
                # take and the base nothing new to hear.
                continue
            if axis.restart_pending:
                axis.restart_pending = False
                if seq.phase in ENABLING:
                    out += seq.start(now_s)
            was = seq.phase
            out += seq.poll(now_s)
            if was is not Phase.ARMED and seq.phase is Phase.ARMED:
                axis.emcy = None  # the drive reached OPERATION ENABLED: no fault is active
            self._refresh(i)
        last = self._last_sync_s
        if self.sync_enabled and (
                last is None or now_s - last >= self.SYNC_FALLBACK_PERIOD_S - 1e-9):
            out.append(self._sync(now_s))
        return out

    def _on_frame(self, frame: Frame) -> bool:
        """Take a frame: TPDO feedback, heartbeat, EMCY or SDO response of one of our nodes;
        raises :class:`DecodeError` for a malformed one (a malformed SDO response also fails
        the step that waited for it)."""
        hit = self._rx.get(frame.arbitration_id)
        if hit is None or frame.is_extended_id:
            return False  # CANopen uses 11-bit COB-IDs; a 29-bit frame is another device's
        i, kind = hit
        axis = self._axes[i]
        now_s = axis.heard_s = frame.timestamp_s
        data = frame.data
        if ((kind is _POSITION or kind is _VELOCITY) and len(data) == _PDO_SIZE
                and not frame.is_remote_frame):  # a TPDO: most of the traffic
            word, value = _PDO_UNPACK(data)
            fb = axis.on_pdo(kind is _POSITION, word, value, now_s)
            if kind is _POSITION or axis.seq.phase is not _ARMED:
                self.live.heard(i, 0, now_s)
            if fb is not None:
                self.store_feedback(i, fb, None)
            if not (axis.published and axis.seq.state is _RUNNING):
                self._refresh(i)
            return True
        try:
            msg = self.codec.decode(frame)
        except DecodeError as err:
            if kind is Received.SDO:
                axis.seq.on_sdo_error(err, now_s)
                self._refresh(i)
            raise
        if axis.seq.phase is not _ARMED:  # (well-formed TPDOs are taken above)
            self.live.heard(i, 0, now_s)
        if isinstance(msg, Heartbeat):
            axis.on_heartbeat(msg.state, self.MAX_BOOT_RESTARTS)
        elif isinstance(msg, Emergency):
            axis.on_emcy(msg)
        elif isinstance(msg, SdoResponse) and not axis.seq.on_sdo(msg, now_s):
            self.reject("unexpected SDO response")
        self._refresh(i)
        return True

    def enable_failed(self) -> list[int]:
        """The nodes whose enable sequence failed (a step without an answer, a write the drive
        refused, a transition it did not make, the base's protection failure): the reason is
        in their fault detail."""
        base = super().enable_failed()
        return [i for i, axis in enumerate(self._axes)
                if axis.seq.phase is Phase.FAILED or i in base]

    def status(self, now_s: float) -> tuple[MotorStatus, ...]:
        """The base's report; an armed drive OFFLINE for its position TPDO alone says so."""
        return tuple(s if s.state is not DriveState.OFFLINE or not (said := a.silence(
            now_s, o.liveness_s)) else dataclasses.replace(s, silence=said)
            for s, a, o in zip(super().status(now_s), self._axes, self.opts, strict=True))

    def _ready_state(self, index: int) -> DriveState:
        """ENABLING while the enable sequence runs, else ENABLED when armed or DISABLED."""
        phase = self._axes[index].seq.phase
        return (DriveState.ENABLING if phase in ENABLING
                else DriveState.ENABLED if phase is Phase.ARMED else DriveState.DISABLED)

    # ----------------------------------------------------------------- frames

    def claims(self) -> tuple[FrameClaim, ...]:
        """Per node, the COB-IDs it sends us (the two feedback TPDOs, EMCY, SDO responses,
        heartbeat) and those we send it (command RPDO, SDO requests); for the bus, the NMT
        commands, SYNC (when ``sync`` is on) and the gateway's own heartbeat."""
        return self._claims

    def _declare(self) -> tuple[FrameClaim, ...]:
        taken = [FrameClaim.exact(cob, False, self._rx[cob][0]) for cob in sorted(self._rx)]
        sent = [FrameClaim.exact(CobBase.NMT, False, None, receive=False),
                FrameClaim.exact(CobBase.HEARTBEAT + self.host.node_id, False, receive=False)]
        if self.sync_enabled:
            sent.append(FrameClaim.exact(CobBase.SYNC, False, None, receive=False))
        for i, axis in enumerate(self._axes):
            sent += [FrameClaim.exact(axis.rpdo_id, False, i, receive=False),
                     FrameClaim.exact(CobBase.SDO_RX + axis.motor.node_id, False, i,
                                      receive=False)]
        return (*taken, *sent)

    def message_name(self, arbitration_id: int, is_extended_id: bool) -> str | None:
        """:func:`~drivers.cia402.codec.cob_name` of an 11-bit COB-ID; ``None`` for 29-bit."""
        return None if is_extended_id else cob_name(arbitration_id)

    def traffic(self, rate_hz: float) -> Traffic:
        """The TPDOs and heartbeats as written while enabling (:mod:`drivers.cia402.traffic`)."""
        from drivers.cia402.traffic import bus_traffic  # noqa: PLC0415 - check and run only
        return bus_traffic(self.opts, rate_hz)

    # ----------------------------------------------------------------- protection

    def protection(self, index: int) -> Protection:
        """:attr:`~gateway.core.protection.Guard.CONFIGURED`: the drive's heartbeat consumer,
        abort connection option and error behaviour; the action as the quick stop option code
        read while enabling says (:mod:`drivers.cia402.protection`)."""
        axis = self._axes[index]
        return describe(axis.opts, axis.seq.readings.get(_QUICK_STOP_OPTION, (None, None)))

    def protection_state(self, index: int) -> ProtectionState:
        """PENDING until 0x1016:01, 0x6007 and 0x1029:01 read back as written (CONFIRMED),
        FAILED if not."""
        return self._axes[index].seq.protection

    def protection_failure(self, index: int) -> str:
        """What came back instead of the protection (an abort, no answer, another value)."""
        return self._axes[index].seq.protection_error or super().protection_failure(index)

    # ----------------------------------------------------------------- state

    def drive_state(self, index: int) -> State | None:
        """The CiA 402 state from motor ``index``'s latest statusword (``None`` if unknown)."""
        return self._axes[index].seq.state

    def phase(self, index: int) -> Phase:
        """Where motor ``index``'s enable/stop sequence stands."""
        return self._axes[index].seq.phase

    # ----------------------------------------------------------------- internals

    def _sync(self, now_s: float) -> Frame:
        self._last_sync_s = now_s
        return make_sync()

    def _refresh(self, i: int) -> None:
        """Publish motor ``i``'s fault flags, detail and armed flag to the base."""
        axis = self._axes[i]
        if axis.running():
            if not axis.published:
                axis.published = True
                self.set_fault(i, DriveFault.NONE)
                self.set_armed(i, True)
            return
        axis.published = False
        armed = axis.seq.phase is Phase.ARMED
        if not armed:
            axis.setpoint = None  # a steering actuator's next armed cycle starts afresh
        flags, detail = axis.fault()
        self.set_fault(i, flags, detail)
        self.set_armed(i, armed)
