"""The simulated VESC's side of COMM_GET_APPCONF (:mod:`drivers.vesc.appconf`).

As firmware 6.00 does it (https://github.com/vedderb/bldc at the tag ``6.00``):
``decode_msg`` in ``comm/comm_can.c`` runs a PROCESS_SHORT_BUFFER with send mode 0 through
``commands_process_packet``; ``comm/commands.c`` answers COMM_GET_APPCONF with ``[17,
confgenerator_serialize_appconf(...)]``, and ``comm_can_send_buffer`` sends it back to the
sender with send mode 1 (:func:`send_buffer`).  The serialized configuration
(:func:`serialize_appconf`) has 6.00's length (:data:`LENGTH_6_00`, counted from
``confgenerator.c`` at that tag) and signature (:data:`SIGNATURE_6_00`, ``confgenerator.h``),
the simulator's ``controller_id``, ``timeout_msec``, ``timeout_brake_current`` (0 A),
``can_status_rate_1`` and ``can_status_msgs_r1``; the fields after those are zero-filled (the
reader never looks at them).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

from drivers.vesc.appconf import BufferPacket, CommPacket, SendMode, crc16
from gateway.core.types import Frame

#: ``APPCONF_SIGNATURE`` of firmware 6.00 (``confgenerator.h`` at the tag ``6.00``).
SIGNATURE_6_00 = 486554156
#: Bytes ``confgenerator_serialize_appconf`` writes at 6.00 (``confgenerator.c``).
LENGTH_6_00 = 493
_LEAD = struct.Struct(">IBIIHHB")


def serialize_appconf(controller_id: int, timeout_msec: int, *, status_rate_hz: int = 50,
                      status_msgs: int = 0, signature: int = SIGNATURE_6_00,
                      length: int = LENGTH_6_00) -> bytes:
    """A serialized app configuration: signature, ``controller_id``, ``timeout_msec``,
    ``timeout_brake_current`` 0.0 (``buffer_append_float32_auto`` writes 0 as four zero
    bytes), ``can_status_rate_1`` and ``_2``, ``can_status_msgs_r1``, then zeros."""
    lead = _LEAD.pack(signature, controller_id, timeout_msec, 0, status_rate_hz, 0, status_msgs)
    return lead + bytes(max(length - len(lead), 0))


def send_buffer(to_id: int, sender_id: int, data: bytes,
                send: int = SendMode.REPLY) -> list[Frame]:
    """``comm_can_send_buffer``: the frames that carry ``data`` to ``to_id``."""
    def frame(packet: BufferPacket, payload: bytes) -> Frame:
        return Frame((packet << 8) | to_id, payload, True)

    if len(data) <= 6:
        return [frame(BufferPacket.PROCESS_SHORT_BUFFER, bytes((sender_id, send)) + data)]
    out, end_a = [], 0
    for i in range(0, len(data), 7):
        if i > 255:
            break
        end_a = i + 7
        out.append(frame(BufferPacket.FILL_RX_BUFFER, bytes((i,)) + data[i:i + 7]))
    for i in range(end_a, len(data), 6):
        out.append(frame(BufferPacket.FILL_RX_BUFFER_LONG, struct.pack(">H", i) + data[i:i + 6]))
    end = struct.pack(">BBHH", sender_id, send, len(data), crc16(data))
    return [*out, frame(BufferPacket.PROCESS_RX_BUFFER, end)]


@dataclass(frozen=True, slots=True)
class AppconfResponder:
    """How a simulated VESC answers COMM_GET_APPCONF.

    :param answers: ``False``: no answer (firmware or a path that does not answer).
    :param signature: ``APPCONF_SIGNATURE`` sent.
    :param controller_id: the ``controller_id`` sent (``None``: the VESC's own).
    :param crc_xor: flipped into the CRC sent (a corrupted reply, for tests).
    """

    answers: bool = True
    signature: int = SIGNATURE_6_00
    controller_id: int | None = None
    crc_xor: int = 0

    def answer(self, frame: Frame, node_id: int, timeout_s: float, status_rate_hz: float,
               status_msgs: int) -> list[Frame]:
        """The reply of VESC ``node_id`` (with these settings) to a PROCESS_SHORT_BUFFER frame
        addressed to it (none to a packet other than COMM_GET_APPCONF, or another send mode)."""
        data = bytes(frame.data)
        if (not self.answers or frame.is_remote_frame or len(data) < 3
                or data[1] != SendMode.PROCESS_AND_REPLY or data[2] != CommPacket.GET_APPCONF):
            return []
        conf = serialize_appconf(
            node_id if self.controller_id is None else self.controller_id,
            round(timeout_s * 1000.0), status_rate_hz=round(status_rate_hz),
            status_msgs=status_msgs, signature=self.signature)
        frames = send_buffer(data[0], node_id, bytes((CommPacket.GET_APPCONF,)) + conf)
        if self.crc_xor:
            last = frames[-1]
            crc = int.from_bytes(last.data[4:6], "big") ^ self.crc_xor
            frames[-1] = Frame(last.arbitration_id, bytes(last.data[:4]) + crc.to_bytes(2, "big"),
                               True)
        return frames
