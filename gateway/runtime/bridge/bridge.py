""":class:`Bridge`: the daemon's Zenoh edge (see :mod:`gateway.runtime.bridge`).

Three kinds of threads meet here, and none waits for another:

* published twists (``cmd/twist``, a ROS ``cmd_vel``) run no Python at all as they arrive:
  their subscribers keep the newest sample in a ring of one inside Zenoh (newest wins, as on
  the socket; :class:`~gateway.runtime.bridge.inbox.TwistSource`);
* Zenoh's own threads run the other callbacks: a query or a commander's token coming or going
  is parsed there and appended to the inbox (a bounded deque; appends are atomic);
* the loop thread takes the newest twist of each source and parses it
  (:meth:`Bridge.take_twists`: one parse a cycle however many samples came), then drains the
  inbox between cycles
  (:meth:`Bridge.take`, within the time :mod:`gateway.runtime.remote` allows), hands each
  request to the same :class:`~gateway.runtime.requests.RequestHandler` logic as the socket's,
  and posts news and replies to the :class:`~gateway.runtime.mailbox.Mailbox` -- a lock held
  for a few stores;
* the bridge's worker thread takes from the mailbox and does every Zenoh ``put`` and query
  reply (50-70 us each of the calling thread): never the loop.

A flood cannot grow memory or the loop's work: published twists replace each other in their
rings; the inbox holds :data:`INBOX_MAX` items (a query beyond it is answered "busy" at once; a
commander's token event still gets in, into :data:`COMMANDER_RESERVE` more, and one beyond even
that is logged), and the loop takes at most what :mod:`gateway.runtime.remote` allows a cycle.
"""

from __future__ import annotations

import collections
import functools
import logging
import threading
import time
from typing import TYPE_CHECKING, Any, cast

from gateway.core.bridge_settings import ZenohMode
from gateway.core.events import OdometryEvent
from gateway.core.status import LastError
from gateway.core.types import ErrorCode
from gateway.runtime.bridge.inbox import NO_REPLY, CommanderEvent, Inbound, TwistSource
from gateway.runtime.bridge.native import (
    RPC_OPS,
    NativeKeys,
    commander_of,
    parse_query,
    parse_twist_sample,
)
from gateway.runtime.bridge.session import BridgeError, import_zenoh, open_session
from gateway.runtime.mailbox import Mailbox
from gateway.wire.socket import ProtocolError, reply_error
from gateway.wire.socket.events import event_line

if TYPE_CHECKING:
    from collections.abc import Iterable, Mapping

    from gateway.core.bridge_settings import BridgeSettings
    from gateway.runtime.bridge.ros2 import Ros2Side
    from gateway.runtime.mailbox import Delivery
    from gateway.wire.socket import Op, Request, Topic

log = logging.getLogger(__name__)

__all__ = ["COMMANDER_RESERVE", "INBOX_MAX", "Bridge"]

#: Items the inbox holds (queries beyond are answered "busy").
INBOX_MAX = 1024
#: Room beyond :data:`INBOX_MAX` kept for the commanders' token events.
COMMANDER_RESERVE = 256
#: Seconds the worker waits for news before looking again (it also wakes on news).
WORKER_WAKE_S = 0.5
#: A client whose router cannot be reached tries again after this long, doubling up to
#: :data:`CONNECT_MAX_S` (s).
CONNECT_FIRST_S = 1.0
CONNECT_MAX_S = 10.0
#: Zenoh's words for a router that cannot be reached (not a bad configuration).
_UNREACHABLE = "Unable to connect"


class Bridge:
    """The Zenoh side of the daemon (see the module's doc).

    :param settings: the ``bridge:`` block.
    :param hardware: each motor's hardware id by its name, for the ROS 2 diagnostics
        (:func:`~gateway.runtime.diagnostics.hardware_ids`).
    :raises BridgeError: when Zenoh is missing, the session cannot be opened or its keys
        cannot be declared.  A client whose router cannot be reached is no error: the robot
        may boot before the machine that runs the router, so the bridge keeps trying in a
        thread of its own (1 s, doubling up to 10 s between tries) while the gateway runs
        without it, and declares its keys once it is connected.
    """

    def __init__(self, settings: BridgeSettings, hardware: Mapping[str, str] | None = None
                 ) -> None:
        self.settings = settings
        self.hardware = dict(hardware or {})
        self.keys = NativeKeys.of(settings.namespace)
        #: News and replies from the loop for the worker.
        self.mailbox: Mailbox[tuple[int, bytes]] = Mailbox()
        self._inbox: collections.deque[Inbound | CommanderEvent] = collections.deque()
        self._lock = threading.Lock()
        self._queries: dict[int, Any] = {}
        self._next_client = NO_REPLY + 1
        #: Where published twists come in (the native key, and ROS's cmd_vel types).
        self._twists: list[TwistSource] = []
        #: Published twists the loop took that did not parse (each reported on the error key).
        self.bad_twists = 0
        #: Items the full inbox refused: queries (answered "busy") and token events (logged).
        self.dropped = 0
        self._closed = False
        self._stop = threading.Event()
        self._entities: list[Any] = []
        self._ros: Ros2Side | None = None
        self._worker: threading.Thread | None = None
        # Any: the zenoh stubs leave close() and undeclare() untyped.
        self.session: Any = None
        try:
            session = open_session(settings.zenoh)
        except BridgeError as err:
            if settings.zenoh.mode is not ZenohMode.CLIENT or _UNREACHABLE not in str(err):
                raise
            log.warning("%s; the gateway runs without its bridge meanwhile, and the bridge "
                        "tries again every %g s to %g s", err, CONNECT_FIRST_S, CONNECT_MAX_S)
            threading.Thread(target=self._connect, name="wheelgate-bridge-connect",
                             daemon=True).start()
            return
        self._start(session)

    def _start(self, session: Any) -> None:
        """Declare the keys on an open session and start the worker (the session is closed
        instead if the bridge was closed meanwhile).

        :raises BridgeError: when a key cannot be declared (the session is closed).
        """
        zenoh: Any = import_zenoh()
        try:
            self._declare(session)
        except zenoh.ZError as err:
            session.close()
            raise BridgeError(f"bridge: cannot declare the keys {self.keys.root}/...: "
                              f"{err}") from err
        except BaseException:
            session.close()
            raise
        with self._lock:
            if self._closed:
                session.close()
                return
            self.session = session
            self._worker = threading.Thread(target=self._work, name="wheelgate-bridge",
                                            daemon=True)
            self._worker.start()
        log.info("bridge: Zenoh session %s, keys %s/..., listening on %s", session.zid(),
                 self.keys.root, ", ".join(self.settings.zenoh.listen) or "nothing")

    def _connect(self) -> None:
        """A client's tries to reach its router, until one succeeds or the bridge closes."""
        delay, since = CONNECT_FIRST_S, time.monotonic()
        while not self._stop.wait(delay):
            try:
                session = open_session(self.settings.zenoh)
            except BridgeError as err:
                delay = min(2.0 * delay, CONNECT_MAX_S)
                # (an unreachable router was said at start; anything else is news)
                log.log(logging.DEBUG if _UNREACHABLE in str(err) else logging.WARNING,
                        "bridge: %s; trying again in %g s", err, delay)
                continue
            log.info("bridge: connected to the router after %.0f s",
                     time.monotonic() - since)
            try:
                self._start(session)
            except BridgeError as err:
                log.error("%s; the bridge stays off", err)
            return

    # ----------------------------------------------------------------- declarations

    def _declare(self, s: Any) -> None:
        keys = self.keys
        ring = cast("Any", import_zenoh()).handlers.RingChannel
        twists = [TwistSource(s.declare_subscriber(keys.twist, ring(1)), _native_twist)]
        self._entities.append(twists[0].subscriber)
        for op in RPC_OPS:
            self._entities.append(s.declare_queryable(
                keys.rpc(op), functools.partial(self._on_query, op)))
        self._entities.append(s.liveliness().declare_subscriber(
            keys.commanders, self._on_commander, history=True))
        self._odom = s.declare_publisher(keys.odom)
        self._status = s.declare_publisher(keys.status)
        self._error = s.declare_publisher(keys.error)
        self._entities += [self._odom, self._status, self._error]
        if self.settings.ros2 is not None:
            from gateway.runtime.bridge.ros2 import Ros2Side  # noqa: PLC0415 - with ros2: only

            self._ros = Ros2Side(
                s, self.settings.ros2, self.settings.ros_namespace,
                commander=lambda who, alive: self._admit(CommanderEvent(who, alive)),
                call=self._submit, hardware=self.hardware)
            twists += self._ros.twists
        self._token: Any = s.liveliness().declare_token(keys.gateway_token)
        self._twists = twists  # (one store: the loop may be reading the list)

    # ----------------------------------------------------------------- Zenoh's threads

    def _admit(self, item: Inbound | CommanderEvent) -> bool:
        # A commander's token event is never lost to a flood of twists: it may use the
        # reserve beyond the inbox's bound (tokens come and go far more slowly).
        bound = INBOX_MAX + COMMANDER_RESERVE if isinstance(item, CommanderEvent) else INBOX_MAX
        if len(self._inbox) >= bound:
            self.dropped += 1
            if isinstance(item, CommanderEvent):  # (a deadman's news: never lost silently)
                log.warning("bridge: inbox full: commander %s %s, not seen by the deadman",
                            item.commander, "came" if item.alive else "went")
            return False
        self._inbox.append(item)
        return True

    def _on_query(self, op: Op, query: Any) -> None:
        key = str(query.key_expr)
        payload = query.payload
        try:
            request: Request | ProtocolError = parse_query(
                op, None if payload is None else payload.to_bytes(), key)
        except ProtocolError as err:
            request = err
        self._submit(query, request)

    def _submit(self, query: Any, request: Request | ProtocolError) -> None:
        """Hand a query's request to the loop, its reply to come (:func:`_answer`); answer
        at once when the gateway is stopping or the inbox is full."""
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

    def take_twists(self) -> list[Inbound]:
        """The newest published twist of each source since the last call, parsed (one that
        does not parse is counted and reported on the error key instead)."""
        out = []
        for source in self._twists:
            try:
                got = source.take()
            except ProtocolError as err:
                self.bad_twists += 1
                self.mailbox.post(errors=(_bad(err),))
                continue
            if got is not None:
                out.append(got)
        return out

    def take(self) -> Inbound | CommanderEvent | None:
        """The oldest query or token event waiting (``None``: none)."""
        try:
            return self._inbox.popleft()
        except IndexError:
            return None

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
        if news.report is not None and self._ros is not None:
            self._ros.publish_report(news.report)
        for err in news.errors:
            self._error.put(event_line(err))
        if news.errors_dropped:
            lost = LastError(ErrorCode.BAD_COMMAND, f"{news.errors_dropped} errors were not "
                             f"published: more were waiting for the bridge than it keeps")
            self._error.put(event_line(lost))
            log.warning("bridge: %s", lost.message)

    # ----------------------------------------------------------------- closing

    def close(self) -> None:
        """Answer what is pending, withdraw the gateway's token and close the session (its
        token disappears for every peer at once)."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
        self._stop.set()  # (a client still trying to reach its router stops trying)
        self.mailbox.close()
        if self._worker is not None:
            self._worker.join(timeout=2.0)
        with self._lock:
            pending, self._queries = self._queries, {}
        for query in pending.values():
            _answer(query, reply_error(None, ErrorCode.BAD_COMMAND, "the gateway is stopping"))
        if self.session is None:  # never connected: nothing declared
            return
        try:
            if self._ros is not None:
                self._ros.close()
            self._token.undeclare()
            self.session.close()
        except Exception:  # closing is best effort: the process ends next
            log.exception("bridge: closing the Zenoh session failed")


def _native_twist(payload: bytes, attachment: bytes | None, key: str) -> Inbound:
    """A twist published on ``cmd/twist``, with the commander its attachment names.

    :raises ProtocolError: for a bad payload or commander name.
    """
    commander = commander_of(attachment, key)
    request: Request = parse_twist_sample(payload, key)
    return Inbound(NO_REPLY, request, commander)


def _bad(err: ProtocolError) -> LastError:
    return LastError(ErrorCode.BAD_COMMAND, str(err))


def _answer(query: Any, line: bytes) -> None:
    """Reply to a query and finalize it (the querier waits until every reply is sent); a
    ROS service call (:class:`~gateway.runtime.bridge.ros2.RosCall`) answers in its type."""
    payload, attachment = line, None
    response = getattr(query, "response", None)
    if response is not None:  # (a RosCall: its query, and its response to the line)
        query = query.query
    try:
        if response is not None:
            payload, attachment = response(line)
        query.reply(query.key_expr, payload, attachment=attachment)
    except Exception:  # the querier may be gone
        log.debug("bridge: reply to %s failed", query.key_expr, exc_info=True)
    finally:
        query.drop()
