"""Which CAN frames are a :class:`~drivers.vesc.driver.VescDriver`'s: its claims, the labels
of their messages, and the PONGs it takes (``datatypes.h`` and ``comm/comm_can.c`` in
https://github.com/vedderb/bldc)."""

from __future__ import annotations

from typing import TYPE_CHECKING

from drivers.vesc.appconf import HOST_ID, BufferPacket
from drivers.vesc.codec import CanPacketId, arbitration_id, decode
from gateway.core.errors import DecodeError
from gateway.drive.claims import FrameClaim

if TYPE_CHECKING:
    from collections.abc import Callable, Sequence

    from drivers.vesc.settings import VescOptions
    from gateway.core.types import Frame
    from gateway.drive.traffic import Traffic

#: The liveness streams (:attr:`VescDriver.LIVENESS_STREAMS`), by index.
STATUS, STATUS_5 = 0, 1
#: Status packets of our VESCs that the driver takes without decoding.
UNUSED = 2
#: Every status packet the driver takes, in packet order, with its use.
RECEIVED = (
    (CanPacketId.STATUS, STATUS),
    (CanPacketId.STATUS_2, UNUSED),
    (CanPacketId.STATUS_3, UNUSED),
    (CanPacketId.STATUS_4, UNUSED),
    (CanPacketId.STATUS_5, STATUS_5),
    (CanPacketId.STATUS_6, UNUSED),
)
#: Every PONG, whatever pinger's ID is in its low byte.
_PONGS = FrameClaim(CanPacketId.PONG << 8, 0x1FFFFF00, True)
#: The commands the driver sends.
_SENT = (CanPacketId.SET_CURRENT, CanPacketId.SET_RPM)


def claims(node_ids: Sequence[int], reads: bool) -> tuple[FrameClaim, ...]:
    """The frames of our VESCs, as 29-bit identifiers (``packet << 8 | controller ID``):
    per controller, STATUS and STATUS_5 (used) and STATUS_2/3/4/6 (taken, unused), exact;
    every PONG, whatever pinger's ID is in its low byte (the answering controller is in the
    payload, so the identifier cannot tell ours from another's; PONGs answer a PING, which
    the driver never sends, so they are rare); the commands sent (SET_CURRENT, SET_RPM), for
    the labels; and with ``reads`` (the timeouts are read back), the COMM_GET_APPCONF requests
    sent (PROCESS_SHORT_BUFFER to each controller) and the buffer protocol's frames to the
    gateway's ID (the replies, of no one motor: their FILL frames do not name the sender).
    A command another master sends one of our controllers is not taken (the gateway's watch
    for a second commander hears the cyclic ones: :mod:`gateway.runtime.commanders`)."""
    out = [
        *(FrameClaim.exact(arbitration_id(packet, n), True, i)
          for i, n in enumerate(node_ids) for packet, _ in RECEIVED),
        _PONGS,
        *(FrameClaim.exact(arbitration_id(packet, n), True, i, receive=False)
          for i, n in enumerate(node_ids) for packet in _SENT),
    ]
    if reads:
        out += [FrameClaim.exact((p << 8) | HOST_ID, True) for p in BufferPacket]
        out += [FrameClaim.exact((BufferPacket.PROCESS_SHORT_BUFFER << 8) | n, True, i,
                                 receive=False) for i, n in enumerate(node_ids)]
    return tuple(out)


def message_name(arbitration_id: int, is_extended_id: bool) -> str | None:
    """The ``CAN_PACKET_ID`` name of a VESC frame (``STATUS_5``), ``packet N`` for one the
    driver does not know; ``None`` for an 11-bit frame (never VESC's)."""
    if not is_extended_id:
        return None
    packet = (arbitration_id >> 8) & 0xFF
    for enum_ in (CanPacketId, BufferPacket):
        try:
            return enum_(packet).name
        except ValueError:
            pass
    return f"packet {packet}"


def pong_is_ours(frame: Frame, index_of: Callable[[int], int | None]) -> bool:
    """Whether ``frame`` is a PONG that names one of our VESCs (proof of life, but liveness is
    defined by the status streams).

    :raises DecodeError: for a malformed PONG to one of our IDs.
    """
    if not frame.is_extended_id or frame.arbitration_id >> 8 != CanPacketId.PONG:
        return False
    try:
        msg = decode(frame)
    except DecodeError:
        if index_of(frame.arbitration_id & 0xFF) is None:
            return False
        raise
    return msg is not None and index_of(msg.node_id) is not None


def status_traffic(opts: Sequence[VescOptions]) -> Traffic:
    """The status frames of VESCs with these motor blocks, for the bus-load budget
    (:mod:`gateway.drive.traffic`): STATUS and STATUS_5 (8 bytes, 29-bit) at each block's
    ``status_rate_hz``; a block that does not state it is listed as not known (a factory VESC
    sends none, and wheelgate cannot read the rate).  The gateway's periodic SET_RPM is
    the budget's, from the commands."""
    from gateway.drive.traffic import Sender, Stream, Traffic  # noqa: PLC0415 - check and run only

    rates = [o.status_rate_hz for o in opts]
    stated = [r for r in rates if r]
    streams = tuple(
        Stream(name, Sender.CONTROLLERS, sum(stated), 8, True,
               f"status_rate_hz ({', '.join(f'{r:g}' for r in sorted(set(stated)))})")
        for name in ("STATUS", "STATUS_5")) if stated else ()
    missing = len(rates) - len(stated)
    unknown = (f"STATUS and STATUS_5 of {missing} VESC(s) whose status_rate_hz is not stated",
               ) if missing else ()
    return Traffic(streams, unknown)
