"""Simulated ODrive axis: the device side of CANSimple, for tests and ``--sim``.

Reference: the 0.5.6 firmware's `can_simple.cpp <https://github.com/odriverobotics/ODrive/
blob/fw-v0.5.6/Firmware/communication/can/can_simple.cpp>`_ (``do_command``,
``service_stack``, ``send_heartbeat``), ``Firmware/MotorControl/axis.cpp`` and ``main.cpp`` of
odriverobotics/ODrive, and the `ODrive CAN protocol
<https://docs.odriverobotics.com/v/latest/manual/can-protocol.html>`_.

Modelled behaviour:

* heartbeat every ``heartbeat_period_s`` (firmware default 100 ms), encoder estimates every
  ``encoder_period_s`` (default 10 ms; 0 turns the cyclic stream off), both from the axis's
  own phase (:attr:`~gateway.sim.device.DeviceSimulator.phase`), answers to RTR requests
  (0.5 also answers DLC 0 data frames) for the encoder estimates and Get_Error /
  Get_Motor_Error, and in 0.6 (unverified) for the heartbeat; 0.5 ignores a heartbeat request
  (``do_command``: "We don't currently do anything to respond to ODrive heartbeat messages");
* axis states IDLE <-> CLOSED_LOOP_CONTROL through Set_Axis_State; arming is refused while an
  error is latched, and by an axis built with ``calibrated=False`` (see the class); other
  requested states are ignored;
* the speed follows Set_Input_Vel only in velocity control, ramped at
  ``vel_ramp_rate_turns_s2`` in VEL_RAMP input mode; in position control (the firmware default)
  the axis follows Set_Input_Pos with its speed feed-forward (the model's position loop) and,
  when armed, first holds where it stands (0.5 ``Axis::run_closed_loop_control_loop`` sets the
  input position to the estimate);
* non-finite inputs as the 0.5.6 controller takes them (:mod:`drivers.odrive.sim_rules`): a
  NaN the armed controller uses latches MOTOR_FAILED with the motor error MODULATION_IS_NAN
  and disarms; an infinity runs the axis at the factory ``vel_limit``.  0.6 (closed firmware,
  behaviour not published) is assumed to fault the same way, with SYSTEM_LEVEL;
* watchdog: **off, as from the factory** (``axis.config.enable_watchdog`` false), unless the
  simulator is built with ``watchdog_timeout_s`` (a device configured and saved with
  odrivetool) or the gateway enables it over CAN (0.6); fed at start (boot,
  ``Axis::apply_config``).  0.5: any frame addressed to the axis feeds it (``do_command``
  calls ``watchdog_feed()`` first), and ``main.cpp`` runs ``Axis::watchdog_check`` every control
  loop **in every state**: once expired it latches WATCHDOG_TIMER_EXPIRED, in IDLE too, so a
  saved-watchdog axis nobody talks to reports 0x800 in its heartbeat (Clear_Errors feeds it
  before it clears).  0.6 (closed firmware): only Set_Input_Pos/Vel/Torque and Set_Axis_State
  feed it, the stricter reading of the official ``can_watchdog.py`` example, and it is
  checked in CLOSED_LOOP_CONTROL only (what 0.6 does in IDLE is not published).  Expired in
  CLOSED_LOOP_CONTROL it disarms (the motor coasts);
* 0.6 Get_Version requests (RTR or DLC 0) are answered, as the firmware answers any ``Get_*``
  request, with the endpoints' firmware and hardware version, or :data:`FACTORY_VERSION`
  without endpoints; 0.5 has no Get_Version (command 0x00 is CANopen NMT's there) and ignores
  it;
* 0.6 parameter access, for the watchdog's two endpoints only (``endpoints``, the IDs the
  motor block names): RxSdo reads answer with TxSdo, writes are taken without an answer
  (firmware before 0.6.11); other endpoints get no answer;
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
from drivers.odrive.commands import (
    ClearErrors,
    Estop,
    Request,
    SetAxisState,
    SetControllerMode,
    SetInputPos,
    SetInputVel,
    decode_command,
)
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
from drivers.odrive.messages import ErrorStatus, Heartbeat, MotorErrorStatus
from drivers.odrive.options import OdriveOptions
from drivers.odrive.sim_rules import (
    FACTORY_VERSION,
    limited,
    nan_reaches_output,
    parameter_access,
)
from drivers.odrive.watchdog import RX_SDO, endpoints_from_options
from gateway.core.cadence import next_due
from gateway.core.errors import DecodeError
from gateway.sim.device import DeviceSimulator, SimFault

if TYPE_CHECKING:
    from drivers.odrive.watchdog import WatchdogEndpoints
    from gateway.core.types import Frame, MotorConfig
    from gateway.sim.device import MotorModel

__all__ = ["FACTORY_VERSION", "OdriveSimulator", "simulator_for"]

log = logging.getLogger(__name__)

TAU = 2.0 * math.pi


class OdriveSimulator(DeviceSimulator):
    """One simulated ODrive axis.

    :param motor: the motor block (``firmware`` and ``extended_id`` keys select the codec).
    :param model: the motor physics; a default model when omitted.
    :param watchdog_timeout_s: the axis watchdog as saved on the device (s); 0 (the factory
        setting) leaves it off.
    :param endpoints: 0.6: the watchdog's endpoint IDs and the firmware version the axis
        reports (``None``: no parameter access is simulated).
    :param heartbeat_period_s: heartbeat period (s).
    :param encoder_period_s: encoder-estimates period (s); 0 disables the cyclic stream.
    :param initial_position_turns: position estimate at start (turns).
    :param vel_ramp_rate_turns_s2: ramp rate of the VEL_RAMP input mode (turns/s^2).
    :param calibrated: the motor and encoder calibrated (default), as a robot builder leaves an
        axis after odrivetool's calibration with ``motor.config.pre_calibrated`` and
        ``encoder.config.pre_calibrated`` saved.  **The factory axis is not calibrated**
        (``pre_calibrated`` false): ``False`` models it, and a CLOSED_LOOP_CONTROL request
        then leaves the axis in IDLE, 0.5 latching INVALID_STATE (``axis.cpp``
        ``run_state_machine_loop``: ``!motor_.is_calibrated_`` goes to
        ``invalid_state_label``), 0.6 reporting the procedure result NOT_CALIBRATED.
    """

    def __init__(
        self,
        motor: MotorConfig,
        model: MotorModel | None = None,
        *,
        watchdog_timeout_s: float = 0.0,
        endpoints: WatchdogEndpoints | None = None,
        heartbeat_period_s: float = 0.1,
        encoder_period_s: float = 0.01,
        initial_position_turns: float = 0.0,
        vel_ramp_rate_turns_s2: float = 20.0,
        calibrated: bool = True,
    ) -> None:
        super().__init__(motor, model)
        self.codec = OdriveCodec.from_options(motor.options)
        #: ``axis.config.watchdog_timeout`` (s) and ``enable_watchdog``.
        self.watchdog_timeout_s = watchdog_timeout_s
        self.watchdog_enabled = watchdog_timeout_s > 0.0
        self.endpoints = endpoints
        self.heartbeat_period_s = heartbeat_period_s
        self.encoder_period_s = encoder_period_s
        self.initial_position_turns = initial_position_turns
        self.vel_ramp_rate_turns_s2 = vel_ramp_rate_turns_s2
        self.calibrated = calibrated
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
        #: The firmware's ``input_vel_`` and ``input_torque_``, which Set_Input_Vel and
        #: Set_Input_Pos both write, for the non-finite check.
        self.input_vel_reg = 0.0
        self.input_torque_nm = 0.0
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
        v06 = self.codec.firmware is Firmware.V0_6
        if not v06:
            self._last_fed_s = now_s
        elif ids[1] == CmdId.GET_VERSION or (self.endpoints is not None and ids[1] == RX_SDO):
            return self._parameter_access(frame, ids[1])
        if v06 and ids[1] in _FEEDS_06:
            self._last_fed_s = now_s
        try:
            cmd = decode_command(self.codec, frame)
        except DecodeError as err:
            log.debug("simulated ODrive %d ignores %s: %s", self.node_id, frame.to_cansend(), err)
            return []
        if isinstance(cmd, SetInputVel):
            self.input_vel_turns_s = self.input_vel_reg = cmd.vel_turns_s
            self.input_torque_nm = cmd.torque_ff_nm
        elif isinstance(cmd, SetInputPos):
            self.input_pos_turns = cmd.pos_turns
            self.input_vel_ff_turns_s = self.input_vel_reg = cmd.vel_ff_turns_s
            self.input_torque_nm = cmd.torque_ff_nm
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
        if self._last_fed_s is None:
            self._last_fed_s = now_s  # fed at boot
        if (
            self.watchdog_enabled
            and (closed_loop or self.codec.firmware is Firmware.V0_5)
            and now_s - self._last_fed_s > self.watchdog_timeout_s
        ):
            self._latch(AxisError.WATCHDOG_TIMER_EXPIRED, AxisError05.WATCHDOG_TIMER_EXPIRED)
        if self.axis_state == AxisState.CLOSED_LOOP_CONTROL and nan_reaches_output(
            self.control_mode, self.input_mode, self.input_pos_turns, self.input_vel_reg,
            self.input_torque_nm,
        ):
            if self.codec.firmware is Firmware.V0_5:
                self.motor_error |= MotorError05.MODULATION_IS_NAN
            self._latch(AxisError.SYSTEM_LEVEL, AxisError05.MOTOR_FAILED)
        self._update_setpoint(dt)
        out: list[Frame] = []
        self._next_heartbeat_s = self.due(self._next_heartbeat_s, now_s, self.heartbeat_period_s)
        if now_s >= self._next_heartbeat_s:
            out.append(self._heartbeat())
            self._next_heartbeat_s = next_due(
                self._next_heartbeat_s, now_s, self.heartbeat_period_s
            )
        if self.encoder_period_s > 0.0:
            due = self._next_encoder_s = self.due(self._next_encoder_s, now_s,
                                                  self.encoder_period_s)
            if now_s >= due:
                out.append(self._estimates())
                self._next_encoder_s = next_due(due, now_s, self.encoder_period_s)
        return out

    def _on_fault(self) -> None:
        if self.codec.firmware is Firmware.V0_5:
            self.motor_error |= MotorError05.DRV_FAULT
        self._latch(AxisError.DRV_FAULT, AxisError05.MOTOR_FAILED)

    # ----------------------------------------------------------------- behaviour

    def _request_state(self, state: AxisState | int) -> None:
        v05 = self.codec.firmware is Firmware.V0_5
        if v05:
            self.axis_error &= ~AxisError05.INVALID_STATE  # auto-cleared by a new request
        if state == AxisState.IDLE:
            self._disarm()
        elif state == AxisState.CLOSED_LOOP_CONTROL:
            if not self.calibrated:
                log.debug("simulated ODrive %d refuses to arm: not calibrated", self.node_id)
                if v05:
                    self.axis_error |= AxisError05.INVALID_STATE
                self.procedure_result = ProcedureResult.NOT_CALIBRATED
                self._disarm()
                return
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
        pos, mode = self.input_pos_turns, self.control_mode
        if mode == ControlMode.POSITION_CONTROL:
            ff = self.input_vel_ff_turns_s
            model.target_position_rad = (pos - self.initial_position_turns) * TAU
            if math.isinf(pos):  # the position loop saturates at vel_limit
                model.target_position_rad, ff = None, limited(pos)
            model.velocity_ff_rad_s = ff * TAU
            self.setpoint_turns_s = ff if armed else 0.0
            model.target_rad_s = self.setpoint_turns_s * TAU
            return
        model.target_position_rad = None
        target = limited(self.input_vel_turns_s) if armed else 0.0
        if mode != ControlMode.VELOCITY_CONTROL:
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

    def _parameter_access(self, frame: Frame, cmd: int) -> list[Frame]:
        """Get_Version, and RxSdo for the watchdog's endpoints (0.6; :mod:`.sim_rules`)."""
        return parameter_access(self, frame, cmd)

    def _answer(self, cmd: CmdId) -> list[Frame]:
        if cmd == CmdId.HEARTBEAT:  # 0.5 ignores it (see the module)
            return [self._heartbeat()] if self.codec.firmware is Firmware.V0_6 else []
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


#: The 0.6 commands that feed the watchdog in this model (see the module docstring).
_FEEDS_06 = frozenset({CmdId.SET_INPUT_POS, CmdId.SET_INPUT_VEL, CmdId.SET_INPUT_TORQUE,
                       CmdId.SET_AXIS_STATE})


def simulator_for(motor: MotorConfig) -> DeviceSimulator:
    """An :class:`OdriveSimulator` for ``motor``, as the motor block says it was configured:
    at factory settings (watchdog off) with the 0.6 endpoint IDs it names, or with the watchdog
    it states (``controller_timeout_s``) saved; its heartbeat and estimates at the periods the
    block states (:data:`drivers.BUILTIN_SIMULATORS`).

    :raises ConfigError: for a bad protocol key or bad endpoint keys.
    """
    where = f"motor {motor.wheel!r}"
    options = OdriveOptions.from_block(motor.options, where)
    endpoints = endpoints_from_options(options, where)
    beat, estimates = options.heartbeat_msg_rate_ms / 1000.0, options.encoder_msg_rate_ms / 1000.0
    if endpoints is not None:
        return OdriveSimulator(motor, endpoints=endpoints, heartbeat_period_s=beat,
                               encoder_period_s=estimates)
    return OdriveSimulator(motor, watchdog_timeout_s=options.controller_timeout_s,
                           heartbeat_period_s=beat, encoder_period_s=estimates)
