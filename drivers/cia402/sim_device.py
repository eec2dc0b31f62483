"""The CiA 402 device control of the simulated drive (:class:`DriveControl`, a part of
:class:`~drivers.cia402.sim.Cia402Simulator`): controlwords with their transition delays, the
fault reaction, the quick stop as 0x605A says, and the reaction to a lost heartbeat as 0x6007
says.  The pure parts, and the sources of their behaviour, are in
:mod:`drivers.cia402.sim_control`.
"""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING

from drivers.cia402.codec import make_emcy
from drivers.cia402.enums import ObjectIndex, State
from drivers.cia402.faults import ErrorRegister
from drivers.cia402.sim_control import (
    STAY_IN_QUICK_STOP,
    QuickStopRamp,
    next_state,
    quick_stop_deceleration,
)
from drivers.cia402.sim_od import FACTORY_QUICK_STOP_OPTION
from gateway.sim.device import SimFault

if TYPE_CHECKING:
    from drivers.cia402.options import Cia402Options
    from drivers.cia402.sim_control import HeartbeatConsumer, Timing
    from drivers.cia402.sim_od import SimObjectDictionary
    from gateway.core.types import Frame
    from gateway.sim.device import MotorModel

log = logging.getLogger(__name__)

#: States in which the power stage is on.
POWERED = frozenset({State.READY_TO_SWITCH_ON, State.SWITCHED_ON, State.OPERATION_ENABLED,
                     State.QUICK_STOP_ACTIVE})


class DriveControl:
    """The device control of a simulated CiA 402 drive.

    The simulator that inherits it provides the attributes below; the state changes when a
    commanded transition is done (:meth:`_enter`), :attr:`_transition` holds one under way.
    """

    node_id: int
    opts: Cia402Options
    od: SimObjectDictionary
    model: MotorModel
    faults: SimFault
    timing: Timing
    consumer: HeartbeatConsumer
    #: The drive state the statusword reports.
    state: State
    _now: float
    _controlword: int
    _transition: tuple[State, float] | None
    _ramp: QuickStopRamp | None
    _error_register: int
    _emcy_out: list[Frame]
    _last_rpdo_s: float | None

    def _apply_controlword(self, cw: int) -> None:
        rising_reset = bool(cw & 0x80) and not self._controlword & 0x80
        self._controlword = cw
        st = self.state
        target = next_state(st, cw, rising_reset=rising_reset,
                            fault_active=bool(self.faults & SimFault.FAULT),
                            quick_stop_option=self._quick_stop_option())
        if target is st:
            if st is not State.FAULT:  # (a fault reset, once taken, completes)
                self._transition = None  # the master no longer asks for it
            return
        if self._transition is not None and self._transition[0] is target:
            return  # under way: a repeated controlword does not restart it
        delay = self.timing.delay(target)
        if delay > 0.0:
            self._transition = (target, self._now + delay)
        else:
            self._enter(target)

    def _enter(self, state: State) -> None:
        """Take ``state`` now (a transition that is done)."""
        was, self.state, self._transition = self.state, state, None
        if was is State.FAULT and state is State.SWITCH_ON_DISABLED:  # 15: fault reset
            self._error_register = 0
            self._emcy_out.append(make_emcy(self.node_id, 0x0000, 0))
        if state is State.OPERATION_ENABLED and was is not State.OPERATION_ENABLED:
            self._last_rpdo_s = self._now

    def _quick_stop_option(self) -> int:
        return self.od.get(ObjectIndex.QUICK_STOP_OPTION_CODE, default=FACTORY_QUICK_STOP_OPTION)

    def _raise_fault(self, code: int, register: int) -> None:
        if self.state in (State.FAULT, State.FAULT_REACTION_ACTIVE):
            return
        log.info("simulated node %d: fault, EMCY 0x%04X", self.node_id, code)
        self.state, self._transition = State.FAULT_REACTION_ACTIVE, None
        self._error_register = register
        self._emcy_out.append(make_emcy(self.node_id, code, register))

    def _connection_lost(self) -> None:
        """A heartbeat event: EMCY 0x8130, then what 0x6007 says (see the module)."""
        option = self.od.get(ObjectIndex.ABORT_CONNECTION_OPTION_CODE)
        log.info("simulated node %d: heartbeat of node %d lost, 0x6007 = %d", self.node_id,
                 self.consumer.node_id, option)
        register = ErrorRegister.GENERIC | ErrorRegister.COMMUNICATION
        if option == 1:  # fault signal
            self._raise_fault(0x8130, register)
            return
        self._emcy_out.append(make_emcy(self.node_id, 0x8130, register))
        st = self.state
        if option == 2 and st in POWERED:  # disable voltage
            self._enter(State.SWITCH_ON_DISABLED)
        elif option == 3 and st is State.OPERATION_ENABLED:  # quick stop
            self._enter(State.QUICK_STOP_ACTIVE)
        elif option == 3 and st in (State.READY_TO_SWITCH_ON, State.SWITCHED_ON):
            self._enter(State.SWITCH_ON_DISABLED)

    def _quick_stop(self) -> None:
        """QUICK STOP ACTIVE: ramp to standstill as 0x605A says, then SWITCH ON DISABLED
        (1 to 4) or stay (5 to 8); 0: switch off at once (the motor coasts)."""
        model, opts, od = self.model, self.opts, self.od
        option = self._quick_stop_option()
        decel = quick_stop_deceleration(
            option, opts.units_to_rad_s(od.get(ObjectIndex.PROFILE_DECELERATION)),
            opts.units_to_rad_s(od.get(ObjectIndex.QUICK_STOP_DECELERATION)))
        model.target_position_rad = None
        if decel is None:
            self._enter(State.SWITCH_ON_DISABLED)
            model.armed = False
            return
        if self._ramp is None:
            self._ramp = QuickStopRamp(model.velocity_rad_s, decel, self._now)
        model.armed = True
        model.target_rad_s = self._ramp.step(self._now)
        stopped = abs(opts.rad_s_to_units(model.velocity_rad_s)) < opts.velocity_factor
        if model.target_rad_s == 0.0 and stopped and option not in STAY_IN_QUICK_STOP:
            self._enter(State.SWITCH_ON_DISABLED)  # 12, automatic
            model.armed, self._ramp = False, None

    def _following(self) -> bool:
        """Whether the motor follows the target: OPERATION ENABLED and halt (bit 8) clear."""
        return self.state is State.OPERATION_ENABLED and not self._controlword & 0x100
