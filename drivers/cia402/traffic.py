"""The frames of a CiA 402 bus besides the commands, for the bus-load budget
(:mod:`gateway.drive.traffic`).

The driver writes every rate itself while enabling (:mod:`drivers.cia402.driver`), so nothing
here is assumed:

* each drive's two feedback TPDOs (statusword + position, statusword + velocity: 6 bytes
  each) at every SYNC (transmission type 1) with ``sync: true``, which the driver sends once
  per cycle; else at their event timer ``event_timer_ms`` (0x18xx:05), plus one at each new
  statusword (occasional, not counted);
* each drive's heartbeat every ``heartbeat_ms`` (0x1017, 1 byte; 0: none);
* the gateway's own heartbeat every ``host_heartbeat_s`` (``0x700 + host_node_id``, 1 byte).

EMCY frames, SDO exchanges and NMT commands come with events, not periodically.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from gateway.drive.traffic import Sender, Stream, Traffic

if TYPE_CHECKING:
    from collections.abc import Sequence

    from drivers.cia402.options import Cia402Options

#: A feedback TPDO's bytes: the statusword (2) and a 32-bit position or velocity.
TPDO_BYTES = 6


def bus_traffic(opts: Sequence[Cia402Options], rate_hz: float) -> Traffic:
    """The TPDOs and heartbeats of the drives with these options, and the gateway's heartbeat,
    at loop rate ``rate_hz``."""
    tpdos: dict[tuple[str, str], float] = {}
    for o in opts:
        per_s, basis = ((rate_hz, f"at every SYNC (gateway.rate_hz {rate_hz:g})") if o.sync
                        else (1000.0 / o.event_timer_ms, "every event_timer_ms"))
        for number in (o.tpdo_position, o.tpdo_velocity):
            key = (f"TPDO{number}", basis)
            tpdos[key] = tpdos.get(key, 0.0) + per_s
    streams = [Stream(name, Sender.CONTROLLERS, per_s, TPDO_BYTES, False, f"each drive {basis}")
               for (name, basis), per_s in tpdos.items()]
    beats = [o.heartbeat_ms for o in opts if o.heartbeat_ms]
    if beats:
        streams.append(Stream(
            "HEARTBEAT", Sender.CONTROLLERS, sum(1000.0 / ms for ms in beats), 1, False,
            f"each drive every heartbeat_ms ({', '.join(map(str, sorted(set(beats))))})"))
    if opts:
        period = opts[0].host_heartbeat_s  # (bus-wide)
        streams.append(Stream("HEARTBEAT", Sender.GATEWAY, 1.0 / period, 1, False,
                              f"the gateway's, every host_heartbeat_s ({period:g})"))
    return Traffic(tuple(streams))
