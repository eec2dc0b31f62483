"""A simulated CiA 402 drive: NMT slave, SDO server, PDOs, SYNC, heartbeat, EMCY, state machine.

The device decodes controlwords from their bits (CiA 402 "device control commands"), not from
the driver's transition table, so the driver is tested against an independent reading of the
standard.  Its default PDO mapping is deliberately not the gateway's (TPDO3 carries velocity,
RPDO4 and TPDO4 are off, TPDO1/2 are on): a driver that does not remap fails the tests.  The
PDO exchange (RPDOs, SYNC, TPDOs) is :mod:`drivers.cia402.sim_pdo`.

Quantisation follows a real drive: position actual value (0x6064) is an int32 count that wraps
modulo 2^32 (``initial_position`` lets a test start near the wrap), velocities are int32
device units.  The motor follows 0x60FF only in OPERATION ENABLED with mode 3 displayed and
halt clear.  In cyclic synchronous position mode (8, a steering actuator) it follows 0x607A
instead, under the same conditions, with the position loop of
:class:`~gateway.sim.device.MotorModel`
(speed limited to ``max_rpm``): the int32 target is taken modulo 2^32 relative to the current
position, as a drive compares target and actual position.  Statusword bit 12 is "speed 0" in
mode 3 and "follows the target" in mode 8.  For a steering actuator the position frame of
0x6064 is the model's (``initial_position`` 0), since ``zero_rad`` is given in it.

Like a device, and unlike a test double, it takes time (:mod:`drivers.cia402.sim_control`):
a commanded state transition shows in the statusword only after its delay (``state_delay_s``,
``switch_on_delay_s``, ``enable_delay_s``), a new mode in 0x6061 after ``mode_switch_delay_s``.
QUICK STOP ACTIVE follows the quick stop option code 0x605A (ramp on 0x6084 or 0x6085, then
SWITCH ON DISABLED, or stay).

**At factory settings it keeps turning when its master dies**: its heartbeat consumer 0x1016:01
is 0 (not used), so nothing watches the master, and the last target velocity stays.  Once a
master writes a consumer entry, the drive watches that node's heartbeat (0x700 + node) from the
first one after the write; when it is missing for longer than the consumer time, it sends EMCY
0x8130 and acts on its abort connection option code 0x6007 (factory value 1): 1 fault (the
motor coasts), 2 disable voltage (SWITCH ON DISABLED: the motor coasts), 3 quick stop (as
0x605A says; from READY TO SWITCH ON or SWITCHED ON: SWITCH ON DISABLED), 0 nothing.  The
heartbeat event is also a communication error (CiA 301), and the NMT state follows the error
behaviour 0x1029:01 (factory value 0, the CiA 301 default, also without the object): 0
PRE-OPERATIONAL if OPERATIONAL, 1 no state change, 2 STOPPED (no EMCY goes out there).  Both
happen: the drive stops on its own (0x6007) while its PDOs stop (0x1029): no TPDO shows the stop,
RPDOs are ignored, and one received before is dropped (CANopenNode ``301/CO_PDO.c``,
``CO_RPDO_process``), until a master sends NMT start again.

Reference: CiA 301 and CiA 402 (https://www.can-cia.org/can-knowledge/cia402-series).
"""

from __future__ import annotations

import logging
import math
from typing import TYPE_CHECKING

from drivers.cia402.codec import make_heartbeat
from drivers.cia402.enums import (
    ClientCommand,
    CobBase,
    NmtCommand,
    NmtState,
    ObjectIndex,
    OperationMode,
    State,
    StatuswordBit,
    supported_mode_bit,
)
from drivers.cia402.faults import ErrorRegister, SdoAbortCode
from drivers.cia402.options import Cia402Options
from drivers.cia402.sdo import (
    make_sdo_abort,
    make_sdo_download_ack,
    make_sdo_upload_response,
    parse_sdo_request,
)
from drivers.cia402.sim_control import (
    HeartbeatConsumer,
    QuickStopRamp,
    Timing,
)
from drivers.cia402.sim_device import POWERED, DriveControl
from drivers.cia402.sim_od import FACTORY_ERROR_BEHAVIOUR, SimObjectDictionary
from drivers.cia402.sim_pdo import PdoExchange
from gateway.core.errors import DecodeError
from gateway.sim.device import DeviceSimulator

if TYPE_CHECKING:
    from collections.abc import Iterable

    from gateway.core.types import Frame, MotorConfig
    from gateway.sim.device import MotorModel

log = logging.getLogger(__name__)

_OPERATING = frozenset({State.OPERATION_ENABLED, State.QUICK_STOP_ACTIVE})
#: The default delays of commanded transitions (:class:`Timing`, assumptions).
_TIMING = Timing()


def _wrap32(value: int) -> int:
    return (value + (1 << 31)) % (1 << 32) - (1 << 31)


def _clamp32(value: int) -> int:
    return max(-(1 << 31), min((1 << 31) - 1, value))


def simulator_for(motor: MotorConfig) -> Cia402Simulator:
    """A simulated CiA 402 drive for ``motor`` at factory settings (for tests and ``--sim``,
    :mod:`gateway.sim.registry`)."""
    return Cia402Simulator(motor)


class Cia402Simulator(PdoExchange, DriveControl, DeviceSimulator):
    """The device side of one CiA 402 drive in profile velocity mode.

    :param motor: the motor block (node ID, ``velocity_factor``, ``counts_per_rev``).
    :param model: the motor physics (motor side).
    :param initial_position: 0x6064 at motor angle 0 (counts, int32).
    :param heartbeat_ms: 0x1017 at power-up (0 = no heartbeat until configured).
    :param command_timeout_s: fault (EMCY 0x8250 RPDO timeout) when OPERATION ENABLED and no
        RPDO came for this long; ``None`` disables the watchdog.
    :param supported_modes: 0x6502; writing an unsupported 0x6060 is aborted.  ``None``:
        modes 1, 3, 4, 6, 7 (0x6D), plus 8 (0x80, CSP) for a steering actuator.
    :param mode_switch_delay_s: 0x6061 follows 0x6060 after this delay (assumed: a few ms).
    :param state_delay_s: a commanded state transition shows after this delay, unless one
        of the two below applies (assumed: 2 ms, two cycles of a 1 kHz state machine).
    :param switch_on_delay_s: the same into SWITCHED ON (power stage on; assumed: 10 ms).
    :param enable_delay_s: the same into OPERATION ENABLED (brake release; assumed: 30 ms).
    :param decelerations_rpm_s: 0x6084 (profile deceleration) and 0x6085 (quick stop
        deceleration) at power-up, in motor RPM per second (manufacturer-specific; assumed).
    :param missing_objects: indices to leave out of the dictionary (SDO abort 0x06020000).
    :param ignored_writes: indices whose SDO writes the device confirms but does not take (a
        firmware that keeps its own value), for tests of the read-back.
    :param fault_code: EMCY code sent on an injected :attr:`SimFault.FAULT`.
    :param fault_register: error register sent with it.
    """

    def __init__(
        self, motor: MotorConfig, model: MotorModel | None = None, *,
        initial_position: int = 0, heartbeat_ms: int = 0,
        command_timeout_s: float | None = None, supported_modes: int | None = None,
        mode_switch_delay_s: float = 0.005, state_delay_s: float = _TIMING.state_s,
        switch_on_delay_s: float = _TIMING.switch_on_s, enable_delay_s: float = _TIMING.enable_s,
        decelerations_rpm_s: tuple[float, float] = (5000.0, 10000.0),
        missing_objects: Iterable[int] = (), ignored_writes: Iterable[int] = (),
        fault_code: int = 0x2310, fault_register: int = 0x03,
    ) -> None:
        super().__init__(motor, model)
        self.opts = Cia402Options.from_block(motor.options, f"motor {motor.wheel!r}")
        self.node_id = motor.node_id
        self.initial_position = _wrap32(initial_position)
        self.command_timeout_s = command_timeout_s
        self.mode_switch_delay_s = mode_switch_delay_s
        self.timing = Timing(state_delay_s, switch_on_delay_s, enable_delay_s)
        self.ignored_writes = frozenset(ignored_writes)
        self.fault_code, self.fault_register = fault_code, fault_register
        if supported_modes is None:
            supported_modes = 0x6D | (
                supported_mode_bit(OperationMode.CYCLIC_SYNCHRONOUS_POSITION)
                if motor.steering else 0)
        decel = tuple(round(self.opts.rpm_to_units(r)) for r in decelerations_rpm_s)
        self.od = SimObjectDictionary(self.node_id, heartbeat_ms, supported_modes,
                                      missing_objects, (decel[0], decel[1]))
        #: Counters for assertions: SYNCs seen, RPDOs applied, SDO aborts sent, bad PDOs.
        self.syncs = self.rpdos = self.aborts = self.pdo_errors = 0
        self._now = 0.0
        self._power_on()

    # ----------------------------------------------------------------- public

    @property
    def position_counts(self) -> int:
        """0x6064 now: the motor angle in counts from ``initial_position``, wrapped to int32."""
        turns = self.model.position_rad / (2.0 * math.pi)
        return _wrap32(self.initial_position + round(turns * self.opts.counts_per_rev))

    @property
    def velocity_units(self) -> int:
        """0x606C now, device units."""
        return _clamp32(round(self.opts.rad_s_to_units(self.model.velocity_rad_s)))

    def object_value(self, index: int, subindex: int = 0) -> int:
        """The current value of an object (for assertions)."""
        self._refresh()
        return self.od.entries[(index, subindex)].value

    # ----------------------------------------------------------------- state

    def _power_on(self) -> None:
        self.nmt = NmtState.PRE_OPERATIONAL
        self.state = State.NOT_READY_TO_SWITCH_ON
        self.od.entries = self.od.defaults()
        self._boot_pending = True
        self._reset_comm_state()
        self._controlword = 0
        self._mode_due: tuple[int, float] | None = None
        #: A commanded transition under way: (target state, when it shows).
        self._transition: tuple[State, float] | None = None
        self._ramp: QuickStopRamp | None = None
        self._error_register = 0
        self._last_rpdo_s: float | None = None

    def _reset_comm_state(self) -> None:
        #: The heartbeat consumer (0x1016:01), which reset communication clears too.
        self.consumer = HeartbeatConsumer()
        self._emcy_out: list[Frame] = []
        self._last_hb_s: float | None = None
        self._reset_pdos()

    def _statusword(self) -> int:
        sw = int(self.state) | StatuswordBit.REMOTE
        if self.state in POWERED:
            sw |= StatuswordBit.VOLTAGE_ENABLED
        if self.state is State.SWITCH_ON_DISABLED:
            sw |= StatuswordBit.QUICK_STOP
        if self.od.get(0x6061) == OperationMode.CYCLIC_SYNCHRONOUS_POSITION:
            if self._following():
                sw |= StatuswordBit.FOLLOWS_TARGET
            return sw
        rpm_units = abs(self.opts.rad_s_to_units(self.model.velocity_rad_s))
        if rpm_units < self.opts.velocity_factor:  # below 1 RPM
            sw |= StatuswordBit.SPEED_ZERO
        if self.state is State.OPERATION_ENABLED:
            target = self.od.get(0x60FF)
            if abs(self.velocity_units - target) <= max(1.0, 0.01 * abs(target)):
                sw |= StatuswordBit.TARGET_REACHED
        return sw

    def _refresh(self) -> None:
        od = self.od
        due = self._transition
        if due is not None and self._now >= due[1] - 1e-12:
            self._enter(due[0])
        if self._mode_due is not None and self._now >= self._mode_due[1]:
            od.set(0x6061, self._mode_due[0])
            self._mode_due = None
        od.set(0x6041, self._statusword())
        od.set(0x6064, self.position_counts)
        od.set(0x606C, self.velocity_units)
        od.set(0x1001, self._error_register)

    # ----------------------------------------------------------------- CiA 402 device control

    def _on_fault(self) -> None:
        self._raise_fault(self.fault_code, self.fault_register)

    def _write(self, index: int, sub: int, data: bytes, *, sdo: bool) -> SdoAbortCode | None:
        """Write an object and act on it; the SDO abort code on refusal."""
        value, abort = self.od.write(index, sub, data, sdo=sdo)
        if abort is None:
            if index == ObjectIndex.CONTROLWORD:
                self._apply_controlword(value)
            elif index == ObjectIndex.MODES_OF_OPERATION:
                self._mode_due = (value, self._now + self.mode_switch_delay_s)
            elif index == ObjectIndex.CONSUMER_HEARTBEAT_TIME:
                self.consumer.configure(value)
        return abort

    # ----------------------------------------------------------------- frames in

    def _on_frame(self, frame: Frame, now_s: float) -> list[Frame]:
        self._now = now_s
        if frame.is_extended_id or frame.is_remote_frame:
            return []
        cob = frame.arbitration_id
        if cob == CobBase.NMT:
            return self._on_nmt(frame)
        if cob & 0x780 == CobBase.HEARTBEAT:  # another node's heartbeat (error control)
            self.consumer.on_heartbeat(frame, now_s)
            return []
        if self.nmt is NmtState.STOPPED:
            return []
        if cob == CobBase.SDO_RX + self.node_id:
            return self._on_sdo(frame)
        if self.nmt is not NmtState.OPERATIONAL:
            return []
        if cob == CobBase.SYNC:
            return self._on_sync()
        for k in range(4):
            if self.od.pdo_valid(0x1400 + k) and self.od.get(0x1400 + k, 1) & 0x7FF == cob:
                self._on_rpdo(k, frame.data)
        return []

    def _on_nmt(self, frame: Frame) -> list[Frame]:
        if len(frame.data) != 2 or frame.data[1] not in (0, self.node_id):
            return []
        try:
            command = NmtCommand(frame.data[0])
        except ValueError:
            return []
        log.debug("simulated node %d: NMT %s", self.node_id, command.name)
        if command is NmtCommand.START:
            self._set_nmt(NmtState.OPERATIONAL)
        elif command is NmtCommand.STOP:
            self._set_nmt(NmtState.STOPPED)
        elif command is NmtCommand.ENTER_PRE_OPERATIONAL:
            self._set_nmt(NmtState.PRE_OPERATIONAL)
        elif command is NmtCommand.RESET_NODE:
            self._power_on()
            self.model.armed = False
        else:
            self.od.reset_communication()
            self._reset_comm_state()
            self.nmt, self._boot_pending = NmtState.PRE_OPERATIONAL, True
        return []

    def _set_nmt(self, state: NmtState) -> None:
        self.nmt = state
        if state is not NmtState.OPERATIONAL:
            self._pending.clear()  # (no RPDO is kept for later outside OPERATIONAL)

    def _communication_error(self) -> None:
        """A heartbeat event: the NMT state as 0x1029:01 says (see the module)."""
        behaviour = self.od.get(ObjectIndex.ERROR_BEHAVIOUR, 1, default=FACTORY_ERROR_BEHAVIOUR)
        if behaviour == 0 and self.nmt is NmtState.OPERATIONAL:
            self._set_nmt(NmtState.PRE_OPERATIONAL)
        elif behaviour == 2:  # (1: no state change)
            self._set_nmt(NmtState.STOPPED)

    def _on_sdo(self, frame: Frame) -> list[Frame]:
        n = self.node_id
        try:
            req = parse_sdo_request(frame)
        except DecodeError:
            if len(frame.data) != 8:
                return []
            index, sub = frame.data[1] | frame.data[2] << 8, frame.data[3]
            self.aborts += 1
            return [make_sdo_abort(n, index, sub, SdoAbortCode.INVALID_COMMAND_SPECIFIER)]
        if req.command is ClientCommand.ABORT:
            return []
        if req.command is ClientCommand.INITIATE_DOWNLOAD:
            if req.index in self.ignored_writes:
                return [make_sdo_download_ack(n, req.index, req.subindex)]
            abort = self._write(req.index, req.subindex, req.data, sdo=True)
            if abort is None:
                return [make_sdo_download_ack(n, req.index, req.subindex)]
        else:
            self._refresh()
            entry = self.od.lookup(req.index, req.subindex)
            if not isinstance(entry, SdoAbortCode):
                return [make_sdo_upload_response(n, req.index, req.subindex, entry.value,
                                                 entry.dtype)]
            abort = entry
        self.aborts += 1
        return [make_sdo_abort(n, req.index, req.subindex, abort)]

    # ----------------------------------------------------------------- device

    def _step_states(self) -> None:
        """Automatic transitions, the RPDO watchdog, and what the motor is told to do."""
        if self.state is State.NOT_READY_TO_SWITCH_ON:
            self.state = State.SWITCH_ON_DISABLED  # transition 1
        elif self.state is State.FAULT_REACTION_ACTIVE:
            self.state = State.FAULT  # transition 14
        if (self.command_timeout_s is not None and self.state is State.OPERATION_ENABLED
                and self._last_rpdo_s is not None
                and self._now - self._last_rpdo_s > self.command_timeout_s):
            self._raise_fault(0x8250, ErrorRegister.GENERIC | ErrorRegister.COMMUNICATION)
        self._refresh()
        model = self.model
        if self.state is State.QUICK_STOP_ACTIVE:
            self._quick_stop()
            return
        self._ramp = None
        model.armed = self.state in _OPERATING
        mode = self.od.get(0x6061)
        follow = self._following()
        if follow and mode == OperationMode.CYCLIC_SYNCHRONOUS_POSITION:
            model.target_position_rad = self._target_position_rad()
            return
        model.target_position_rad = None  # velocity mode, or stopping
        target = self.od.get(0x60FF) if follow and mode == OperationMode.PROFILE_VELOCITY else 0
        model.target_rad_s = self.opts.units_to_rad_s(target)

    def _target_position_rad(self) -> float:
        """0x607A as a model position: the int32 target modulo 2^32 from where the motor is."""
        model = self.model
        here = self.initial_position + self.opts.rad_to_counts(model.position_rad)
        delta = (self.od.get(0x607A) - here + (1 << 31)) % (1 << 32) - (1 << 31)
        return model.position_rad + delta * (2.0 * math.pi) / self.opts.counts_per_rev

    def _on_tick(self, now_s: float) -> list[Frame]:
        self._now = now_s
        out: list[Frame] = []
        if self._boot_pending:
            self._boot_pending = False
            out.append(make_heartbeat(self.node_id, NmtState.BOOT_UP))
        if self.consumer.expired(now_s):
            self._connection_lost()  # CiA 402: 0x6007
            self._communication_error()  # CiA 301: 0x1029:01
        self._step_states()
        if self.nmt is not NmtState.STOPPED:
            out += self._emcy_out
            self._emcy_out = []
        period_ms = self.od.get(0x1017)
        if period_ms and (self._last_hb_s is None
                          or now_s - self._last_hb_s >= period_ms / 1000.0 - 1e-9):
            self._last_hb_s = now_s
            out.append(make_heartbeat(self.node_id, self.nmt))
        if self.nmt is NmtState.OPERATIONAL:
            out += self._event_tpdos(now_s)
        return out
