""":class:`Bridge`: the daemon's Zenoh edge (see :mod:`gateway.runtime.bridge`).

Three kinds of threads meet here, and none waits for another:

* Zenoh's own threads run the callbacks: a twist sample, a query, a commander's token coming or
  going is parsed there and appended to the inbox (a bounded deque; appends are atomic);
* the loop thread drains the inbox between cycles (:meth:`Bridge.poll`, at most
  :data:`POLL_MAX` items a call), hands each request to the same
  :class:`~gateway.runtime.requests.RequestHandler` logic as the socket's, and posts news and
  replies to the :class:`~gateway.runtime.mailbox.Mailbox` -- a lock held for a few stores;
* the bridge's worker thread takes from the mailbox and does every Zenoh ``put`` and query
  reply (50-70 us each of the calling thread): never the loop.

A flood cannot grow memory or the loop's work: the inbox holds :data:`INBOX_MAX` items (a query
beyond it is answered "busy" at once, a twist beyond it is dropped and counted; a commander's
token event still gets in, into :data:`COMMANDER_RESERVE` more), and the loop takes at most
:data:`POLL_MAX` a call.
"""

from __future__ import annotations

import collections
import functools
import logging
import threading
from typing import TYPE_CHECKING, Any, cast

from gateway.core.events import OdometryEvent
from gateway.core.status import LastError
from gateway.core.types import ErrorCode
from gateway.runtime.bridge.inbox import NO_REPLY, CommanderEvent, Inbound
from gateway.runtime.bridge.native import (
    RPC_OPS,
    NativeKeys,
    commander_of,
    parse_query,
    parse_twist_sample,
)
from gateway.runtime.bridge.session import open_session
from gateway.runtime.mailbox import Mailbox
from gateway.wire.socket import ProtocolError, reply_error
from gateway.wire.socket.events import event_line

if TYPE_CHECKING:
    from collections.abc import Iterable

    from gateway.core.bridge_settings import BridgeSettings
    from gateway.runtime.bridge.ros2 import Ros2Side
    from gateway.runtime.mailbox import Delivery
    from gateway.wire.socket import Op, Request, Topic

log = logging.getLogger(__name__)

__all__ = ["COMMANDER_RESERVE", "INBOX_MAX", "POLL_MAX", "Bridge"]

#: Items the inbox holds (twists beyond are dropped, queries answered "busy").
INBOX_MAX = 1024
#: Room beyond :data:`INBOX_MAX` kept for the commanders' token events.
COMMANDER_RESERVE = 256
#: Items the loop takes per :meth:`Bridge.poll`.
POLL_MAX = 64
#: Seconds the worker waits for news before looking again (it also wakes on news).
WORKER_WAKE_S = 0.5


class Bridge:
    """The Zenoh side of the daemon (see the module's doc).

    :param settings: the ``bridge:`` block.
    :raises BridgeError: when Zenoh is missing or the session cannot be opened.
    """

    def __init__(self, settings: BridgeSettings) -> None:
        self.settings = settings
        self.keys = NativeKeys.of(settings.namespace)
        #: News and replies from the loop for the worker.
        self.mailbox: Mailbox[tuple[int, bytes]] = Mailbox()
        self._inbox: collections.deque[Inbound | CommanderEvent] = collections.deque()
        self._lock = threading.Lock()
        self._queries: dict[int, Any] = {}
        self._next_client = NO_REPLY + 1
        #: Twists dropped because the inbox was full; queries answered "busy".
        self.dropped = 0
        self._closed = False
        self._entities: list[Any] = []
        # Any: the zenoh stubs leave close() and undeclare() untyped.
        self.session: Any = cast("Any", open_session(settings.zenoh))
        try:
            self._declare()
        except BaseException:
            self.session.close()
            raise
        self._worker = threading.Thread(target=self._work, name="wheelgate-bridge", daemon=True)
        self._worker.start()
        log.info("bridge: Zenoh session %s, keys %s/..., listening on %s", self.session.zid(),
                 self.keys.root, ", ".join(settings.zenoh.listen) or "nothing")

    # ----------------------------------------------------------------- declarations

    def _declare(self) -> None:
        s = self.session
        keys = self.keys
        self._entities.append(s.declare_subscriber(keys.twist, self._on_twist))
        for op in RPC_OPS:
            self._entities.append(s.declare_queryable(
                keys.rpc(op), functools.partial(self._on_query, op)))
        self._entities.append(s.liveliness().declare_subscriber(
            keys.commanders, self._on_commander, history=True))
        self._odom = s.declare_publisher(keys.odom)
        self._status = s.declare_publisher(keys.status)
        self._error = s.declare_publisher(keys.error)
        self._entities += [self._odom, self._status, self._error]
        self._ros: Ros2Side | None = None
        if self.settings.ros2 is not None:
            from gateway.runtime.bridge.ros2 import Ros2Side  # noqa: PLC0415 - with ros2: only

            self._ros = Ros2Side(
                s, self.settings.ros2, self.settings.ros_namespace,
                twist=lambda request, who: self._admit_twist(Inbound(NO_REPLY, request, who)),
                commander=lambda who, alive: self._admit(CommanderEvent(who, alive)),
                error=lambda err: self.mailbox.post(errors=(err,)))
        self._token: Any = s.liveliness().declare_token(keys.gateway_token)

    # ----------------------------------------------------------------- Zenoh's threads

    def _admit(self, item: Inbound | CommanderEvent) -> bool:
        # A commander's token event is never lost to a flood of twists: it may use the
        # reserve beyond the inbox's bound (tokens come and go far more slowly).
        bound = INBOX_MAX + COMMANDER_RESERVE if isinstance(item, CommanderEvent) else INBOX_MAX
        if len(self._inbox) >= bound:
            self.dropped += 1
            return False
        self._inbox.append(item)
        return True

    def _on_twist(self, sample: Any) -> None:
        key = str(sample.key_expr)
        try:
            attachment = sample.attachment
            commander = commander_of(None if attachment is None else attachment.to_bytes(), key)
            request: Request | ProtocolError = parse_twist_sample(sample.payload.to_bytes(), key)
        except ProtocolError as err:
            self.mailbox.post(errors=(_bad(err),))
            return
        self._admit_twist(Inbound(NO_REPLY, request, commander))

    def _admit_twist(self, item: Inbound) -> None:
        if not self._admit(item):
            log.debug("bridge: inbox full, a twist dropped")

    def _on_query(self, op: Op, query: Any) -> None:
        key = str(query.key_expr)
        payload = query.payload
        try:
            request: Request | ProtocolError = parse_query(
                op, None if payload is None else payload.to_bytes(), key)
        except ProtocolError as err:
            request = err
        with self._lock:
            if self._closed:
                client = 0
            else:
                client = self._next_client
                self._next_client += 1
                self._queries[client] = query
        if client and self._admit(Inbound(client, request)):
            return
        with self._lock:
            self._queries.pop(client, None)
        why = "the gateway is stopping" if not client else \
            f"the gateway is busy ({INBOX_MAX} requests waiting)"
        _answer(query, reply_error(getattr(request, "id", None), ErrorCode.BAD_COMMAND, why))

    def _on_commander(self, sample: Any) -> None:
        name = str(sample.key_expr).rsplit("/", 1)[-1]
        alive = str(sample.kind).endswith("PUT")
        self._admit(CommanderEvent(name, alive))

    # ----------------------------------------------------------------- the loop's side

    def poll(self) -> list[Inbound | CommanderEvent]:
        """What came in since the last call (at most :data:`POLL_MAX`), oldest first."""
        out: list[Inbound | CommanderEvent] = []
        inbox = self._inbox
        while inbox and len(out) < POLL_MAX:
            out.append(inbox.popleft())
        return out

    def reply(self, client_id: int, data: bytes) -> bool:
        """Queue the reply to request ``client_id`` for the worker (a published twist's goes
        nowhere)."""
        if client_id != NO_REPLY:
            self.mailbox.post(replies=((client_id, data),))
        return True

    def subscribe(self, client_id: int, topics: Iterable[Topic]) -> bool:
        """Nothing to do: over Zenoh, a client subscribes to the keys themselves."""
        return True

    def unsubscribe(self, client_id: int) -> bool:
        """See :meth:`subscribe`."""
        return True

    # ----------------------------------------------------------------- the worker

    def _work(self) -> None:
        while True:
            news = self.mailbox.take(WORKER_WAKE_S)
            try:
                self._publish(news)
            except Exception:  # a Zenoh error must not end the worker silently
                log.exception("bridge: publishing failed")
            if news.closed:
                return

    def _publish(self, news: Delivery[tuple[int, bytes]]) -> None:
        for client, line in news.replies:
            with self._lock:
                query = self._queries.pop(client, None)
            if query is not None:
                _answer(query, line)
        if news.snapshot is not None:
            self._odom.put(event_line(OdometryEvent(news.snapshot.odometry)))
            if self._ros is not None:
                self._ros.publish(news.snapshot)
        if news.status is not None:
            self._status.put(event_line(news.status))
        for err in news.errors:
            self._error.put(event_line(err))

    # ----------------------------------------------------------------- closing

    def close(self) -> None:
        """Answer what is pending, withdraw the gateway's token and close the session (its
        token disappears for every peer at once)."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
        self.mailbox.close()
        self._worker.join(timeout=2.0)
        with self._lock:
            pending, self._queries = self._queries, {}
        for query in pending.values():
            _answer(query, reply_error(None, ErrorCode.BAD_COMMAND, "the gateway is stopping"))
        try:
            if self._ros is not None:
                self._ros.close()
            self._token.undeclare()
            self.session.close()
        except Exception:  # closing is best effort: the process ends next
            log.exception("bridge: closing the Zenoh session failed")


def _bad(err: ProtocolError) -> LastError:
    return LastError(ErrorCode.BAD_COMMAND, str(err))


def _answer(query: Any, line: bytes) -> None:
    """Reply to a query and finalize it (the querier waits until every reply is sent)."""
    try:
        query.reply(query.key_expr, line)
    except Exception:  # the querier may be gone
        log.debug("bridge: reply to %s failed", query.key_expr, exc_info=True)
    finally:
        query.drop()
