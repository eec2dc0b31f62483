"""VESC controllers on a scan (:class:`VescProbe`, ``wheelgate scan``).

A VESC sends **status** messages only when VESC Tool enabled them (``can_status_msgs_r1`` is 0
from the factory), so a factory VESC is silent on the bus.  The scan finds those through
the protocol's own discovery: **PING**, packet 17 to each controller ID 0..254 in turn
(``(17 << 8) | id``, one byte: the pinger's ID, :data:`PINGER_ID`), which a VESC with that ID
answers with a **PONG** (packet 18) to ``(18 << 8) | pinger`` carrying the ID it was asked as
and its ``HW_TYPE`` (``comm/comm_can.c``, ``decode_msg``, in https://github.com/vedderb/bldc).
This is how the firmware itself scans the bus (``comm_can_ping``, one ID at a time: a broadcast
PING to 255 is answered with 255, not with the IDs).  PING moves nothing, changes no setting
and does not reset the command timeout (``decode_msg`` calls ``timeout_reset()`` only for the
motor commands).  Status frames seen (STATUS 1..6, any packet of the six, DLC 8) also show a
controller, and STATUS and STATUS_5 are read.

A PONG is taken only in the shape the firmware sends it: a data frame of two bytes, the ID and
``HW_TYPE`` (``comm/comm_can.c``, ``decode_msg``, ``case CAN_PACKET_PING``: ``buffer[1] =
HW_TYPE_VESC``, sent with length 2), or of one, the ID alone, from firmware before ``HW_TYPE``
was added (its ``case CAN_PACKET_PONG`` still reads a one-byte PONG as ``HW_TYPE_VESC``), whose
first byte is the ID that was pinged
(:class:`PingRequest`).  Any other frame on the PONG identifier (another device's, eight bytes
that happen to start with that ID) answers nothing: it is counted as traffic on its identifier
and listed with the unknown ones, and no VESC is made of it.

The pings go out once, after the scan's listening quarter, to 29-bit identifiers
0x1100..0x11FE (a VESC powered after its PING went out is found only by its status frames); a
device of another protocol whose frames use them (an ODrive with 29-bit identifiers at node
136..143) is skipped by the scan once found.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar

from drivers.vesc.codec import (
    BROADCAST_ID,
    CanPacketId,
    HwType,
    VescPong,
    VescStatus,
    VescStatus5,
    arbitration_id,
    decode,
    make_ping,
)
from gateway.core.errors import DecodeError
from gateway.drive.scan import Description, Found, Request, ScanProbe

if TYPE_CHECKING:
    from collections.abc import Sequence

    from gateway.core.types import Frame
    from gateway.drive.scan import Answer, Heard, Reading

#: The controller ID the scan pings as (where the PONGs go).  254, next to the broadcast ID:
#: a VESC with this ID still answers its own PING.
PINGER_ID = 254
#: The status packets whose frames show a controller.
STATUS_PACKETS = frozenset({CanPacketId.STATUS, CanPacketId.STATUS_2, CanPacketId.STATUS_3,
                            CanPacketId.STATUS_4, CanPacketId.STATUS_5, CanPacketId.STATUS_6})
#: The key of a PING request.
PING = "PING"
#: Identifier bits a VESC frame leaves zero (``decode_msg``: packet below 256, ID one byte).
_HIGH_BITS = ~0xFFFF


@dataclass(frozen=True, slots=True)
class PingRequest(Request):
    """A PING, answered only by a PONG as the firmware sends it (see the module): a data
    frame on the PONG identifier, of one or two bytes (:func:`~drivers.vesc.codec.decode`
    checks the length), the first the ID that was pinged."""

    def answered_by(self, frame: Frame) -> bool:
        # (Request's method by name: a slotted dataclass has no zero-argument super().)
        if not Request.answered_by(self, frame):
            return False
        try:
            pong = decode(frame)
        except DecodeError:
            return False
        return isinstance(pong, VescPong) and pong.node_id == self.node_id


class VescProbe(ScanProbe):
    """VESC controllers, by status frames and PING (see the module)."""

    PROTOCOL: ClassVar[str] = "vesc"
    TITLE: ClassVar[str] = "VESC"
    DRIVER: ClassVar[str] = "vesc"
    PRECEDENCE: ClassVar[int] = 30

    def find(self, heard: Sequence[Heard]) -> list[Found]:
        out = []
        for h in heard:
            arb = h.arbitration_id
            if (h.is_extended_id and not arb & _HIGH_BITS and arb >> 8 in STATUS_PACKETS
                    and h.last is not None and h.last.dlc == 8 and arb & 0xFF != BROADCAST_ID):
                out.append(Found(arb & 0xFF, True, "status"))
        return out

    def owns(self, found: Found, arbitration_id: int, extended: bool) -> bool:
        return extended and not arbitration_id & _HIGH_BITS and (
            arbitration_id & 0xFF == found.node_id)

    def reserved(self, arbitration_id: int, extended: bool) -> bool:
        """The broadcast commands (controller ID 255), which every VESC takes."""
        return extended and not arbitration_id & _HIGH_BITS and (
            arbitration_id & 0xFF == BROADCAST_ID)

    def discovery(self) -> tuple[Request, ...]:
        pong = arbitration_id(CanPacketId.PONG, PINGER_ID)
        return tuple(PingRequest(PING, k, make_ping(k, PINGER_ID), pong, True, bytes((k,)))
                     for k in range(BROADCAST_ID))

    def found_by(self, answer: Answer) -> Found | None:
        # (the answer's frame passed PingRequest.answered_by: a PONG of the pinged ID)
        if answer.request.key != PING or answer.frame is None:
            return None
        return Found(answer.request.node_id, True, "pong")

    def describe(self, found: Found, heard: Sequence[Heard],
                 answers: Sequence[Answer]) -> Description:
        readings: list[Reading] = []
        for h in sorted(heard, key=lambda h: h.arbitration_id):
            try:
                msg = None if h.last is None else decode(h.last)
            except DecodeError:
                continue
            if isinstance(msg, VescStatus):
                readings += [("erpm", msg.erpm), ("current_a", msg.current_a),
                             ("duty", msg.duty)]
            elif isinstance(msg, VescStatus5):
                readings += [("tachometer", msg.tachometer), ("v_in_v", msg.v_in_v)]
        hardware = None
        for a in answers:
            pong = _pong(a)
            if pong is not None:
                try:
                    hardware = HwType(pong.hw_type).name
                except ValueError:
                    hardware = f"HW_TYPE {pong.hw_type}"
        notes = []
        if not any(h.arbitration_id >> 8 in STATUS_PACKETS for h in heard):
            notes.append("no status messages (none from the factory: VESC Tool, App Settings > "
                         "General > CAN Status Message Rate 1, Status 1 and 5)")
        if hardware is None and any(a.request.key == PING for a in answers):
            notes.append("no PONG")
        return Description(hardware=hardware, readings=tuple(readings), notes=tuple(notes))


def _pong(answer: Answer) -> VescPong | None:
    if answer.request.key != PING or answer.frame is None:
        return None
    try:
        msg = decode(answer.frame)
    except DecodeError:
        return None
    return msg if isinstance(msg, VescPong) else None
