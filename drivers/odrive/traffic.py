"""The frames an ODrive axis sends on its own, for the bus-load budget
(:mod:`gateway.drive.traffic`).

Every axis sends its heartbeat and, unless turned off, its encoder estimates on timers of its
own, at the periods its motor block states (``heartbeat_msg_rate_ms``, ``encoder_msg_rate_ms``:
:mod:`drivers.odrive.options`; the factory's 100 ms and 10 ms unless stated).  With
``encoder_request: rtr`` the driver asks for the estimates every cycle (a remote frame) and the
axis answers each request.  Other cyclic messages (iq, temperature, bus voltage, ...) are off
from the factory and not counted.  All data frames are 8 bytes.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from drivers.odrive.options import FACTORY_ENCODER_MS, FACTORY_HEARTBEAT_MS
from gateway.drive.traffic import Sender, Stream, Traffic

if TYPE_CHECKING:
    from collections.abc import Sequence

    from drivers.odrive.options import OdriveOptions


def axis_traffic(opts: Sequence[OdriveOptions], extended: bool, rate_hz: float) -> Traffic:
    """The heartbeats and estimates of the axes with these options at loop rate ``rate_hz``."""
    streams = [_cyclic("Heartbeat", [o.heartbeat_msg_rate_ms for o in opts],
                       "heartbeat_msg_rate_ms", FACTORY_HEARTBEAT_MS, extended)]
    estimates = [o.encoder_msg_rate_ms for o in opts if o.encoder_msg_rate_ms]
    if estimates:
        streams.append(_cyclic("Get_Encoder_Estimates", estimates, "encoder_msg_rate_ms",
                               FACTORY_ENCODER_MS, extended))
    rtr = sum(1 for o in opts if o.encoder_request == "rtr")
    if rtr:
        every = f"every cycle (gateway.rate_hz {rate_hz:g}), encoder_request: rtr"
        streams += [
            Stream("Get_Encoder_Estimates", Sender.GATEWAY, rtr * rate_hz, 0, extended,
                   every, remote=True),
            Stream("Get_Encoder_Estimates", Sender.CONTROLLERS, rtr * rate_hz, 8, extended,
                   f"the answers, {every}")]
    return Traffic(tuple(streams))


def _cyclic(name: str, periods_ms: Sequence[int], key: str, factory_ms: int,
            extended: bool) -> Stream:
    """One cyclic message of every axis with these periods."""
    said = ", ".join(f"{p}" for p in sorted(set(periods_ms)))
    whose = "the factory's" if set(periods_ms) == {factory_ms} else "as stated"
    return Stream(name, Sender.CONTROLLERS, sum(1000.0 / p for p in periods_ms), 8, extended,
                  f"{said} ms each, {key} ({whose})")
