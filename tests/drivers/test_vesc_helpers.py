"""Helpers of the VESC tests: an enable whose timeout reads are answered at once, as a VESC of
firmware 6.00 answers COMM_GET_APPCONF (drivers/vesc/sim_appconf.py).  No tests here."""

from __future__ import annotations

from typing import TYPE_CHECKING

from drivers.vesc.appconf import HOST_ID, BufferPacket
from drivers.vesc.sim_appconf import send_buffer, serialize_appconf

if TYPE_CHECKING:
    from collections.abc import Mapping, Sequence

    from drivers.vesc import VescDriver
    from gateway.core.types import Frame

__all__ = ["answer_reads", "enabled"]


def answer_reads(drv: VescDriver, frames: Sequence[Frame], t: float,
                 read_ms: Mapping[int, int] | None = None) -> list[Frame]:
    """Answer every COMM_GET_APPCONF request in ``frames``, and in the polls (at ``t``) that
    follow, as a VESC of firmware 6.00 would, with ``read_ms[node]`` or else the timeout its
    block states (the factory 1000 ms when it states none); return the other frames."""
    out, todo = [], list(frames)
    while todo:
        f = todo.pop(0)
        if f.arbitration_id >> 8 != BufferPacket.PROCESS_SHORT_BUFFER:
            out.append(f)
            continue
        node = f.arbitration_id & 0xFF
        i = drv.index_of(node)
        assert i is not None
        ms = (read_ms or {}).get(node, round(drv.opts[i].timeout_s * 1000.0))
        for r in send_buffer(HOST_ID, node, bytes((17,)) + serialize_appconf(node, ms)):
            assert drv.on_frame(r.stamped(t))
        todo += drv.poll(t)
    return out


def enabled(drv: VescDriver, t: float, read_ms: Mapping[int, int] | None = None) -> list[Frame]:
    """:meth:`VescDriver.enable` at ``t`` with every timeout read back (:func:`answer_reads`):
    the frames that arm the motors."""
    return answer_reads(drv, drv.enable(t), t, read_ms)
