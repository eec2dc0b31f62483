"""Reading a VESC's command timeout over CAN: COMM_GET_APPCONF through the buffer protocol.

Firmware facts (https://github.com/vedderb/bldc, read at ``b9d287b3``; the same at the tags
``3.60``, ``4.00``, ``5.03`` and ``6.00``):

* **The request** is one ``CAN_PACKET_PROCESS_SHORT_BUFFER`` (8) frame to ``(8 << 8) | id``:
  ``[sender ID, send mode, command packet...]`` (``decode_msg`` in ``comm/comm_can.c``).  Send
  mode 0 runs the packet through ``commands_process_packet`` with a reply function that sends
  the reply back to the sender over CAN, with send mode 1 (the sender treats it as a reply).
  The packet here is one byte, ``COMM_GET_APPCONF`` (17, ``COMM_PACKET_ID`` in
  ``datatypes.h``), which ``comm/commands.c`` answers with ``[17, confgenerator_serialize_
  appconf(...)]``.  The sender ID is the gateway's: :data:`HOST_ID`, the ID ``wheelgate scan``
  pings as (:data:`drivers.vesc.scan.PINGER_ID`).
* **The reply** (``comm_can_send_buffer`` in ``comm/comm_can.c``): up to 6 bytes go as one
  PROCESS_SHORT_BUFFER to ``(8 << 8) | sender`` (``[VESC ID, send mode, bytes...]``); longer
  ones as ``CAN_PACKET_FILL_RX_BUFFER`` (5) frames ``[offset u8, up to 7 bytes]`` for the
  offsets 0, 7, ... 252, then ``CAN_PACKET_FILL_RX_BUFFER_LONG`` (6) frames ``[offset u16 BE,
  up to 6 bytes]`` from offset 259 on, then ``CAN_PACKET_PROCESS_RX_BUFFER`` (7) ``[VESC ID,
  send mode, length u16 BE, crc u16 BE]``, all to the sender's ID.  The CRC is ``crc16`` of
  ``util/crc.c``: CRC-16/XMODEM (polynomial 0x1021, initial value 0, no reflection), which is
  :func:`binascii.crc_hqx` with 0.  The FILL frames do not name the VESC that sends them, so
  only one VESC may be asked at a time.
* **The app configuration** (``confgenerator_serialize_appconf`` in ``confgenerator.c``) begins
  with ``APPCONF_SIGNATURE`` (u32 BE; it changes with every firmware's layout), then
  ``controller_id`` (u8), then ``timeout_msec`` (u32 BE), then ``timeout_brake_current``...  The
  first three fields have kept these offsets since firmware 3.x; the signature has not, and
  wheelgate cannot know every firmware's, so the reply's ``controller_id`` is the check that
  the layout is the one expected: it must be the ID the VESC was asked as.  (A dual-motor
  VESC answers for its second motor with that motor's ID, ``commands.c``, while the
  PROCESS_RX_BUFFER names its first: the sender byte is not checked.)
"""

from __future__ import annotations

import binascii
import enum
import struct
from dataclasses import dataclass

from gateway.core.errors import DecodeError
from gateway.core.types import Frame

__all__ = [
    "HOST_ID",
    "AppconfTimeout",
    "BufferPacket",
    "CommPacket",
    "LayoutError",
    "Reassembly",
    "SendMode",
    "crc16",
    "make_get_appconf",
    "parse_appconf",
]

#: The gateway's own controller ID on the bus, where the VESCs send their replies: 254, the
#: ID ``wheelgate scan`` pings as (next to the broadcast ID 255, unlikely to be a VESC's).
HOST_ID = 254
#: Bytes of ``[COMM_GET_APPCONF, signature u32, controller_id u8, timeout_msec u32]``.
_HEAD = struct.Struct(">BIBI")
_RX_END = struct.Struct(">BBHH")
#: A bound well above the firmware's packets (``PACKET_MAX_PL_LEN``, 512 in ``comm/packet.h``):
#: a buffer growing past it is malformed.
MAX_LENGTH = 4096


class BufferPacket(enum.IntEnum):
    """The ``CAN_PACKET_ID`` values of the buffer protocol (``datatypes.h``)."""

    FILL_RX_BUFFER = 5
    FILL_RX_BUFFER_LONG = 6
    PROCESS_RX_BUFFER = 7
    PROCESS_SHORT_BUFFER = 8


class SendMode(enum.IntEnum):
    """The send-mode byte of PROCESS_SHORT_BUFFER and PROCESS_RX_BUFFER (``decode_msg``)."""

    #: Process the packet and send the reply back to the sender.
    PROCESS_AND_REPLY = 0
    #: A reply: pass it on to whoever asked (``commands_send_packet_can_last``).
    REPLY = 1
    #: Process the packet, send no reply.
    PROCESS_ONLY = 2


class CommPacket(enum.IntEnum):
    """The ``COMM_PACKET_ID`` values used here (``datatypes.h``)."""

    GET_APPCONF = 17


@dataclass(frozen=True, slots=True)
class BufferReply:
    """A reassembled buffer: the VESC that says it sent it, its send mode and the bytes."""

    sender_id: int
    send_mode: int
    payload: bytes


@dataclass(frozen=True, slots=True)
class AppconfTimeout:
    """What wheelgate reads of a COMM_GET_APPCONF reply.

    :param signature: ``APPCONF_SIGNATURE`` of the VESC's firmware.
    :param controller_id: the ID the configuration gives the VESC.
    :param timeout_msec: the command timeout (ms; 0: never).
    """

    signature: int
    controller_id: int
    timeout_msec: int


class LayoutError(DecodeError):
    """A COMM_GET_APPCONF reply whose leading fields are not where wheelgate expects them."""


def crc16(data: bytes) -> int:
    """``crc16`` of the firmware's ``util/crc.c``: CRC-16/XMODEM."""
    return binascii.crc_hqx(data, 0)


def make_get_appconf(node_id: int, host_id: int = HOST_ID) -> Frame:
    """The request: PROCESS_SHORT_BUFFER to ``node_id``, ``[host_id, 0, COMM_GET_APPCONF]``.

    :raises ValueError: if an ID is outside 0..255.
    """
    for name, value in (("VESC ID", node_id), ("host ID", host_id)):
        if not 0 <= value <= 0xFF:
            raise ValueError(f"{name}: expected 0..255, got {value!r}")
    return Frame(
        (BufferPacket.PROCESS_SHORT_BUFFER << 8) | node_id,
        bytes((host_id, SendMode.PROCESS_AND_REPLY, CommPacket.GET_APPCONF)),
        True,
    )


def parse_appconf(payload: bytes, node_id: int) -> AppconfTimeout:
    """The signature, ``controller_id`` and ``timeout_msec`` of a COMM_GET_APPCONF reply.

    :param node_id: the ID the VESC was asked as; the reply's ``controller_id`` must be it.
    :raises DecodeError: for another packet or a reply too short for the leading fields.
    :raises LayoutError: for a ``controller_id`` other than ``node_id``.
    """
    if not payload or payload[0] != CommPacket.GET_APPCONF:
        got = f"packet {payload[0]}" if payload else "an empty reply"
        raise DecodeError(
            f"VESC {node_id}: expected a COMM_GET_APPCONF reply (packet "
            f"{int(CommPacket.GET_APPCONF)}), got {got}"
        )
    if len(payload) < _HEAD.size:
        raise DecodeError(
            f"VESC {node_id}: expected a COMM_GET_APPCONF reply of at least {_HEAD.size} bytes "
            f"(packet, signature, controller_id, timeout_msec), got {len(payload)}"
        )
    _, signature, controller_id, timeout_msec = _HEAD.unpack_from(payload)
    if controller_id != node_id:
        raise LayoutError(
            f"cannot read the timeout: the reply's layout is not the one expected (byte 5, "
            f"controller_id, is {controller_id}, expected the VESC's ID {node_id}; signature "
            f"{signature})"
        )
    return AppconfTimeout(signature, controller_id, timeout_msec)


def _continues(packet: int, data: bytes) -> bool:
    """Whether a frame of the buffer protocol continues a reply (FILL at an offset other than
    0, or the end), rather than starting one (FILL at offset 0, or a PROCESS_SHORT_BUFFER)."""
    if packet == BufferPacket.FILL_RX_BUFFER:
        return data[:1] != b"\0"
    if packet == BufferPacket.FILL_RX_BUFFER_LONG:
        return data[:2] != b"\0\0"
    return packet == BufferPacket.PROCESS_RX_BUFFER


class Reassembly:
    """The host side of ``comm_can_send_buffer``: FILL_RX_BUFFER(_LONG) frames into a buffer,
    returned when PROCESS_RX_BUFFER gives its length and CRC (or a PROCESS_SHORT_BUFFER
    reply, whole).  Offset 0 starts a new buffer; a frame at any other offset must continue
    the bytes so far.  A reply that went wrong (a lost frame leaves a gap) is one error, the
    first: the rest of that reply, its FILL frames up to its PROCESS_RX_BUFFER, is dropped
    without another (until that end or the next offset 0), as it cannot be whole."""

    __slots__ = ("_buf", "_lost")

    def __init__(self) -> None:
        self._buf = bytearray()
        #: A frame of the reply under way went wrong: drop the rest of it.
        self._lost = False

    def reset(self) -> None:
        """Forget the bytes so far."""
        self._buf.clear()
        self._lost = False

    def feed(self, frame: Frame) -> BufferReply | None:
        """Take a frame of the buffer protocol (the caller checks its identifier).

        :return: the whole buffer once it is complete, else ``None`` (also for the rest of a
            reply that went wrong, up to its end or the next offset 0).
        :raises DecodeError: for a remote frame, a frame too short, an offset that does not
            continue the buffer, or an end whose length or CRC does not match (the bytes so
            far are dropped, and the rest of the reply with them).
        """
        packet, data = frame.arbitration_id >> 8, bytes(frame.data)
        end = packet == BufferPacket.PROCESS_RX_BUFFER
        if self._lost and _continues(packet, data):
            self._lost = not end  # after its end, the next reply's frames count again
            return None  # the rest of a reply that went wrong
        try:
            return self._feed(BufferPacket(packet), data, frame.is_remote_frame)
        except DecodeError:
            self._buf.clear()
            self._lost = not end  # an end that went wrong leaves nothing of its reply to come
            raise

    def _feed(self, packet: BufferPacket, data: bytes, remote: bool) -> BufferReply | None:
        least = {BufferPacket.FILL_RX_BUFFER: 2, BufferPacket.FILL_RX_BUFFER_LONG: 3,
                 BufferPacket.PROCESS_RX_BUFFER: _RX_END.size,
                 BufferPacket.PROCESS_SHORT_BUFFER: 3}[packet]
        if remote or len(data) < least:
            raise DecodeError(
                f"{packet.name}: expected a data frame of at least {least} bytes, got "
                f"{'a remote frame' if remote else f'{len(data)} bytes'}"
            )
        if packet is BufferPacket.PROCESS_SHORT_BUFFER:
            return BufferReply(data[0], data[1], data[2:])
        if packet is BufferPacket.PROCESS_RX_BUFFER:
            sender, mode, length, crc = _RX_END.unpack_from(data)
            buf, have = bytes(self._buf), len(self._buf)
            self._buf.clear()
            if length != have:
                raise DecodeError(
                    f"PROCESS_RX_BUFFER: expected the length of the {have} bytes received, "
                    f"got {length}"
                )
            if crc != crc16(buf):
                raise DecodeError(
                    f"PROCESS_RX_BUFFER: expected crc16 0x{crc16(buf):04X} of the {have} bytes "
                    f"received, got 0x{crc:04X}"
                )
            return BufferReply(sender, mode, buf)
        if packet is BufferPacket.FILL_RX_BUFFER:
            offset, chunk = data[0], data[1:]
        else:
            offset, chunk = (data[0] << 8) | data[1], data[2:]
        if offset == 0:
            self._buf.clear()
            self._lost = False
        if offset != len(self._buf):
            raise DecodeError(
                f"{packet.name}: expected offset {len(self._buf)} (the bytes so far), got "
                f"{offset}: a frame was lost"
            )
        if offset + len(chunk) > MAX_LENGTH:
            raise DecodeError(
                f"{packet.name}: expected at most {MAX_LENGTH} bytes, got {offset + len(chunk)}"
            )
        self._buf += chunk
        return None
