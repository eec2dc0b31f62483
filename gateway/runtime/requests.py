"""The daemon's answers to the control socket's requests (:mod:`gateway.wire.socket`).

:class:`RequestHandler` takes one parsed request (or the :class:`ProtocolError` of a line that
did not parse), acts on the gateway -- a twist to follow, stop, e-stop (latched on disk),
enable, disable, an odometry reset, a subscription -- and queues the reply for its client.
The daemon (:mod:`gateway.runtime.daemon`) calls it between cycles, from its loop's thread.
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING

from gateway.core.control import Accepted, Source
from gateway.wire.socket import (
    CommandRequest,
    Op,
    ProtocolError,
    ResetOdometryRequest,
    SubscribeRequest,
    TwistRequest,
    reply_error,
    reply_ok,
    reply_ok_data,
    reply_protocol_error,
)
from gateway.wire.socket.status import odometry_to_json, status_to_json

if TYPE_CHECKING:
    from collections.abc import Callable

    from gateway.core.status import GatewayStatus
    from gateway.core.types import Frame
    from gateway.runtime.latch import EstopLatch
    from gateway.runtime.loop import Gateway
    from gateway.runtime.server import ControlServer
    from gateway.wire.socket import Request

__all__ = ["RequestHandler"]


class RequestHandler:
    """Answers control-socket requests.

    :param gateway: the gateway whose cycle the daemon runs.
    :param server: the control server the replies go out through.
    :param latch: the e-stop latch on disk (an ``estop`` request sets it).
    :param status: everything a ``status`` request returns, now.
    """

    def __init__(self, gateway: Gateway, server: ControlServer, latch: EstopLatch,
                 status: Callable[[], GatewayStatus]) -> None:
        self.gateway = gateway
        self.server = server
        self.latch = latch
        self.status = status
        #: ``time.perf_counter()`` when each twist accepted since the last cycle arrived:
        #: where the daemon's twist-to-frames latency starts (the daemon empties it).
        self.pending_twists: list[float] = []

    def handle(self, client: int, request: Request | ProtocolError, now_s: float) -> None:
        """Answer one socket request."""
        gw, server = self.gateway, self.server
        if isinstance(request, ProtocolError):
            server.reply(client, reply_protocol_error(request))
            return
        rid = request.id
        if isinstance(request, TwistRequest):
            result = gw.twist(request.twist, now_s, Source.SOCKET)
            if isinstance(result, Accepted):
                self.pending_twists.append(time.perf_counter())
                server.reply(client, reply_ok(rid, {
                    "twist": result.twist, "projected": result.projected,
                    **({"warning": str(result.error)} if result.error else {}),
                }))
                return
            details: dict[str, object] = {}
            if result.error is not None:
                err = result.error
                details = {"wheel": err.wheel, "constraint": err.constraint,
                           "residual_m_s": err.residual_m_s, "nearest": err.nearest}
            out: list[Frame] = []
            gw.report_error(result.code, result.message, out, result)
            gw.edge.send(out)
            server.reply(client, reply_error(rid, result.code, result.message, **details))
            return
        if isinstance(request, ResetOdometryRequest):
            gw.odometry.reset(request.pose)
            odometry = odometry_to_json(gw.odometry.state)
            server.reply(client, reply_ok(rid, {"odometry": odometry}))
            return
        if isinstance(request, SubscribeRequest):
            server.subscribe(client, request.topics)
            server.reply(client, reply_ok(rid, {"topics": sorted(t.value for t in request.topics)}))
            return
        self._command(client, request, now_s)

    def _command(self, client: int, request: CommandRequest, now_s: float) -> None:
        sup, rid = self.gateway.supervisor, request.id
        if request.op is Op.STATUS:
            self.server.reply(client, reply_ok_data(rid, status_to_json(self.status())))
            return
        if request.op is Op.STOP:
            sup.stop(now_s)
        elif request.op is Op.ESTOP:
            sup.estop("e-stop requested on the control socket")
            self.latch.set(sup.reason)
        elif request.op is Op.ENABLE:
            sup.enable(now_s)
        elif request.op is Op.DISABLE:
            sup.disable()
        elif request.op is Op.UNSUBSCRIBE:
            self.server.unsubscribe(client)
        self.server.reply(client, reply_ok(rid, {"state": sup.state}))
