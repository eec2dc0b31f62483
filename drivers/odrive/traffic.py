"""The frames an ODrive axis sends on its own, for the bus-load budget
(:mod:`gateway.drive.traffic`).

Every axis sends its heartbeat and, unless the estimates are requested (``encoder_request:
rtr``), its encoder estimates on timers of its own.  wheelgate does not write those rates, so
the budget takes the firmware's factory defaults: 100 ms and 10 ms (0.5.x
``axis.config.can.heartbeat_rate_ms`` and ``encoder_rate_ms``, ``can_simple.cpp``
``service_stack()`` of odriverobotics/ODrive; 0.6 ``heartbeat_msg_rate_ms`` and
``encoder_msg_rate_ms``, the ODrive CAN protocol page).  The other cyclic messages are off from
the factory.  With ``encoder_request: rtr`` the driver asks for the estimates every cycle (a
remote frame) and the axis answers each request.  All frames are 8 bytes.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from gateway.drive.traffic import Sender, Stream, Traffic

if TYPE_CHECKING:
    from collections.abc import Sequence

    from drivers.odrive.options import OdriveOptions

#: The factory heartbeat and encoder-estimate periods (s).
HEARTBEAT_S = 0.1
ENCODER_S = 0.01


def axis_traffic(opts: Sequence[OdriveOptions], extended: bool, rate_hz: float) -> Traffic:
    """The heartbeats and estimates of the axes with these options at loop rate ``rate_hz``."""
    n = len(opts)
    rtr = sum(1 for o in opts if o.encoder_request == "rtr")
    rates = "heartbeat_msg_rate_ms (0.5: heartbeat_rate_ms)"
    streams = [Stream("Heartbeat", Sender.CONTROLLERS, n / HEARTBEAT_S, 8, extended,
                      f"{HEARTBEAT_S * 1000:g} ms each, the factory {rates}")]
    if n - rtr:
        streams.append(Stream(
            "Get_Encoder_Estimates", Sender.CONTROLLERS, (n - rtr) / ENCODER_S, 8, extended,
            f"{ENCODER_S * 1000:g} ms each, the factory encoder_msg_rate_ms (0.5: "
            f"encoder_rate_ms)"))
    if rtr:
        every = f"every cycle (gateway.rate_hz {rate_hz:g}), encoder_request: rtr"
        streams += [
            Stream("Get_Encoder_Estimates", Sender.GATEWAY, rtr * rate_hz, 0, extended,
                   every, remote=True),
            Stream("Get_Encoder_Estimates", Sender.CONTROLLERS, rtr * rate_hz, 8, extended,
                   f"the answers, {every}")]
    return Traffic(tuple(streams))
