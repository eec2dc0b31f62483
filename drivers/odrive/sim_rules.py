"""Firmware rules of the simulated ODrive axis (:mod:`drivers.odrive.sim`) kept apart from its
state: the 0.6 parameter access (Get_Version, the watchdog's two endpoints over RxSdo/TxSdo),
and what the 0.5 controller does with non-finite inputs.

Non-finite inputs (0.5.6 firmware, `odriverobotics/ODrive
<https://github.com/odriverobotics/ODrive/tree/fw-v0.5.6/Firmware>`_): ``can_simple.cpp``
stores Set_Input_Vel's and Set_Input_Pos' floats in ``input_vel_``, ``input_torque_`` and
``input_pos_`` without a check, and ``MotorControl/controller.cpp`` (``Controller::update``)
has none either:

* a NaN passes ``std::clamp`` (every comparison with NaN is false), so the torque output turns
  NaN, the current controller's modulation too, and ``MotorControl/foc.cpp``
  (``AlphaBetaFrameController::get_output``) returns ``ERROR_MODULATION_IS_NAN``, which
  ``MotorControl/motor.cpp`` (``Motor::pwm_update_cb``, ``disarm_with_error``) latches as the
  motor error with the axis error ``MOTOR_FAILED`` and disarms: the axis falls back to IDLE.
  Only inputs the control and input modes use count (:func:`nan_reaches_output`), and only
  while the axis runs its controller (CLOSED_LOOP_CONTROL); a NaN taken in IDLE waits there;
* an infinity is clamped to ``vel_limit`` (``enable_vel_limit``, on from the factory), 2 turn/s
  from the factory (``MotorControl/controller.hpp``): :data:`FACTORY_VEL_LIMIT_TURNS_S`.
"""

from __future__ import annotations

import math
import struct
from typing import TYPE_CHECKING, Protocol

from drivers.odrive.enums import CmdId, ControlMode, InputMode
from drivers.odrive.watchdog import OPCODE_READ, OPCODE_WRITE, TX_SDO, parse_sdo, version_reply
from gateway.core.types import Frame

if TYPE_CHECKING:
    from drivers.odrive.codec import OdriveCodec
    from drivers.odrive.watchdog import WatchdogEndpoints

#: ``(firmware, hardware)`` version a 0.6 axis without watchdog endpoints reports in
#: Get_Version: 0.0.0, which no real ODrive reports (the demo's endpoints name it too).
FACTORY_VERSION = ("0.0.0", "")
#: ``controller.config.vel_limit`` from the factory (turn/s, 0.5 ``controller.hpp``).
FACTORY_VEL_LIMIT_TURNS_S = 2.0


class ParameterAxis(Protocol):
    """What the 0.6 parameter access reads and writes of a simulated axis."""

    codec: OdriveCodec
    endpoints: WatchdogEndpoints | None
    watchdog_enabled: bool
    watchdog_timeout_s: float

    @property
    def node_id(self) -> int: ...


def parameter_access(axis: ParameterAxis, frame: Frame, cmd: int) -> list[Frame]:
    """Get_Version (RTR or DLC 0), and RxSdo for the watchdog's two endpoints (0.6): reads
    answer with TxSdo, writes are taken without an answer (firmware before 0.6.11), other
    endpoints get no answer."""
    arb, ext = axis.codec.arbitration_id, axis.codec.extended_id
    ep = axis.endpoints
    if cmd == CmdId.GET_VERSION:
        if frame.dlc != 0:
            return []  # not a request
        fw, hw = FACTORY_VERSION if ep is None else (ep.fw_version, ep.hw_version)
        return [Frame(arb(axis.node_id, CmdId.GET_VERSION), version_reply(fw, hw), ext)]
    sdo = parse_sdo(frame.data)
    if ep is None or sdo is None:
        return []
    opcode, endpoint, value = sdo
    if endpoint not in (ep.enable_id, ep.timeout_id):
        return []
    fmt = "<?" if endpoint == ep.enable_id else "<f"
    if opcode == OPCODE_WRITE:
        if len(value) < struct.calcsize(fmt):
            return []
        (x,) = struct.unpack_from(fmt, value)
        if endpoint == ep.enable_id:
            axis.watchdog_enabled = bool(x)
        else:
            axis.watchdog_timeout_s = float(x)
        return []
    if opcode != OPCODE_READ:
        return []
    current = axis.watchdog_enabled if endpoint == ep.enable_id else axis.watchdog_timeout_s
    head = struct.pack("<BHB", OPCODE_READ, endpoint, 0)
    return [Frame(arb(axis.node_id, TX_SDO), head + struct.pack(fmt, current), ext)]


def nan_reaches_output(
    control_mode: int, input_mode: int, pos: float, vel: float, torque: float
) -> bool:
    """Whether a NaN among the controller's inputs (``input_pos_``, ``input_vel_``,
    ``input_torque_``) reaches its torque output in 0.5.6 ``Controller::update``.

    VEL_RAMP ramps ``vel_setpoint_`` towards ``input_vel_`` and feeds the ramp's step to the
    torque setpoint, which every control mode adds; the other input modes are taken as
    PASSTHROUGH (the simulator models no other), where the torque input always counts, the
    speed input from VELOCITY_CONTROL on and the position input in POSITION_CONTROL.
    """
    if input_mode == InputMode.VEL_RAMP:
        used = [vel]
    else:
        used = [torque]
        if control_mode >= ControlMode.VELOCITY_CONTROL:
            used.append(vel)
        if control_mode >= ControlMode.POSITION_CONTROL:
            used.append(pos)
    return any(math.isnan(x) for x in used)


def limited(turns_s: float) -> float:
    """A speed input as the controller takes it in this model: an infinity clamped to the
    factory ``vel_limit`` (a finite speed is not limited: the simulator has no velocity
    limit)."""
    return math.copysign(FACTORY_VEL_LIMIT_TURNS_S, turns_s) if math.isinf(turns_s) else turns_s
