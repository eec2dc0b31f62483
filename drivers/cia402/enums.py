"""Wire enums of CANopen (CiA 301) and the CiA 402 drive state machine as explicit tables.

Every number that travels on the bus is named here once: COB-ID bases, NMT commands and
states, SDO command specifiers, object indices, the statusword masks and the controlword
commands.  The state machine is data: :data:`STATUSWORD_MASK` decodes a statusword,
:data:`TRANSITIONS` gives the controlword of every commandable transition, and
:data:`NEXT_TOWARD_ENABLED` is the path the enable sequence walks.

Reference: CiA 301 (application layer) and CiA 402 / IEC 61800-7-201 (drive profile); the masks
and the transition table match ``canopen.profiles.p402.State402`` (``SW_MASK``,
``TRANSITIONTABLE``) of https://github.com/canopen-python/canopen, which the tests check.
"""

from __future__ import annotations

import enum
import struct

from gateway.core.errors import EncodeError, IllegalTransitionError

#: COB-ID bit 31 of a PDO communication parameter: the PDO is not valid (switched off).
PDO_COB_INVALID = 1 << 31
#: Largest node ID (CiA 301).
MAX_NODE_ID = 127


class CobBase(enum.IntEnum):
    """Function-code base of the CiA 301 predefined connection set (COB-ID = base + node)."""

    NMT = 0x000
    SYNC = 0x080
    #: Same base as SYNC; node IDs 1..127 make 0x081..0x0FF.
    EMCY = 0x080
    TIME = 0x100
    TPDO1 = 0x180
    RPDO1 = 0x200
    TPDO2 = 0x280
    RPDO2 = 0x300
    TPDO3 = 0x380
    RPDO3 = 0x400
    TPDO4 = 0x480
    RPDO4 = 0x500
    #: SDO server -> client (the drive's answers).
    SDO_TX = 0x580
    #: SDO client -> server (our requests).
    SDO_RX = 0x600
    HEARTBEAT = 0x700


def tpdo_cob_id(number: int, node_id: int) -> int:
    """Predefined COB-ID of TPDO ``number`` (1..4) of ``node_id``: 0x180 + (n-1)*0x100 + id."""
    return CobBase.TPDO1 + (number - 1) * 0x100 + node_id


def rpdo_cob_id(number: int, node_id: int) -> int:
    """Predefined COB-ID of RPDO ``number`` (1..4) of ``node_id``: 0x200 + (n-1)*0x100 + id."""
    return CobBase.RPDO1 + (number - 1) * 0x100 + node_id


class NmtCommand(enum.IntEnum):
    """NMT command specifier, byte 0 of a COB-ID 0x000 frame."""

    START = 0x01
    STOP = 0x02
    ENTER_PRE_OPERATIONAL = 0x80
    RESET_NODE = 0x81
    RESET_COMMUNICATION = 0x82


class NmtState(enum.IntEnum):
    """NMT state in a heartbeat frame (bit 7, the node-guarding toggle, masked off)."""

    BOOT_UP = 0x00
    STOPPED = 0x04
    OPERATIONAL = 0x05
    PRE_OPERATIONAL = 0x7F


class ClientCommand(enum.IntEnum):
    """SDO client command specifier (bits 7..5 of byte 0 of a request)."""

    DOWNLOAD_SEGMENT = 0
    INITIATE_DOWNLOAD = 1
    INITIATE_UPLOAD = 2
    UPLOAD_SEGMENT = 3
    ABORT = 4
    BLOCK_UPLOAD = 5
    BLOCK_DOWNLOAD = 6


class ServerCommand(enum.IntEnum):
    """SDO server command specifier (bits 7..5 of byte 0 of a response)."""

    UPLOAD_SEGMENT = 0
    DOWNLOAD_SEGMENT = 1
    INITIATE_UPLOAD = 2
    INITIATE_DOWNLOAD = 3
    ABORT = 4
    BLOCK_DOWNLOAD = 5
    BLOCK_UPLOAD = 6


class SdoFlag(enum.IntFlag):
    """Low bits of an SDO initiate command byte (bits 3..2 hold ``n``, the unused bytes)."""

    NONE = 0
    SIZE_INDICATED = 0x01
    EXPEDITED = 0x02


class DataType(enum.IntEnum):
    """CiA 301 basic data types (object 0x0001..0x0007) used by the objects we touch."""

    INTEGER8 = 0x0002
    INTEGER16 = 0x0003
    INTEGER32 = 0x0004
    UNSIGNED8 = 0x0005
    UNSIGNED16 = 0x0006
    UNSIGNED32 = 0x0007

    @property
    def codec(self) -> struct.Struct:
        """Little-endian ``struct`` of this type."""
        return _DATATYPE_STRUCT[self]

    @property
    def size(self) -> int:
        """Size in bytes."""
        return _DATATYPE_STRUCT[self].size

    @property
    def bounds(self) -> tuple[int, int]:
        """Smallest and largest value."""
        return _DATATYPE_BOUNDS[self]

    def check(self, value: int, what: str) -> int:
        """Return ``value`` if it is an int in this type's range.

        :raises EncodeError: naming ``what``, the range and the value.
        """
        lo, hi = _DATATYPE_BOUNDS[self]  # every command RPDO checks two fields
        if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
            raise EncodeError(f"Expected {what} between {lo} and {hi}, but got {value!r}.")
        return value


def check_node_id(node_id: int) -> int:
    """Return ``node_id`` if it is a CANopen node ID (1..127).

    :raises EncodeError: otherwise.
    """
    if isinstance(node_id, bool) or not isinstance(node_id, int) or not 1 <= node_id <= 127:
        raise EncodeError(f"Expected a CANopen node ID between 1 and 127, but got {node_id!r}.")
    return node_id


_DATATYPE_STRUCT = {
    DataType.INTEGER8: struct.Struct("<b"),
    DataType.INTEGER16: struct.Struct("<h"),
    DataType.INTEGER32: struct.Struct("<i"),
    DataType.UNSIGNED8: struct.Struct("<B"),
    DataType.UNSIGNED16: struct.Struct("<H"),
    DataType.UNSIGNED32: struct.Struct("<I"),
}


def _bounds(dtype: DataType) -> tuple[int, int]:
    bits = 8 * _DATATYPE_STRUCT[dtype].size
    if dtype in (DataType.INTEGER8, DataType.INTEGER16, DataType.INTEGER32):
        return -(1 << (bits - 1)), (1 << (bits - 1)) - 1
    return 0, (1 << bits) - 1


#: Smallest and largest value of each type, computed once (:meth:`DataType.check`).
_DATATYPE_BOUNDS = {dtype: _bounds(dtype) for dtype in DataType}


class ObjectIndex(enum.IntEnum):
    """Object dictionary indices used by the driver (PDO parameters: add ``n - 1``)."""

    DEVICE_TYPE = 0x1000
    ERROR_REGISTER = 0x1001
    #: CiA 301: consumer heartbeat time, sub 1..n = watched node (bits 23..16) + ms (15..0).
    CONSUMER_HEARTBEAT_TIME = 0x1016
    PRODUCER_HEARTBEAT_TIME = 0x1017
    #: CiA 301: error behaviour, sub 1 = the NMT state a communication error leads to.
    ERROR_BEHAVIOUR = 0x1029
    RPDO_COMMUNICATION = 0x1400
    RPDO_MAPPING = 0x1600
    TPDO_COMMUNICATION = 0x1800
    TPDO_MAPPING = 0x1A00
    #: CiA 402: what the drive does on a connection abort (a heartbeat event among them).
    ABORT_CONNECTION_OPTION_CODE = 0x6007
    CONTROLWORD = 0x6040
    STATUSWORD = 0x6041
    #: CiA 402: how QUICK STOP ACTIVE stops the motor and where it goes then.
    QUICK_STOP_OPTION_CODE = 0x605A
    MODES_OF_OPERATION = 0x6060
    MODES_OF_OPERATION_DISPLAY = 0x6061
    POSITION_ACTUAL_VALUE = 0x6064
    VELOCITY_ACTUAL_VALUE = 0x606C
    TARGET_POSITION = 0x607A
    PROFILE_DECELERATION = 0x6084
    QUICK_STOP_DECELERATION = 0x6085
    TARGET_VELOCITY = 0x60FF
    SUPPORTED_DRIVE_MODES = 0x6502


class PdoParameter(enum.IntEnum):
    """Sub-indices of a PDO communication parameter record (0x1400.. / 0x1800..)."""

    HIGHEST_SUBINDEX = 0
    COB_ID = 1
    TRANSMISSION_TYPE = 2
    INHIBIT_TIME = 3
    EVENT_TIMER = 5


class TransmissionType(enum.IntEnum):
    """PDO transmission types (1..240 = every n-th SYNC)."""

    SYNC_ACYCLIC = 0
    SYNC_EVERY = 1
    EVENT_MANUFACTURER = 254
    EVENT_PROFILE = 255


class OperationMode(enum.IntEnum):
    """Modes of operation (0x6060 / 0x6061, INTEGER8)."""

    NO_MODE = 0
    PROFILE_POSITION = 1
    VELOCITY = 2
    PROFILE_VELOCITY = 3
    PROFILE_TORQUE = 4
    HOMING = 6
    INTERPOLATED_POSITION = 7
    CYCLIC_SYNCHRONOUS_POSITION = 8
    CYCLIC_SYNCHRONOUS_VELOCITY = 9
    CYCLIC_SYNCHRONOUS_TORQUE = 10


def supported_mode_bit(mode: OperationMode) -> int:
    """The bit of 0x6502 (supported drive modes) that stands for ``mode`` (bit = mode - 1)."""
    return 1 << (int(mode) - 1)


class StatuswordBit(enum.IntFlag):
    """Bits of the statusword (0x6041); bits 12 and 13 mean something else in each mode."""

    NONE = 0
    READY_TO_SWITCH_ON = 0x0001
    SWITCHED_ON = 0x0002
    OPERATION_ENABLED = 0x0004
    FAULT = 0x0008
    VOLTAGE_ENABLED = 0x0010
    #: Active low: 0 while a quick stop is active.
    QUICK_STOP = 0x0020
    SWITCH_ON_DISABLED = 0x0040
    WARNING = 0x0080
    REMOTE = 0x0200
    TARGET_REACHED = 0x0400
    INTERNAL_LIMIT_ACTIVE = 0x0800
    #: Profile velocity mode: the speed is 0.
    SPEED_ZERO = 0x1000
    #: Cyclic synchronous modes: the drive follows the target (an alias of bit 12).
    FOLLOWS_TARGET = 0x1000
    #: Cyclic synchronous and profile position modes: following error.
    FOLLOWING_ERROR = 0x2000


class State(enum.IntEnum):
    """CiA 402 drive states; each value is the statusword pattern under its mask."""

    NOT_READY_TO_SWITCH_ON = 0x00
    SWITCH_ON_DISABLED = 0x40
    READY_TO_SWITCH_ON = 0x21
    SWITCHED_ON = 0x23
    OPERATION_ENABLED = 0x27
    QUICK_STOP_ACTIVE = 0x07
    FAULT_REACTION_ACTIVE = 0x0F
    FAULT = 0x08

    @property
    def label(self) -> str:
        """The state's name as CiA 402 writes it, e.g. ``"SWITCH ON DISABLED"``."""
        return self.name.replace("_", " ")


#: Statusword mask of each state: ``statusword & mask == state.value`` (exactly one matches).
STATUSWORD_MASK: dict[State, int] = {
    State.NOT_READY_TO_SWITCH_ON: 0x4F,
    State.SWITCH_ON_DISABLED: 0x4F,
    State.READY_TO_SWITCH_ON: 0x6F,
    State.SWITCHED_ON: 0x6F,
    State.OPERATION_ENABLED: 0x6F,
    State.QUICK_STOP_ACTIVE: 0x6F,
    State.FAULT_REACTION_ACTIVE: 0x4F,
    State.FAULT: 0x4F,
}


def _scan_statusword(statusword: int) -> State | None:
    for state, mask in STATUSWORD_MASK.items():
        if statusword & mask == state:
            return state
    return None


#: Every mask is a subset of 0x6F, so ``statusword & 0x6F`` decides the state: the table of
#: :func:`_scan_statusword` over those bits turns the per-TPDO scan into one index.
_STATUSWORD_BITS = 0x6F
_STATE_BY_BITS: tuple[State | None, ...] = tuple(
    _scan_statusword(bits) for bits in range(_STATUSWORD_BITS + 1)
)


def state_from_statusword(statusword: int) -> State | None:
    """The drive state a statusword reports, or ``None`` for a pattern no state has.

    :param statusword: the 16-bit statusword (0x6041).
    """
    return _STATE_BY_BITS[statusword & _STATUSWORD_BITS]


class Controlword(enum.IntEnum):
    """Controlword (0x6040) commands of the CiA 402 state machine."""

    DISABLE_VOLTAGE = 0x0000
    QUICK_STOP = 0x0002
    SHUTDOWN = 0x0006
    #: Also "disable operation" (transition 5): the same bits.
    SWITCH_ON = 0x0007
    ENABLE_OPERATION = 0x000F
    #: Rising edge of bit 7 (transition 15).
    FAULT_RESET = 0x0080


#: Every transition a controlword can cause, with its CiA 402 number in the comment.
TRANSITIONS: dict[tuple[State, State], Controlword] = {
    (State.SWITCH_ON_DISABLED, State.READY_TO_SWITCH_ON): Controlword.SHUTDOWN,  # 2
    (State.READY_TO_SWITCH_ON, State.SWITCHED_ON): Controlword.SWITCH_ON,  # 3
    (State.SWITCHED_ON, State.OPERATION_ENABLED): Controlword.ENABLE_OPERATION,  # 4
    (State.OPERATION_ENABLED, State.SWITCHED_ON): Controlword.SWITCH_ON,  # 5
    (State.SWITCHED_ON, State.READY_TO_SWITCH_ON): Controlword.SHUTDOWN,  # 6
    (State.READY_TO_SWITCH_ON, State.SWITCH_ON_DISABLED): Controlword.DISABLE_VOLTAGE,  # 7
    (State.OPERATION_ENABLED, State.READY_TO_SWITCH_ON): Controlword.SHUTDOWN,  # 8
    (State.OPERATION_ENABLED, State.SWITCH_ON_DISABLED): Controlword.DISABLE_VOLTAGE,  # 9
    (State.SWITCHED_ON, State.SWITCH_ON_DISABLED): Controlword.DISABLE_VOLTAGE,  # 10
    (State.OPERATION_ENABLED, State.QUICK_STOP_ACTIVE): Controlword.QUICK_STOP,  # 11
    (State.QUICK_STOP_ACTIVE, State.SWITCH_ON_DISABLED): Controlword.DISABLE_VOLTAGE,  # 12
    (State.FAULT, State.SWITCH_ON_DISABLED): Controlword.FAULT_RESET,  # 15
    (State.QUICK_STOP_ACTIVE, State.OPERATION_ENABLED): Controlword.ENABLE_OPERATION,  # 16
}

#: Transitions the drive makes on its own (1 and 14); no controlword causes them.
AUTOMATIC_TRANSITIONS: frozenset[tuple[State, State]] = frozenset(
    {
        (State.NOT_READY_TO_SWITCH_ON, State.SWITCH_ON_DISABLED),
        (State.FAULT_REACTION_ACTIVE, State.FAULT),
    }
)

#: The next state on the way to OPERATION ENABLED from each other state.  QUICK STOP ACTIVE
#: goes through SWITCH ON DISABLED because transition 16 is optional (quick stop option code).
NEXT_TOWARD_ENABLED: dict[State, State] = {
    State.NOT_READY_TO_SWITCH_ON: State.SWITCH_ON_DISABLED,
    State.SWITCH_ON_DISABLED: State.READY_TO_SWITCH_ON,
    State.READY_TO_SWITCH_ON: State.SWITCHED_ON,
    State.SWITCHED_ON: State.OPERATION_ENABLED,
    State.QUICK_STOP_ACTIVE: State.SWITCH_ON_DISABLED,
    State.FAULT_REACTION_ACTIVE: State.FAULT,
    State.FAULT: State.SWITCH_ON_DISABLED,
}


def controlword_for(current: State, target: State) -> Controlword:
    """The controlword that takes a drive from ``current`` to ``target`` in one transition.

    :raises IllegalTransitionError: if no controlword causes that transition (no such
        transition, an automatic one, or ``current == target``).
    """
    try:
        return TRANSITIONS[(current, target)]
    except KeyError:
        why = (
            "it is automatic"
            if (current, target) in AUTOMATIC_TRANSITIONS
            else "CiA 402 has no such transition"
        )
        raise IllegalTransitionError(
            f"Expected a CiA 402 transition that a controlword causes, but got "
            f"{current.label} -> {target.label} ({why})"
        ) from None
