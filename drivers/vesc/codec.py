"""Pure codec of the VESC CAN protocol (vedderb/bldc, ``CAN_MODE_VESC``).

Reference: the firmware's own description, ``documentation/comm_can.md``, and its
implementation ``comm/comm_can.c`` (``decode_msg``, ``comm_can_send_status1..6``) and
``datatypes.h`` (``CAN_PACKET_ID``, ``HW_TYPE``) in https://github.com/vedderb/bldc
(read at ``b9d287b3``).

* 29-bit extended identifiers only: ``eid = (packet << 8) | vesc_id``.  Standard-ID frames are
  never VESC frames (the firmware hands them to its Lisp and BMS hooks).
* Every multi-byte field is big endian.  Commands are one int32 ``value * scale`` (DLC 4).  The
  6-byte SET_CURRENT variant with an off-delay is inconsistent between the firmware's sender and
  receiver since commit ``766f6e02``, so only the 4-byte forms exist here.
* Status frames (STATUS, STATUS_5) are cyclic only; there is no RTR.  They carry no fault code.

Everything here is pure: no I/O, no clock.  Host side: :func:`make_command` (and its
``make_set_*`` shorthands), :func:`make_ping`, :func:`decode` (and :func:`unpack_status`, the
fields of a status frame, for the driver's receive path).  Device side (the simulator):
:func:`decode_command`, :func:`make_status`, :func:`make_status5`, :func:`make_pong`.  The host
side rounds a command's value to the field; the device side truncates toward zero, as the
firmware's casts do.
"""

from __future__ import annotations

import enum
import math
import struct
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, TypeAlias

from gateway.core.errors import DecodeError, EncodeError
from gateway.core.types import Frame

if TYPE_CHECKING:
    from collections.abc import Mapping

#: The controller-ID byte that addresses every VESC on the bus.
BROADCAST_ID = 0xFF
#: Tachometer steps per electrical revolution (``mcpwm_foc.c``: one step per 60 degrees).
TACHO_STEPS_PER_EREV = 6
#: RPM per rad/s (eRPM = motor rad/s * RPM_PER_RAD_S * pole pairs).
RPM_PER_RAD_S = 60.0 / (2.0 * math.pi)

_I32_MIN = -(2**31)
_I32_MAX = 2**31 - 1
_I16_MIN = -(2**15)
_I16_MAX = 2**15 - 1

_I32 = struct.Struct(">i")
_I32_PACK = _I32.pack
#: STATUS and STATUS_5 share one layout: int32, int16, int16.
_STATUS = struct.Struct(">ihh")
_PONG = struct.Struct(">BB")
_STATUS_UNPACK = _STATUS.unpack


class CanPacketId(enum.IntEnum):
    """``CAN_PACKET_ID`` values used here (``datatypes.h``); the high bits of the ID."""

    SET_DUTY = 0
    SET_CURRENT = 1
    SET_CURRENT_BRAKE = 2
    SET_RPM = 3
    SET_POS = 4
    STATUS = 9
    STATUS_2 = 14
    STATUS_3 = 15
    STATUS_4 = 16
    PING = 17
    PONG = 18
    STATUS_5 = 27
    SHUTDOWN = 31
    STATUS_6 = 58


_STATUS_ID = int(CanPacketId.STATUS)
_STATUS_5_ID = int(CanPacketId.STATUS_5)
_SET_RPM_BASE = int(CanPacketId.SET_RPM) << 8


class HwType(enum.IntEnum):
    """``HW_TYPE`` (``datatypes.h``), byte 1 of a PONG."""

    VESC = 0
    VESC_BMS = 1
    CUSTOM_MODULE = 2


@dataclass(frozen=True, slots=True)
class CommandField:
    """The one int32 field of a simple command: ``raw = round(value * scale)``.

    :param name: what the value is, for error messages.
    :param unit: its unit, for error messages.
    :param scale: raw counts per unit.
    """

    name: str
    unit: str
    scale: float
    #: Smallest encodable value in the field's unit (computed once: every command checks it).
    minimum: float = field(init=False)
    #: Largest encodable value in the field's unit.
    maximum: float = field(init=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "minimum", _I32_MIN / self.scale)
        object.__setattr__(self, "maximum", _I32_MAX / self.scale)


#: The simple commands this codec speaks, described once (``decode_msg`` in ``comm_can.c``).
COMMANDS: Mapping[CanPacketId, CommandField] = {
    CanPacketId.SET_CURRENT: CommandField("current", "A", 1e3),
    CanPacketId.SET_CURRENT_BRAKE: CommandField("brake current", "A", 1e3),
    CanPacketId.SET_RPM: CommandField("speed", "eRPM", 1.0),
}


@dataclass(frozen=True, slots=True)
class VescStatus:
    """STATUS (packet 9), ``comm_can_send_status1``.

    :param node_id: the sending controller.
    :param erpm: electrical RPM (mechanical RPM times pole pairs), signed.
    :param current_a: total motor current, filtered, resolution 0.1 A.
    :param duty: duty cycle -1..1, resolution 0.001.
    """

    node_id: int
    erpm: int
    current_a: float
    duty: float


@dataclass(frozen=True, slots=True)
class VescStatus5:
    """STATUS_5 (packet 27), ``comm_can_send_status5``.

    :param node_id: the sending controller.
    :param tachometer: int32 step counter, 6 steps per electrical revolution; wraps.
    :param v_in_v: input voltage, resolution 0.1 V.
    """

    node_id: int
    tachometer: int
    v_in_v: float


@dataclass(frozen=True, slots=True)
class VescPong:
    """PONG (packet 18): the answer to a PING.

    :param node_id: the answering controller (byte 0; the firmware echoes the ID the PING was
        addressed to, so a broadcast PING is answered with 255).
    :param to_id: the pinger's ID (the low byte of the arbitration ID).
    :param hw_type: ``HW_TYPE`` of the answering device; an int so that future types decode.
    """

    node_id: int
    to_id: int
    hw_type: int


@dataclass(frozen=True, slots=True)
class VescCommand:
    """A simple command as the controller receives it (device side).

    :param node_id: the addressed controller, 255 for all.
    :param packet: which command.
    :param value: the value in the unit of ``COMMANDS[packet]``.
    """

    node_id: int
    packet: CanPacketId
    value: float


@dataclass(frozen=True, slots=True)
class VescPing:
    """A PING as the controller receives it (device side).

    :param node_id: the addressed controller, 255 for all.
    :param sender_id: where the PONG goes.
    """

    node_id: int
    sender_id: int


#: Everything :func:`decode` returns.
VescMessage: TypeAlias = VescStatus | VescStatus5 | VescPong


def arbitration_id(packet: CanPacketId, node_id: int) -> int:
    """The 29-bit identifier of ``packet`` to or from controller ``node_id`` (``packet << 8 |
    node_id``; a PONG's low byte is the pinger's ID)."""
    return (int(packet) << 8) | node_id


def _check_id(node_id: int, what: str = "VESC ID") -> None:
    if not isinstance(node_id, int) or isinstance(node_id, bool) or not 0 <= node_id <= 0xFF:
        raise EncodeError(f"Expected {what} between 0 and 255, but got {node_id!r}.")


# ----------------------------------------------------------------------- host side


def make_command(packet: CanPacketId, node_id: int, value: float) -> Frame:
    """A simple 4-byte command frame.

    :param packet: a key of :data:`COMMANDS`.
    :param node_id: the controller, 0..254, or 255 for every controller.
    :param value: in the unit of the command (A or eRPM), rounded to the field's resolution.
    :raises EncodeError: for an unknown packet, a bad ID, or a value that is not finite or does
        not fit the int32 field.
    """
    spec = COMMANDS.get(packet)
    if spec is None:
        raise EncodeError(f"Expected one of {', '.join(p.name for p in COMMANDS)}, got {packet!r}.")
    # Every cycle sends one of these per motor: a plain int ID in range passes with one test.
    if not (type(node_id) is int and 0 <= node_id <= 0xFF):
        _check_id(node_id)
    if not math.isfinite(value) or not spec.minimum <= value <= spec.maximum:
        raise EncodeError(
            f"Expected {spec.name} for VESC {node_id} between {spec.minimum:.10g} and "
            f"{spec.maximum:.10g} {spec.unit}, but got {value!r}."
        )
    raw = round(value * spec.scale)
    if not _I32_MIN <= raw <= _I32_MAX:
        raw = min(max(raw, _I32_MIN), _I32_MAX)  # value * scale may round just past the edge
    return Frame(packet << 8 | node_id, _I32_PACK(raw), True)


def make_set_rpm(node_id: int, erpm: float) -> Frame:
    """SET_RPM: run the speed controller at ``erpm`` electrical RPM (:func:`make_command`)."""
    if type(erpm) is int and type(node_id) is int and 0 <= node_id <= 0xFF:
        if _I32_MIN <= erpm <= _I32_MAX:  # every cycle, per motor: the frame at once
            return Frame(_SET_RPM_BASE | node_id, _I32_PACK(erpm), True)
    return make_command(CanPacketId.SET_RPM, node_id, erpm)


def make_set_current(node_id: int, current_a: float) -> Frame:
    """SET_CURRENT: motor current in A.  Below ``cc_min_current`` (0.05 A) it releases the motor."""
    return make_command(CanPacketId.SET_CURRENT, node_id, current_a)


def make_set_current_brake(node_id: int, current_a: float) -> Frame:
    """SET_CURRENT_BRAKE: brake with ``current_a`` A."""
    return make_command(CanPacketId.SET_CURRENT_BRAKE, node_id, current_a)


def make_ping(node_id: int, sender_id: int) -> Frame:
    """PING ``node_id``; the PONG comes back to ``(18 << 8) | sender_id``.

    :raises EncodeError: if an ID is outside 0..255.
    """
    _check_id(node_id)
    _check_id(sender_id, "sender ID")
    return Frame(arbitration_id(CanPacketId.PING, node_id), bytes((sender_id,)), True)


def _check_data(frame: Frame, packet: CanPacketId, node_id: int, sizes: tuple[int, ...]) -> None:
    if frame.is_remote_frame:
        raise DecodeError(
            f"Expected a data frame for {packet.name} from VESC {node_id}, but got a remote frame."
        )
    if len(frame.data) not in sizes:
        want = " or ".join(str(s) for s in sizes)
        raise DecodeError(
            f"Expected {want} data bytes for {packet.name} of VESC {node_id}, "
            f"but got {len(frame.data)}."
        )


def unpack_status(frame: Frame) -> tuple[int, int, int]:
    """The raw fields of a STATUS or STATUS_5 frame (one layout: int32, int16, int16; STATUS:
    eRPM, current * 10, duty * 1000; STATUS_5: tachometer, input voltage * 10, reserved).

    :raises DecodeError: for a remote frame or a length other than 8.
    """
    data = frame.data
    if frame.is_remote_frame or len(data) != 8:
        # Off the per-frame path: the packet's enum member is built only to raise.
        arb = frame.arbitration_id
        _check_data(frame, CanPacketId(arb >> 8), arb & 0xFF, (8,))
    fields: tuple[int, int, int] = _STATUS_UNPACK(data)
    return fields


def decode(frame: Frame) -> VescMessage | None:
    """Decode a frame a controller sent (STATUS, STATUS_5, PONG).

    :return: the message, or ``None`` for anything else (standard IDs, commands, other
        status packets, IDs with bits above 15).
    :raises DecodeError: for a STATUS, STATUS_5 or PONG that is a remote frame or has the
        wrong length.
    """
    if not frame.is_extended_id:
        return None
    arb = frame.arbitration_id
    packet, node_id = arb >> 8, arb & 0xFF
    if packet == _STATUS_ID:
        erpm, current, duty = unpack_status(frame)
        return VescStatus(node_id, erpm, current / 10.0, duty / 1000.0)
    if packet == _STATUS_5_ID:
        tacho, v_in, _ = unpack_status(frame)
        return VescStatus5(node_id, tacho, v_in / 10.0)
    if packet == CanPacketId.PONG:
        _check_data(frame, CanPacketId.PONG, node_id, (1, 2))
        # ``decode_msg``: a one-byte PONG means HW_TYPE_VESC.
        hw = frame.data[1] if len(frame.data) == 2 else HwType.VESC
        return VescPong(frame.data[0], node_id, int(hw))
    return None


# ----------------------------------------------------------------------- device side


def decode_command(frame: Frame) -> VescCommand | VescPing | None:
    """Decode a frame as a controller receives it (SET_CURRENT, SET_CURRENT_BRAKE, SET_RPM, PING).

    :return: the command, or ``None`` for anything else.
    :raises DecodeError: for one of those packets as a remote frame or with the wrong length
        (only the 4-byte command forms are accepted).
    """
    if not frame.is_extended_id:
        return None
    packet, node_id = frame.arbitration_id >> 8, frame.arbitration_id & 0xFF
    if packet == CanPacketId.PING:
        _check_data(frame, CanPacketId.PING, node_id, (1,))
        return VescPing(node_id, frame.data[0])
    if packet not in COMMANDS:
        return None
    cmd = CanPacketId(packet)
    _check_data(frame, cmd, node_id, (4,))
    (raw,) = _I32.unpack(frame.data)
    return VescCommand(node_id, cmd, raw / COMMANDS[cmd].scale)


def _fixed(value: float, scale: float, *, name: str, node_id: int, lo: int, hi: int) -> int:
    # Truncated toward zero, as the firmware's C casts do (``(int16_t)(current * 1e1)`` in
    # ``comm_can_send_status1``): a device-side field is up to one LSB below the value.
    raw = math.trunc(value * scale) if math.isfinite(value) else None
    if raw is None or not lo <= raw <= hi:
        raise EncodeError(
            f"Expected {name} for VESC {node_id} between {lo / scale:g} and {hi / scale:g}, "
            f"but got {value!r}."
        )
    return raw


def make_status(node_id: int, erpm: float, current_a: float, duty: float) -> Frame:
    """STATUS as a controller sends it: every field truncated toward zero, as
    ``comm_can_send_status1`` casts (``(int32_t)rpm``, ``(int16_t)(current * 1e1)``,
    ``(int16_t)(duty * 1e3)``).

    :raises EncodeError: if a value does not fit its field.
    """
    _check_id(node_id)
    raw_erpm = _fixed(erpm, 1.0, name="eRPM", node_id=node_id, lo=_I32_MIN, hi=_I32_MAX)
    raw_current = _fixed(current_a, 10.0, name="current", node_id=node_id, lo=_I16_MIN, hi=_I16_MAX)
    raw_duty = _fixed(duty, 1000.0, name="duty", node_id=node_id, lo=_I16_MIN, hi=_I16_MAX)
    data = _STATUS.pack(raw_erpm, raw_current, raw_duty)
    return Frame(arbitration_id(CanPacketId.STATUS, node_id), data, is_extended_id=True)


def make_status5(node_id: int, tachometer: int, v_in_v: float) -> Frame:
    """STATUS_5 as a controller sends it (bytes 6-7 reserved, zero); the voltage truncated
    toward zero, as ``comm_can_send_status5`` casts (``(int16_t)(v_in * 1e1)``).

    :raises EncodeError: if a value does not fit its field.
    """
    _check_id(node_id)
    raw_tacho = _fixed(
        tachometer, 1.0, name="tachometer", node_id=node_id, lo=_I32_MIN, hi=_I32_MAX
    )
    raw_v = _fixed(v_in_v, 10.0, name="input voltage", node_id=node_id, lo=_I16_MIN, hi=_I16_MAX)
    data = _STATUS.pack(raw_tacho, raw_v, 0)
    return Frame(arbitration_id(CanPacketId.STATUS_5, node_id), data, is_extended_id=True)


def make_pong(to_id: int, responder_id: int, hw_type: HwType = HwType.VESC) -> Frame:
    """PONG as a controller sends it, to the pinger ``to_id``.

    :raises EncodeError: if an ID is outside 0..255.
    """
    _check_id(to_id, "pinger ID")
    _check_id(responder_id)
    data = _PONG.pack(responder_id, int(hw_type))
    return Frame(arbitration_id(CanPacketId.PONG, to_id), data, is_extended_id=True)


def wrap_int32(value: int) -> int:
    """``value`` wrapped into int32 the way a C ``int`` counter overflows.

    >>> wrap_int32(2**31)
    -2147483648
    """
    return ((value + 2**31) % 2**32) - 2**31
