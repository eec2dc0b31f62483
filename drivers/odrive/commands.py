"""ODrive commands as the axis decodes them: the device side of :mod:`drivers.odrive.codec`.

The driver only encodes commands (:class:`~drivers.odrive.codec.OdriveCodec`'s ``make_*``); the
simulator, the monitor's tests and the frame tests decode them back with
:func:`decode_command` into the frozen dataclasses here.  Kept apart from
:mod:`drivers.odrive.messages` so that a process that drives axes never builds these classes.
Layouts and field scales: :mod:`drivers.odrive.messages` (after the official DBC
``odrive-cansimple.dbc``).
"""

from __future__ import annotations

from dataclasses import dataclass
from types import MappingProxyType
from typing import TYPE_CHECKING, TypeAlias

from drivers.odrive.enums import AxisState, CmdId, Firmware
from drivers.odrive.messages import (
    ENCODER_ESTIMATES,
    ESTOP,
    HEARTBEAT,
    INPUT_POS_FF_SCALE,
    SET_AXIS_STATE,
    SET_CONTROLLER_MODE,
    SET_INPUT_POS,
    SET_INPUT_VEL,
)

if TYPE_CHECKING:
    from collections.abc import Mapping

    from drivers.odrive.codec import OdriveCodec
    from gateway.core.types import Frame

__all__ = [
    "ClearErrors",
    "Command",
    "Estop",
    "Request",
    "SetAxisState",
    "SetControllerMode",
    "SetInputPos",
    "SetInputVel",
    "decode_command",
]

_AXIS_STATES: Mapping[int, AxisState] = MappingProxyType({int(s): s for s in AxisState})


@dataclass(frozen=True, slots=True)
class SetInputVel:
    """Set_Input_Vel (0x0D). :param vel_turns_s: turns/s. :param torque_ff_nm: N*m."""

    node_id: int
    vel_turns_s: float
    torque_ff_nm: float = 0.0


@dataclass(frozen=True, slots=True)
class SetInputPos:
    """Set_Input_Pos (0x0C). :param pos_turns: turns. :param vel_ff_turns_s: turns/s.
    :param torque_ff_nm: N*m."""

    node_id: int
    pos_turns: float
    vel_ff_turns_s: float = 0.0
    torque_ff_nm: float = 0.0


@dataclass(frozen=True, slots=True)
class SetAxisState:
    """Set_Axis_State (0x07). :param state: requested state (int if unknown)."""

    node_id: int
    state: AxisState | int


@dataclass(frozen=True, slots=True)
class SetControllerMode:
    """Set_Controller_Mode (0x0B)."""

    node_id: int
    control_mode: int
    input_mode: int


@dataclass(frozen=True, slots=True)
class ClearErrors:
    """Clear_Errors (0x18). :param identify: 0.6 only: blink the LED."""

    node_id: int
    identify: bool = False


@dataclass(frozen=True, slots=True)
class Estop:
    """Estop (0x02)."""

    node_id: int


@dataclass(frozen=True, slots=True)
class Request:
    """A request for a cyclic message (RTR frame, or DLC 0 data frame in 0.5)."""

    node_id: int
    cmd: CmdId


#: Everything :func:`decode_command` returns.
Command: TypeAlias = (
    SetInputVel | SetInputPos | SetAxisState | SetControllerMode | ClearErrors | Estop | Request
)


def decode_command(codec: OdriveCodec, frame: Frame) -> Command | None:
    """Decode a host-to-axis frame as an axis configured like ``codec`` does.

    :return: ``None`` for a frame of the other ID type or a command not modelled here.
    :raises DecodeError: for a wrong DLC.
    """
    ids = codec.split_id(frame)
    if ids is None:
        return None
    node, cmd = ids
    getter = cmd in (HEARTBEAT.cmd, ENCODER_ESTIMATES.cmd, codec.error_layout.cmd)
    if frame.is_remote_frame or (getter and frame.dlc == 0 and codec.firmware is Firmware.V0_5):
        return Request(node, CmdId(cmd)) if getter else None
    if cmd == CmdId.SET_INPUT_VEL:
        vel, torque = SET_INPUT_VEL.unpack(node, frame)
        return SetInputVel(node, vel, torque)
    if cmd == CmdId.SET_INPUT_POS:
        pos, vel_ff, torque_ff = SET_INPUT_POS.unpack(node, frame)
        return SetInputPos(node, pos, vel_ff * INPUT_POS_FF_SCALE, torque_ff * INPUT_POS_FF_SCALE)
    if cmd == CmdId.SET_AXIS_STATE:
        (state,) = SET_AXIS_STATE.unpack(node, frame)
        state = int(state)
        return SetAxisState(node, _AXIS_STATES.get(state, state))
    if cmd == CmdId.SET_CONTROLLER_MODE:
        control, inp = SET_CONTROLLER_MODE.unpack(node, frame)
        return SetControllerMode(node, int(control), int(inp))
    if cmd == CmdId.CLEAR_ERRORS:
        values = codec.clear_errors_layout.unpack(node, frame)
        return ClearErrors(node, bool(values and values[0]))
    if cmd == CmdId.ESTOP:
        ESTOP.unpack(node, frame)
        return Estop(node)
    return None
