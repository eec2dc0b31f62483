"""ODrive "CANSimple" messages described once, as data: no I/O, no clock.

Each message is a :class:`Layout` (command ID, precompiled ``struct.Struct``, the official
DBC's signal names and the DLCs accepted); :class:`~drivers.odrive.codec.OdriveCodec`, the
device simulator, the tests' cantools cross-check and the benchmarks all derive from these
tables.  Beside them: the identifier and range constants with the checks of field values, the
decoded feedback messages as frozen dataclasses, and the table of allowed axis-state
transitions.  The commands as the device decodes them are in :mod:`drivers.odrive.commands`.
"""

from __future__ import annotations

import enum
import struct
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import TYPE_CHECKING, Any, TypeAlias

from drivers.odrive.enums import AxisState, CmdId, Firmware, ProcedureResult
from gateway.core.errors import DecodeError, EncodeError

if TYPE_CHECKING:
    from collections.abc import Mapping

    from gateway.core.types import Frame

#: Bits of the command ID in the arbitration ID.
CMD_BITS = 5
CMD_MASK = (1 << CMD_BITS) - 1
#: Largest node ID with 11-bit identifiers (0x3F is the 0.6 broadcast address).
MAX_STANDARD_NODE_ID = 0x3F
#: Largest node ID with 29-bit identifiers.
MAX_EXTENDED_NODE_ID = 0xFFFFFF
#: Largest finite float32.
FLOAT32_MAX = 3.4028234663852886e38
U32_MAX = 0xFFFFFFFF
#: Defaults of the ``firmware`` and ``extended_id`` motor-block keys.
DEFAULT_FIRMWARE = Firmware.V0_6
DEFAULT_EXTENDED_ID = False


@dataclass(frozen=True, slots=True)
class Layout:
    """One CANSimple message, described once.

    :param cmd: command ID.
    :param name: message name in the official DBC (without the ``AxisN_`` prefix).
    :param packer: packing of the fields, little endian.
    :param signals: DBC signal names of the fields, in ``packer`` order.
    :param dlcs: data lengths accepted when decoding; the first is the one encoded (the
        payload is zero-padded up to it).
    """

    cmd: CmdId
    name: str
    packer: struct.Struct
    signals: tuple[str, ...]
    dlcs: tuple[int, ...] = (8,)
    #: Zero bytes appended to the packed fields to reach ``dlcs[0]``.
    padding: bytes = field(init=False, repr=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "padding", bytes(self.dlcs[0] - self.packer.size))

    def pack(self, *values: float) -> bytes:
        """The payload for ``values``, zero-padded to the encoded DLC."""
        data = self.packer.pack(*values)
        return data + self.padding if self.padding else data

    def unpack(self, node: int, frame: Frame) -> tuple[Any, ...]:
        """The fields of ``frame``, a message of ``node``.

        :raises DecodeError: for a data length other than :attr:`dlcs`, naming the message.
        """
        if frame.dlc not in self.dlcs or len(frame.data) != frame.dlc:
            expected = " or ".join(str(d) for d in self.dlcs)
            raise DecodeError(
                f"Expected {expected} data bytes in {self.name} of ODrive node {node} "
                f"(ID {frame.arbitration_id:#x}), but got {len(frame.data)}."
            )
        return self.packer.unpack_from(frame.data)


SET_INPUT_VEL = Layout(
    CmdId.SET_INPUT_VEL, "Set_Input_Vel", struct.Struct("<ff"), ("Input_Vel", "Input_Torque_FF")
)
#: Feed-forwards in 0.001 rev/s and 0.001 N*m (0.5 fixed; 0.6 configurable, these by default).
SET_INPUT_POS = Layout(
    CmdId.SET_INPUT_POS,
    "Set_Input_Pos",
    struct.Struct("<fhh"),
    ("Input_Pos", "Vel_FF", "Torque_FF"),
)
#: The scale of Set_Input_Pos's Vel_FF (rev/s per count) and Torque_FF (N*m per count).
INPUT_POS_FF_SCALE = 0.001
#: The largest feed-forward Set_Input_Pos carries, in rev/s or N*m (int16 counts).
INPUT_POS_FF_MAX = 32767 * INPUT_POS_FF_SCALE
#: DLC 8 as in the DBC and the generated 0.6 header; the official python example sends 4 and
#: the firmware reads only 4, so both are accepted.
SET_AXIS_STATE = Layout(
    CmdId.SET_AXIS_STATE, "Set_Axis_State", struct.Struct("<I"), ("Axis_Requested_State",), (8, 4)
)
SET_CONTROLLER_MODE = Layout(
    CmdId.SET_CONTROLLER_MODE,
    "Set_Controller_Mode",
    struct.Struct("<II"),
    ("Control_Mode", "Input_Mode"),
)
CLEAR_ERRORS_05 = Layout(CmdId.CLEAR_ERRORS, "Clear_Errors", struct.Struct("<"), (), (0,))
CLEAR_ERRORS_06 = Layout(
    CmdId.CLEAR_ERRORS, "Clear_Errors", struct.Struct("<B"), ("Identify",), (1,)
)
ESTOP = Layout(CmdId.ESTOP, "Estop", struct.Struct("<"), (), (0,))
#: Bytes 5..7 differ: 0.5 motor/encoder/controller error flags (byte 7 bit 7 = trajectory done),
#: 0.6 procedure result, trajectory done (byte 6 bit 0), reserved.
HEARTBEAT = Layout(
    CmdId.HEARTBEAT, "Heartbeat", struct.Struct("<IBBBB"), ("Axis_Error", "Axis_State")
)
ENCODER_ESTIMATES = Layout(
    CmdId.GET_ENCODER_ESTIMATES,
    "Get_Encoder_Estimates",
    struct.Struct("<ff"),
    ("Pos_Estimate", "Vel_Estimate"),
)
GET_ERROR_06 = Layout(
    CmdId.GET_ERROR, "Get_Error", struct.Struct("<II"), ("Active_Errors", "Disarm_Reason")
)
#: The firmware sends 64 bits; the 0.5.6 DBC declares 32 (quirk 3 of the spec).
GET_MOTOR_ERROR_05 = Layout(
    CmdId.GET_ERROR, "Get_Motor_Error", struct.Struct("<Q"), ("Motor_Error",)
)

#: 0.5 heartbeat byte 7: bit 7 trajectory done, the rest the controller error flags.
TRAJ_DONE_05 = 0x80
CONTROLLER_ERROR_05 = 0x01


# ----------------------------------------------------------------------------- field values


def ff_counts(value: float) -> int:
    """A Set_Input_Pos feed-forward in int16 counts of 0.001, clipped."""
    clipped = min(max(value, -INPUT_POS_FF_MAX), INPUT_POS_FF_MAX)
    return round(clipped / INPUT_POS_FF_SCALE)


def check_float32(name: str, node_id: int, value: float, unit: str) -> None:
    """:raises EncodeError: unless ``value`` is a finite float32 (field ``name``, in ``unit``)."""
    try:
        ok = -FLOAT32_MAX <= value <= FLOAT32_MAX  # False for NaN and +-inf
    except TypeError:
        ok = False
    if not ok:
        raise EncodeError(
            f"Expected {name} for node {node_id} between {-FLOAT32_MAX:.7g} and "
            f"{FLOAT32_MAX:.7g} {unit}, but got {value!r}."
        )


def check_u32(name: str, node_id: int, value: int) -> None:
    """:raises EncodeError: unless ``value`` is an int that fits a u32 (field ``name``)."""
    if not (isinstance(value, int) and 0 <= value <= U32_MAX):
        raise EncodeError(
            f"Expected {name} for node {node_id} between 0 and {U32_MAX}, but got {value!r}."
        )


# ----------------------------------------------------------------------------- messages


@dataclass(frozen=True, slots=True)
class Heartbeat:
    """Cyclic status of one axis (0x01).

    :param node_id: sender.
    :param axis_error: raw u32 error word (:class:`~drivers.odrive.enums.AxisError` in 0.6,
        :class:`~drivers.odrive.enums.AxisError05` in 0.5).
    :param axis_state: current axis state (a plain int if this firmware's enum lacks it).
    :param trajectory_done: the trajectory-done flag.
    :param procedure_result: 0.6 only (``SUCCESS`` in 0.5 frames).
    :param motor_error: 0.5 only: the motor reports an error.
    :param encoder_error: 0.5 only: the encoder reports an error.
    :param controller_error: 0.5 only: the controller reports an error.
    """

    node_id: int
    axis_error: int
    axis_state: AxisState | int
    trajectory_done: bool = False
    procedure_result: ProcedureResult | int = ProcedureResult.SUCCESS
    motor_error: bool = False
    encoder_error: bool = False
    controller_error: bool = False


@dataclass(frozen=True, slots=True)
class EncoderEstimates:
    """Get_Encoder_Estimates (0x09).

    :param node_id: sender.
    :param pos_turns: position estimate in turns (float32, unwrapped by the firmware).
    :param vel_turns_s: velocity estimate in turns/s.
    """

    node_id: int
    pos_turns: float
    vel_turns_s: float


@dataclass(frozen=True, slots=True)
class ErrorStatus:
    """0.6 Get_Error (0x03).

    :param node_id: sender.
    :param active_errors: raw :class:`~drivers.odrive.enums.AxisError` bits now active.
    :param disarm_reason: raw :class:`~drivers.odrive.enums.AxisError` bits of the last disarm.
    """

    node_id: int
    active_errors: int
    disarm_reason: int


@dataclass(frozen=True, slots=True)
class MotorErrorStatus:
    """0.5 Get_Motor_Error (0x03).

    :param node_id: sender.
    :param motor_error: raw u64 :class:`~drivers.odrive.enums.MotorError05` bits.
    """

    node_id: int
    motor_error: int


#: Everything :meth:`OdriveCodec.decode` returns.
Feedback: TypeAlias = Heartbeat | EncoderEstimates | ErrorStatus | MotorErrorStatus


class Step(enum.Enum):
    """What a requested axis-state change sends."""

    #: Clear_Errors, Set_Controller_Mode(velocity, input mode), Set_Axis_State(CLOSED_LOOP).
    ARM = "arm"
    #: Set_Input_Vel(0), Set_Axis_State(IDLE).
    DISARM = "disarm"


def _transitions() -> Mapping[tuple[AxisState, AxisState], Step]:
    table = {(s, AxisState.IDLE): Step.DISARM for s in AxisState}
    for s in (AxisState.UNDEFINED, AxisState.IDLE, AxisState.CLOSED_LOOP_CONTROL):
        table[(s, AxisState.CLOSED_LOOP_CONTROL)] = Step.ARM
    return MappingProxyType(table)


#: (current axis state, requested axis state) -> step.  Disarming is allowed from every state
#: (it must be able to stop a running calibration); arming only from IDLE, CLOSED_LOOP_CONTROL
#: (harmless repeat) or UNDEFINED (no heartbeat seen yet), never in the middle of a
#: calibration or homing procedure, which a new request would abort.  Any other pair is illegal.
TRANSITIONS: Mapping[tuple[AxisState, AxisState], Step] = _transitions()

#: How to switch the cyclic messages the driver's liveness needs on (``axis<n>.config.can``;
#: 0.5 names them ``*_rate_ms``, 0.6 ``*_msg_rate_ms``; 0 turns a message off).
STREAM_HINTS: Mapping[str, str] = MappingProxyType({
    "encoder estimates": "set axis<n>.config.can.encoder_msg_rate_ms (0.6) or encoder_rate_ms "
                         "(0.5), 10 ms from the factory",
    "heartbeat": "set axis<n>.config.can.heartbeat_msg_rate_ms (0.6) or heartbeat_rate_ms "
                 "(0.5), 100 ms from the factory",
})
