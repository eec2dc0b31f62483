"""The frames DBC-described controllers send on their own, for the bus-load budget
(:mod:`gateway.drive.traffic`).

A DBC states a message's period in the ``GenMsgCycleTime`` attribute (ms; Vector's "DBC File
Format Documentation", attributes), which cantools reads as ``Message.cycle_time``.  Every
message the driver receives (feedback, fault) counts at that period, one frame per frame ID;
a message without one is listed as not known.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from gateway.drive.traffic import Sender, Stream, Traffic

if TYPE_CHECKING:
    from collections.abc import Iterable

    from drivers.dbc.frames import Group


def received_traffic(groups: Iterable[Group]) -> Traffic:
    """The streams of the received frame IDs ``groups`` (by message), and the messages
    without a cycle time."""
    per_message: dict[tuple[str, int, bool, int], int] = {}
    unknown: dict[str, int] = {}
    for g in groups:
        name = str(g.message.name)
        cycle = g.message.cycle_time
        if cycle:
            key = (name, g.length, g.extended, int(cycle))
            per_message[key] = per_message.get(key, 0) + 1
        else:
            unknown[name] = unknown.get(name, 0) + 1
    return Traffic(
        tuple(Stream(name, Sender.CONTROLLERS, n * 1000.0 / cycle, dlc, ext,
                     f"{cycle} ms each, GenMsgCycleTime in the DBC")
              for (name, dlc, ext, cycle), n in per_message.items()),
        tuple(f"{name} ({n} frame ID{'s' if n > 1 else ''}): no GenMsgCycleTime in the DBC"
              for name, n in unknown.items()))
