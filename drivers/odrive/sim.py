"""Simulated ODrive axis: the device side of CANSimple, for tests and ``--sim``.

Reference: the 0.5.x firmware's `can_simple.cpp <https://github.com/odriverobotics/ODrive/
blob/master/Firmware/communication/can/can_simple.cpp>`_ (``do_command``, ``service_stack``,
``send_heartbeat``) and the `ODrive CAN protocol
<https://docs.odriverobotics.com/v/latest/manual/can-protocol.html>`_.

Modelled behaviour:

* heartbeat every ``heartbeat_period_s`` (firmware default 100 ms), encoder estimates every
  ``encoder_period_s`` (default 10 ms; 0 turns the cyclic stream off), answers to RTR requests
  (0.5 also answers DLC 0 data frames) for the heartbeat, encoder estimates and Get_Error /
  Get_Motor_Error;
* axis states IDLE <-> CLOSED_LOOP_CONTROL through Set_Axis_State; arming is refused while an
  error is latched; other requested states are ignored;
* the speed follows Set_Input_Vel only in velocity control, ramped at
  ``vel_ramp_rate_turns_s2`` in VEL_RAMP input mode; in position control (the firmware default)
  the axis follows Set_Input_Pos with its speed feed-forward (the model's position loop) and,
  when armed, first holds where it stands (0.5 ``Axis::run_closed_loop_control_loop`` sets the
  input position to the estimate);
* watchdog: any frame addressed to the axis feeds it (0.5 ``do_command`` calls
  ``watchdog_feed()`` first); ``watchdog_timeout_s`` without one in CLOSED_LOOP_CONTROL latches
  WATCHDOG_TIMER_EXPIRED and disarms;
* an injected FAULT latches DRV_FAULT (0.6) or MOTOR_FAILED + motor DRV_FAULT (0.5) and
  disarms; Clear_Errors clears, but latches again at once while the injected cause remains;
* Estop latches ESTOP_REQUESTED and disarms;
* the position is reported as float32 turns (quantised like the firmware), starting at
  ``initial_position_turns`` so tests can check the precision far from zero.
"""

from __future__ import annotations

import logging
import math
from typing import TYPE_CHECKING

from drivers.odrive.codec import OdriveCodec
from drivers.odrive.enums import (
    AxisError,
    AxisError05,
    AxisState,
    CmdId,
    ControlMode,
    Firmware,
    InputMode,
    MotorError05,
    ProcedureResult,
)
from drivers.odrive.messages import (
    ClearErrors,
    ErrorStatus,
    Estop,
    Heartbeat,
    MotorErrorStatus,
    Request,
    SetAxisState,
    SetControllerMode,
    SetInputPos,
    SetInputVel,
)
from gateway.errors import DecodeError
from gateway.sim import DeviceSimulator, SimFault

if TYPE_CHECKING:
    from gateway.sim import MotorModel
    from gateway.types import Frame, MotorConfig

log = logging.getLogger(__name__)

TAU = 2.0 * math.pi


class OdriveSimulator(DeviceSimulator):
    """One simulated ODrive axis.

    :param motor: the motor block (``firmware`` and ``extended_id`` keys select the codec).
    :param model: the motor physics; a default model when omitted.
    :param watchdog_timeout_s: axis watchdog timeout (s); 0 disables it.
    :param heartbeat_period_s: heartbeat period (s).
    :param encoder_period_s: encoder-estimates period (s); 0 disables the cyclic stream.
    :param initial_position_turns: position estimate at start (turns).
    :param vel_ramp_rate_turns_s2: ramp rate of the VEL_RAMP input mode (turns/s^2).
    """

    def __init__(
        self,
        motor: MotorConfig,
        model: MotorModel | None = None,
        *,
        watchdog_timeout_s: float = 0.5,
        heartbeat_period_s: float = 0.1,
        encoder_period_s: float = 0.01,
        initial_position_turns: float = 0.0,
        vel_ramp_rate_turns_s2: float = 20.0,
    ) -> None:
        super().__init__(motor, model)
        self.codec = OdriveCodec.from_options(motor.options)
        self.watchdog_timeout_s = watchdog_timeout_s
        self.heartbeat_period_s = heartbeat_period_s
        self.encoder_period_s = encoder_period_s
        self.initial_position_turns = initial_position_turns
        self.vel_ramp_rate_turns_s2 = vel_ramp_rate_turns_s2
        #: Device state, inspectable by tests.
        self.axis_state = AxisState.IDLE
        self.axis_error = 0
        self.disarm_reason = 0
        self.motor_error = 0
        self.procedure_result = ProcedureResult.SUCCESS
        self.control_mode = int(ControlMode.POSITION_CONTROL)
        self.input_mode = int(InputMode.PASSTHROUGH)
        self.input_vel_turns_s = 0.0
        self.input_pos_turns = self.position_turns
        self.input_vel_ff_turns_s = 0.0
        self.setpoint_turns_s = 0.0
        self._last_fed_s: float | None = None
        self._next_heartbeat_s: float | None = None
        self._next_encoder_s: float | None = None
        self._last_tick_time_s: float | None = None

    @property
    def node_id(self) -> int:
        """The axis node ID."""
        return self.motor.node_id

    @property
    def position_turns(self) -> float:
        """The exact (float64) position estimate in turns, before float32 rounding."""
        return self.initial_position_turns + self.model.position_rad / TAU

    # ----------------------------------------------------------------- hooks

    def _on_frame(self, frame: Frame, now_s: float) -> list[Frame]:
        ids = self.codec.split_id(frame)
        if ids is None or ids[0] != self.node_id:
            return []
        self._last_fed_s = now_s
        try:
            cmd = self.codec.decode_command(frame)
        except DecodeError as err:
            log.debug("simulated ODrive %d ignores %s: %s", self.node_id, frame.to_cansend(), err)
            return []
        if isinstance(cmd, SetInputVel):
            self.input_vel_turns_s = cmd.vel_turns_s
        elif isinstance(cmd, SetInputPos):
            self.input_pos_turns = cmd.pos_turns
            self.input_vel_ff_turns_s = cmd.vel_ff_turns_s
        elif isinstance(cmd, SetAxisState):
            self._request_state(cmd.state)
        elif isinstance(cmd, SetControllerMode):
            self.control_mode, self.input_mode = cmd.control_mode, cmd.input_mode
        elif isinstance(cmd, ClearErrors):
            self._clear_errors()
        elif isinstance(cmd, Estop):
            self._latch(AxisError.ESTOP_REQUESTED, AxisError05.ESTOP_REQUESTED)
        elif isinstance(cmd, Request):
            return self._answer(cmd.cmd)
        return []

    def _on_tick(self, now_s: float) -> list[Frame]:
        dt = 0.0 if self._last_tick_time_s is None else now_s - self._last_tick_time_s
        self._last_tick_time_s = now_s
        closed_loop = self.axis_state == AxisState.CLOSED_LOOP_CONTROL
        fed = self._last_fed_s
        if (
            closed_loop
            and self.watchdog_timeout_s > 0.0
            and fed is not None
            and now_s - fed > self.watchdog_timeout_s
        ):
            self._latch(AxisError.WATCHDOG_TIMER_EXPIRED, AxisError05.WATCHDOG_TIMER_EXPIRED)
        self._update_setpoint(dt)
        out: list[Frame] = []
        if self._next_heartbeat_s is None or now_s >= self._next_heartbeat_s:
            out.append(self._heartbeat())
            self._next_heartbeat_s = _next_due(
                self._next_heartbeat_s, now_s, self.heartbeat_period_s
            )
        if self.encoder_period_s > 0.0 and (
            self._next_encoder_s is None or now_s >= self._next_encoder_s
        ):
            out.append(self._estimates())
            self._next_encoder_s = _next_due(self._next_encoder_s, now_s, self.encoder_period_s)
        return out

    def _on_fault(self) -> None:
        if self.codec.firmware is Firmware.V0_5:
            self.motor_error |= MotorError05.DRV_FAULT
        self._latch(AxisError.DRV_FAULT, AxisError05.MOTOR_FAILED)

    # ----------------------------------------------------------------- behaviour

    def _request_state(self, state: AxisState | int) -> None:
        if state == AxisState.IDLE:
            self._disarm()
        elif state == AxisState.CLOSED_LOOP_CONTROL:
            if self.axis_error or self.motor_error:
                log.debug("simulated ODrive %d refuses to arm: errors latched", self.node_id)
                self.procedure_result = ProcedureResult.DISARMED
                return
            if self.axis_state != AxisState.CLOSED_LOOP_CONTROL:
                self.input_pos_turns = self.position_turns
                self.input_vel_ff_turns_s = 0.0
            self.axis_state = AxisState.CLOSED_LOOP_CONTROL
            self.procedure_result = ProcedureResult.SUCCESS
            self.model.armed = True
        else:
            log.debug("simulated ODrive %d ignores requested state %r", self.node_id, state)

    def _disarm(self) -> None:
        self.axis_state = AxisState.IDLE
        self.model.armed = False
        self.setpoint_turns_s = 0.0

    def _latch(self, error_06: AxisError, error_05: AxisError05) -> None:
        bit = int(error_06 if self.codec.firmware is Firmware.V0_6 else error_05)
        self.axis_error |= bit
        if self.axis_state == AxisState.CLOSED_LOOP_CONTROL:
            self.disarm_reason |= bit
            self.procedure_result = ProcedureResult.DISARMED
        self._disarm()

    def _clear_errors(self) -> None:
        self.axis_error = self.disarm_reason = self.motor_error = 0
        self.procedure_result = ProcedureResult.SUCCESS
        if self.faults & SimFault.FAULT:
            self._on_fault()  # the injected cause is still there

    def _update_setpoint(self, dt: float) -> None:
        armed = self.axis_state == AxisState.CLOSED_LOOP_CONTROL
        model = self.model
        if self.control_mode == ControlMode.POSITION_CONTROL:
            model.target_position_rad = (self.input_pos_turns - self.initial_position_turns) * TAU
            model.velocity_ff_rad_s = self.input_vel_ff_turns_s * TAU
            self.setpoint_turns_s = self.input_vel_ff_turns_s if armed else 0.0
            return
        model.target_position_rad = None
        target = self.input_vel_turns_s if armed else 0.0
        if self.control_mode != ControlMode.VELOCITY_CONTROL:
            target = 0.0
        if self.input_mode == InputMode.VEL_RAMP:
            step = self.vel_ramp_rate_turns_s2 * dt
            target = min(max(target, self.setpoint_turns_s - step), self.setpoint_turns_s + step)
        self.setpoint_turns_s = target
        self.model.target_rad_s = target * TAU

    # ----------------------------------------------------------------- frames

    def _heartbeat(self) -> Frame:
        return self.codec.make_heartbeat(
            Heartbeat(
                self.node_id,
                self.axis_error,
                self.axis_state,
                trajectory_done=True,
                procedure_result=(
                    self.procedure_result
                    if self.codec.firmware is Firmware.V0_6
                    else ProcedureResult.SUCCESS
                ),
                motor_error=self.codec.firmware is Firmware.V0_5 and self.motor_error != 0,
            )
        )

    def _estimates(self) -> Frame:
        return self.codec.make_encoder_estimates(
            self.node_id, self.position_turns, self.model.velocity_rad_s / TAU
        )

    def _answer(self, cmd: CmdId) -> list[Frame]:
        if cmd == CmdId.HEARTBEAT:
            return [self._heartbeat()]
        if cmd == CmdId.GET_ENCODER_ESTIMATES:
            return [self._estimates()]
        if cmd == CmdId.GET_ERROR:
            status: ErrorStatus | MotorErrorStatus = (
                ErrorStatus(self.node_id, self.axis_error, self.disarm_reason)
                if self.codec.firmware is Firmware.V0_6
                else MotorErrorStatus(self.node_id, self.motor_error)
            )
            return [self.codec.make_error_status(status)]
        return []


def _next_due(previous: float | None, now_s: float, period_s: float) -> float:
    """The next due time of a periodic frame, without bursts after a gap."""
    nxt = (now_s if previous is None else previous) + period_s
    return nxt if nxt > now_s else now_s + period_s
