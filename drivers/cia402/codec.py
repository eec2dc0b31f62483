"""Pure frame builders and parsers for CANopen (CiA 301) with the CiA 402 drive objects.

No I/O, no clock: every function maps values to a :class:`~gateway.core.types.Frame` or back.  The
PDO layout the gateway writes into each drive is data (:data:`RPDO_MAP` for a drive motor,
:data:`RPDO_POSITION_MAP` for a steering actuator, :data:`TPDO_POSITION_MAP`,
:data:`TPDO_VELOCITY_MAP`) and the packed form is one precompiled ``struct.Struct("<Hi")``
(statusword/controlword u16 + int32), as in the spec's worked examples.

SDO frames live in :mod:`drivers.cia402.sdo`.

Reference: CiA 301 (NMT, SYNC, EMCY, PDO), CiA 402 (objects
0x6040/0x6041/0x6064/0x606C/0x607A/0x60FF); byte layouts and worked frames in
CiA 301 / CiA 402 as the canopen library (christiansandberg/canopen) implements them.
"""

from __future__ import annotations

import enum
import math
import struct
from dataclasses import dataclass
from typing import TYPE_CHECKING

from drivers.cia402.enums import (
    CobBase,
    DataType,
    NmtCommand,
    NmtState,
    ObjectIndex,
    check_node_id,
    rpdo_cob_id,
    tpdo_cob_id,
)
from drivers.cia402.sdo import SdoResponse, parse_sdo_response
from gateway.core.errors import DecodeError, EncodeError
from gateway.core.types import Frame

if TYPE_CHECKING:
    from collections.abc import Mapping

#: RPDO content: controlword (U16) + target velocity (I32), as (index, subindex, bits).
RPDO_MAP: tuple[tuple[int, int, int], ...] = (
    (ObjectIndex.CONTROLWORD, 0, 16),
    (ObjectIndex.TARGET_VELOCITY, 0, 32),
)
#: RPDO content of a steering actuator (cyclic synchronous position): controlword (U16) +
#: target position (I32), the "RPDO3 = 6040 + 607A" of the DS402 default pattern.
RPDO_POSITION_MAP: tuple[tuple[int, int, int], ...] = (
    (ObjectIndex.CONTROLWORD, 0, 16),
    (ObjectIndex.TARGET_POSITION, 0, 32),
)
#: TPDO with statusword (U16) + position actual value (I32).
TPDO_POSITION_MAP: tuple[tuple[int, int, int], ...] = (
    (ObjectIndex.STATUSWORD, 0, 16),
    (ObjectIndex.POSITION_ACTUAL_VALUE, 0, 32),
)
#: TPDO with statusword (U16) + velocity actual value (I32).
TPDO_VELOCITY_MAP: tuple[tuple[int, int, int], ...] = (
    (ObjectIndex.STATUSWORD, 0, 16),
    (ObjectIndex.VELOCITY_ACTUAL_VALUE, 0, 32),
)
#: Packed form of each of the three PDOs above.
PDO_STRUCT = struct.Struct("<Hi")
_EMCY = struct.Struct("<HB5s")
_PDO_UNPACK = PDO_STRUCT.unpack
_PDO_PACK = PDO_STRUCT.pack
_PDO_SIZE = PDO_STRUCT.size
#: The int32 range of the target velocity (0x60FF).
INT32_RANGE = DataType.INTEGER32.bounds
_I32_MIN, _I32_MAX = INT32_RANGE
_U16_MAX = DataType.UNSIGNED16.bounds[1]


def mapping_entry(index: int, subindex: int, bits: int) -> int:
    """A PDO mapping entry (0x16xx/0x1Axx sub 1..8): ``index << 16 | subindex << 8 | bits``."""
    return (index << 16) | (subindex << 8) | bits


def unpack_mapping_entry(entry: int) -> tuple[int, int, int]:
    """``(index, subindex, bits)`` of a PDO mapping entry."""
    return (entry >> 16) & 0xFFFF, (entry >> 8) & 0xFF, entry & 0xFF


@dataclass(frozen=True, slots=True)
class PdoLayout:
    """Which PDO numbers (1..4) carry the command and the two feedback messages of one node.

    :param rpdo: RPDO with controlword + target velocity, or target position for a steering
        actuator (default RPDO4, 0x500 + node).
    :param tpdo_position: TPDO with statusword + position (default TPDO3, 0x380 + node).
    :param tpdo_velocity: TPDO with statusword + velocity (default TPDO4, 0x480 + node).
    """

    rpdo: int = 4
    tpdo_position: int = 3
    tpdo_velocity: int = 4


# ----------------------------------------------------------------- value checks


def velocity_to_raw(value: float, what: str) -> int:
    """Round a device velocity to an int32 (``round()``, never truncation).

    :raises EncodeError: if it is not finite or out of the int32 range.
    """
    lo, hi = INT32_RANGE
    if not math.isfinite(value) or not lo <= round(value) <= hi:
        raise EncodeError(
            f"Expected {what} between {lo} and {hi} device units, but got {value!r}."
        )
    return round(value)


def position_to_raw(counts: float, what: str) -> int:
    """Round a target position (position units) and wrap it into the int32 range.

    The position objects wrap modulo 2^32 (0x6064 past 2^31 - 1 goes on at -2^31), and the
    drive compares target and actual position in that frame, so a position past the end is
    sent wrapped rather than refused.

    :raises EncodeError: if it is not finite.
    """
    if not math.isfinite(counts):
        raise EncodeError(f"Expected {what} as a finite number of position units, but got "
                          f"{counts!r}.")
    return (round(counts) + (1 << 31)) % (1 << 32) - (1 << 31)


# ----------------------------------------------------------------- NMT, SYNC, heartbeat, EMCY


def make_nmt(command: NmtCommand, node_id: int = 0) -> Frame:
    """NMT command frame (COB-ID 0x000, ``[command, node]``; node 0 addresses every node)."""
    if node_id != 0:
        check_node_id(node_id)
    return Frame(CobBase.NMT, bytes((NmtCommand(command), node_id)))


def cob_name(cob_id: int) -> str | None:
    """The CiA 301 name of a COB-ID's function code (``NMT``, ``SYNC``, ``EMCY``, ``TPDO3``,
    ``RPDO4``, ``SDO_TX``, ``SDO_RX``, ``HEARTBEAT``); ``None`` for an unknown one."""
    if cob_id == CobBase.NMT:
        return "NMT"
    if cob_id == CobBase.SYNC:
        return "SYNC"
    base = cob_id & 0x780
    if base == CobBase.EMCY:
        return "EMCY"  # (the same function code as SYNC, with a node ID)
    try:
        return CobBase(base).name
    except ValueError:
        return None


def make_sync(counter: int | None = None) -> Frame:
    """SYNC frame (COB-ID 0x080): DLC 0, or DLC 1 with a counter 1..240 (0x1019 set)."""
    if counter is None:
        return Frame(CobBase.SYNC)
    if not 1 <= counter <= 240:
        raise EncodeError(f"Expected a SYNC counter between 1 and 240, but got {counter!r}.")
    return Frame(CobBase.SYNC, bytes((counter,)))


def make_heartbeat(node_id: int, state: NmtState) -> Frame:
    """Heartbeat frame (0x700 + node, one byte: the NMT state)."""
    return Frame(CobBase.HEARTBEAT + check_node_id(node_id), bytes((NmtState(state),)))


def make_emcy(node_id: int, code: int, register: int, data: bytes = b"") -> Frame:
    """EMCY frame (0x080 + node): u16 error code, u8 error register, 5 manufacturer bytes."""
    DataType.UNSIGNED16.check(code, "an EMCY error code")
    DataType.UNSIGNED8.check(register, "an error register")
    if len(data) > 5:
        raise EncodeError(f"Expected at most 5 EMCY data bytes, but got {len(data)}.")
    return Frame(CobBase.EMCY + check_node_id(node_id), _EMCY.pack(code, register, data))


# ----------------------------------------------------------------- PDOs


def make_rpdo(cob_id: int, controlword: int, target: int) -> Frame:
    """The command RPDO: controlword (u16) + target (i32), 6 bytes little endian.

    :param target: target velocity (0x60FF, device velocity units) of a drive motor, or
        target position (0x607A, position units) of a steering actuator.
    :raises EncodeError: if a value does not fit its field.
    """
    # Every cycle sends one per node: plain ints in range pass with one test each (check()
    # also takes int subclasses such as Controlword members, and raises).
    if not (type(controlword) is int and 0 <= controlword <= _U16_MAX):
        DataType.UNSIGNED16.check(controlword, "a controlword")
    if not (type(target) is int and _I32_MIN <= target <= _I32_MAX):
        DataType.INTEGER32.check(target, "a target velocity or position")
    return Frame(cob_id, _PDO_PACK(controlword, target))


def make_tpdo(cob_id: int, statusword: int, value: int) -> Frame:
    """A feedback TPDO: statusword (u16) + position or velocity (i32), 6 bytes."""
    DataType.UNSIGNED16.check(statusword, "a statusword")
    DataType.INTEGER32.check(value, "a position or velocity")
    return Frame(cob_id, PDO_STRUCT.pack(statusword, value))


def unpack_pdo(frame: Frame, what: str) -> tuple[int, int]:
    """``(u16, i32)`` of one of our 6-byte PDOs.

    :raises DecodeError: on an extended ID, a remote frame or a DLC other than 6.
    """
    if frame.is_extended_id or frame.is_remote_frame:
        raise DecodeError(f"Expected an 11-bit {what} data frame, but got {frame.to_cansend()}.")
    if len(frame.data) != PDO_STRUCT.size:
        raise DecodeError(
            f"Expected {PDO_STRUCT.size} data bytes in the {what}, but got {len(frame.data)}."
        )
    word, value = PDO_STRUCT.unpack(frame.data)
    return int(word), int(value)


# ----------------------------------------------------------------- codec


class FeedbackKind(enum.IntEnum):
    """What the second field of a feedback TPDO holds (value = its object index)."""

    POSITION = ObjectIndex.POSITION_ACTUAL_VALUE
    VELOCITY = ObjectIndex.VELOCITY_ACTUAL_VALUE


@dataclass(frozen=True, slots=True)
class PdoFeedback:
    """A decoded feedback TPDO: statusword plus position (counts) or velocity (device units)."""

    node_id: int
    kind: FeedbackKind
    statusword: int
    value: int


@dataclass(frozen=True, slots=True)
class Heartbeat:
    """A decoded heartbeat (``BOOT_UP`` is the boot-up message)."""

    node_id: int
    state: NmtState


@dataclass(frozen=True, slots=True)
class Emergency:
    """A decoded EMCY: error code, error register (0x1001), 5 manufacturer bytes."""

    node_id: int
    code: int
    register: int
    data: bytes


#: Everything :meth:`Cia402Codec.decode` returns.
Cia402Message = PdoFeedback | Heartbeat | Emergency | SdoResponse


class Received(enum.Enum):
    """What a node sends us, by COB-ID (value: how messages name it)."""

    POSITION = "TPDO (statusword + position)"
    VELOCITY = "TPDO (statusword + velocity)"
    EMCY = "EMCY"
    SDO = "SDO response"
    HEARTBEAT = "heartbeat"


class Cia402Codec:
    """Builder of command RPDOs and decoder of everything our nodes send.

    :param nodes: node ID -> the PDO layout the gateway configured on that node.
    """

    def __init__(self, nodes: Mapping[int, PdoLayout]) -> None:
        self.nodes = dict(nodes)
        #: Every COB-ID :meth:`decode` takes (the feedback TPDOs, EMCY, SDO responses and
        #: heartbeats of our nodes; CiA 301 predefined connection set: function code << 7 |
        #: node), with the node and what it carries.
        self.receivers: dict[int, tuple[int, Received]] = {}
        for node_id, layout in self.nodes.items():
            check_node_id(node_id)
            rx = self.receivers
            rx[tpdo_cob_id(layout.tpdo_position, node_id)] = (node_id, Received.POSITION)
            rx[tpdo_cob_id(layout.tpdo_velocity, node_id)] = (node_id, Received.VELOCITY)
            rx[CobBase.EMCY + node_id] = (node_id, Received.EMCY)
            rx[CobBase.SDO_TX + node_id] = (node_id, Received.SDO)
            rx[CobBase.HEARTBEAT + node_id] = (node_id, Received.HEARTBEAT)
        #: node ID -> command RPDO COB-ID (every cycle sends one per node).
        self.rpdo_ids = {
            node_id: rpdo_cob_id(layout.rpdo, node_id) for node_id, layout in self.nodes.items()
        }

    def rpdo(self, node_id: int, controlword: int, target: int) -> Frame:
        """The command RPDO of ``node_id`` (its configured RPDO number): controlword and
        target velocity (drive motor) or target position (steering actuator)."""
        return make_rpdo(self.rpdo_ids[node_id], controlword, target)

    def decode(self, frame: Frame) -> Cia402Message | None:
        """Decode a frame from one of our nodes; ``None`` for any other frame.

        :raises DecodeError: if a frame on one of our nodes' COB-IDs is malformed.
        """
        if frame.is_extended_id:
            return None  # CANopen uses 11-bit COB-IDs; a 29-bit frame is another device's
        hit = self.receivers.get(frame.arbitration_id)
        if hit is None:
            return None
        node_id, kind = hit
        if frame.is_remote_frame:
            raise DecodeError(
                f"Expected an 11-bit {kind.value} data frame from node {node_id}, but got "
                f"{frame.to_cansend()}."
            )
        if kind is Received.SDO:
            return parse_sdo_response(frame)
        if kind is Received.HEARTBEAT:
            return _decode_heartbeat(frame, node_id)
        if kind is Received.EMCY:
            if len(frame.data) != _EMCY.size:
                raise DecodeError(
                    f"Expected 8 data bytes in the EMCY of node {node_id}, "
                    f"but got {len(frame.data)}."
                )
            code, register, data = _EMCY.unpack(frame.data)
            return Emergency(node_id, code, register, data)
        # A TPDO (most of the traffic; remote and 29-bit frames are out already): the length
        # check inline, unpack_pdo called only to raise, with its message built only then.
        data = frame.data
        if len(data) != _PDO_SIZE:
            unpack_pdo(frame, f"{kind.value} of node {node_id}")
        word, value = _PDO_UNPACK(data)
        fb = FeedbackKind.POSITION if kind is Received.POSITION else FeedbackKind.VELOCITY
        return PdoFeedback(node_id, fb, word, value)


def _decode_heartbeat(frame: Frame, node_id: int) -> Heartbeat:
    if len(frame.data) != 1:
        raise DecodeError(
            f"Expected 1 data byte in the heartbeat of node {node_id}, but got {len(frame.data)}."
        )
    try:
        state = NmtState(frame.data[0] & 0x7F)
    except ValueError:
        raise DecodeError(
            f"Expected an NMT state (0x00, 0x04, 0x05 or 0x7F) in the heartbeat of node "
            f"{node_id}, but got 0x{frame.data[0]:02X}."
        ) from None
    return Heartbeat(node_id, state)
