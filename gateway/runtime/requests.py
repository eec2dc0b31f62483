"""The daemon's answers to the control socket's requests (:mod:`gateway.wire.socket`).

:class:`RequestHandler` takes one parsed request (or the :class:`ProtocolError` of a line that
did not parse), acts on the gateway -- a twist to follow, stop, e-stop (latched on disk),
enable, disable, an odometry reset, a subscription -- and queues the reply for its client.
The daemon (:mod:`gateway.runtime.daemon`) calls it between cycles, from its loop's thread.
"""

from __future__ import annotations

import logging
import time
from typing import TYPE_CHECKING, Protocol

from gateway.core.control import Accepted, Source
from gateway.core.errors import GatewayError
from gateway.core.kinematics.limits import binding_limit
from gateway.core.settings import EstopRelease
from gateway.core.types import ErrorCode, GatewayState
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
    from collections.abc import Callable, Iterable

    from gateway.core.status import GatewayStatus
    from gateway.core.types import Twist
    from gateway.runtime.latch import EstopLatch
    from gateway.runtime.loop import Gateway
    from gateway.wire.socket import Request, Topic

__all__ = ["Replier", "RequestHandler"]

log = logging.getLogger(__name__)


class Replier(Protocol):
    """Where a handler's replies go: the control socket's clients, or the Zenoh bridge's."""

    def reply(self, client_id: int, data: bytes) -> bool: ...

    def subscribe(self, client_id: int, topics: Iterable[Topic]) -> bool: ...

    def unsubscribe(self, client_id: int) -> bool: ...


class RequestHandler:
    """Answers control-socket requests (and the same requests from the Zenoh bridge).

    :param gateway: the gateway whose cycle the daemon runs.
    :param server: where the replies go out.
    :param latch: the e-stop latch on disk (an ``estop`` request sets it).
    :param status: everything a ``status`` request returns, now.
    :param source: where the twists come from (for the log).
    :param origin: how an e-stop's reason names where it came from.
    """

    def __init__(self, gateway: Gateway, server: Replier, latch: EstopLatch,
                 status: Callable[[], GatewayStatus], source: Source = Source.SOCKET,
                 origin: str = "the control socket") -> None:
        self.gateway = gateway
        self.server = server
        self.latch = latch
        self.status = status
        self.source = source
        self.origin = origin
        #: The twist the last twist request made the target (``None``: refused).
        self.last_accepted: Twist | None = None
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
            result = gw.twist(request.twist, now_s, self.source)
            self.last_accepted = result.twist if isinstance(result, Accepted) else None
            if isinstance(result, Accepted):
                self.pending_twists.append(time.perf_counter())
                applied, limited_by = self._applied(result)
                server.reply(client, reply_ok(rid, {
                    "twist": result.twist, "projected": result.projected,
                    "applied": applied, "limited_by": limited_by,
                    **({"warning": str(result.error)} if result.error else {}),
                }))
                return
            details: dict[str, object] = {}
            if result.error is not None:
                err = result.error
                details = {"wheel": err.wheel, "constraint": err.constraint,
                           "residual_m_s": err.residual_m_s, "nearest": err.nearest}
            # On CAN with the next cycle's reports (at most one WG_Error a cycle, see
            # Gateway.report_error): a request never sends on the bus itself.
            gw.report_error(result.code, result.message, rejection=result)
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

    def handle_safely(self, client: int, request: Request | ProtocolError, now_s: float) -> None:
        """:meth:`handle`, but a reply that cannot be built becomes an error reply: no client
        message may stop the loop."""
        try:
            self.handle(client, request, now_s)
        except (GatewayError, ValueError, UnicodeError) as err:
            log.warning("request from client %d failed: %s", client, err)
            try:
                self.server.reply(client, reply_error(
                    None, ErrorCode.BAD_COMMAND, f"request failed: {err}"))
            except (GatewayError, ValueError, UnicodeError):
                log.warning("client %d: no error reply possible", client)

    def _applied(self, result: Accepted) -> tuple[Twist, str | None]:
        """The twist the wheels will follow once the speed limits have scaled the accepted one
        (the acceleration limits only ramp towards it), and the limit that scaled it."""
        gw = self.gateway
        ik = result.ik
        if ik is None:
            ik = gw.model.try_ik(result.twist, gw.prev.steer_rad)
            if ik is None:  # cannot happen for an accepted twist; report it unscaled
                return result.twist, None
        scale, why = binding_limit(gw.model, ik, gw.config.limits)
        return (result.twist.scaled(scale), why) if scale < 1.0 else (result.twist, None)

    def _command(self, client: int, request: CommandRequest, now_s: float) -> None:
        sup, rid = self.gateway.supervisor, request.id
        if request.op is Op.STATUS:
            self.server.reply(client, reply_ok_data(rid, status_to_json(self.status())))
            return
        if request.op is Op.STOP:
            sup.stop(now_s)
        elif request.op is Op.ESTOP:
            sup.estop(f"e-stop requested on {self.origin}")
            self.gateway.stop_now(now_s)  # (before the latch's disk write, and any enable)
            self.latch.set(sup.reason)
        elif request.op is Op.ENABLE:
            if (sup.state is GatewayState.ESTOP and self.source is not Source.SOCKET
                    and self.gateway.config.loop.estop_release is EstopRelease.SOCKET):
                self.server.reply(client, reply_error(
                    rid, ErrorCode.ESTOP, f"an e-stop is released only by an enable on the "
                    f"control socket (gateway.estop_release: socket); the enable from "
                    f"{self.origin} was refused", state=sup.state))
                return
            was_estop = sup.state is GatewayState.ESTOP
            sup.enable(now_s)
            if was_estop and sup.state is not GatewayState.ESTOP:
                self.latch.clear()  # (released here: the next cycle may never see ESTOP)
        elif request.op is Op.DISABLE:
            sup.disable()
        elif request.op is Op.UNSUBSCRIBE:
            self.server.unsubscribe(client)
        self.server.reply(client, reply_ok(rid, {"state": sup.state}))
