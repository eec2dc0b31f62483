"""The control socket's connected clients: their lines in, their replies and events out.

:class:`Connections` is the half of :class:`gateway.runtime.server.ControlServer` that deals with a
client once it is admitted: it takes the client's lines one at a time and parses them, sends
replies and events without blocking (queuing what the kernel does not take), keeps the
subscriptions, and disconnects clients that hang up, fail, stop reading or stall.  Listening,
accepting, the selector loop and the budgets' sizes are the server's; access control is
:mod:`gateway.runtime.access`.

What one client can cost the daemon is bounded:

* **input**: lines are taken round robin, one per client per turn, while the poll's
  :class:`Budget` lasts (requests, bytes received, and the costly ops' allowances); a client
  with more waits -- unread, in the kernel's buffer -- for a later poll, first in line.  At most
  :attr:`Connections.RECV_BYTES` are received at a time, and only once every line received
  before has been taken, so a client's framer holds at most that plus one unfinished line;
* **output**: a client's requests are not read while half of
  :attr:`~Connections.max_pending_bytes_per_client` is queued for it, so a client that
  pipelines requests and reads its replies slowly is slowed down, not dropped, and its queued
  replies stay bounded; an event that would take a subscriber's queue beyond that limit (or
  all clients' beyond :attr:`~Connections.MAX_PENDING_BYTES_TOTAL`) disconnects it as too
  slow instead;
* **time**: a client that stays in the middle of a line for ``partial_timeout_s``, or sends
  no line for ``idle_timeout_s`` (subscribers excepted: they are dropped if they stop reading),
  is disconnected by :meth:`Connections._expire`.
"""

from __future__ import annotations

import itertools
import logging
import selectors
import socket
import time
from collections import OrderedDict
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, TypeAlias

from gateway.wire.socket import LineFramer, Op, ProtocolError, Request, Topic, parse_request

if TYPE_CHECKING:
    from collections import deque
    from collections.abc import Iterable

log = logging.getLogger(__name__)

_SEND_FLAGS = getattr(socket, "MSG_NOSIGNAL", 0)

#: What :meth:`gateway.runtime.server.ControlServer.poll` returns.
Events: TypeAlias = list[tuple[int, Request | ProtocolError]]

# How a client's turn ended (see Connections._take).
_MORE = 0  # took a line; there may be more
_DONE = 1  # nothing more to take now (the kernel's buffer is empty, or the client is gone)
_WAIT = 2  # input left, but the budget's bytes are spent: wait for the next poll
_HELD = 3  # its next request's op has no allowance left: wait for the next cycle
_FULL = 4  # too much output queued for it: not read until its output drains


@dataclass(slots=True)
class Budget:
    """What a poll may still take from the clients.

    :param requests: lines (blank and bad ones included).
    :param bytes: bytes received.
    :param ops: the costly ops' allowances (a request of such an op takes one; fractions carry
        over between cycles); ``None``: no op is limited beyond ``requests``.
    """

    requests: int
    bytes: int
    ops: dict[Op, float] | None = None


class Connection:
    """One client: its socket, its unfinished input, the output queued for it, and its state."""

    __slots__ = ("cid", "deferred", "drained", "framer", "held", "interest", "last_active",
                 "outbuf", "partial_since", "read_closed", "sock")

    def __init__(self, cid: int, sock: socket.socket, max_message_bytes: int,
                 now_s: float) -> None:
        self.cid = cid
        self.sock = sock
        self.framer = LineFramer(max_message_bytes)
        self.outbuf = bytearray()
        self.read_closed = False  # the peer shut down its writing side
        self.interest = selectors.EVENT_READ
        #: Waiting for a later poll (input left over, or a held request): not read meanwhile.
        self.deferred = False
        #: The last receive took less than asked: the kernel's buffer is likely empty.
        self.drained = False
        #: A request whose op had no allowance left when it was parsed, given out first.
        self.held: Request | None = None
        #: When the client was admitted, last sent a line or last took an event at once,
        #: monotonic s.
        self.last_active = now_s
        #: When the unfinished line it is in the middle of began, monotonic s; ``None``: none.
        self.partial_since: float | None = None


@dataclass(frozen=True, slots=True)
class ServerCounters:
    """A snapshot of the server's counters (all since start except ``clients``).

    :param clients: clients connected now.
    :param accepted: connections admitted as clients.
    :param refused: connections closed without being served: uid not allowed, or displaced by
        a newer connection while ``max_clients`` were connected before any of their lines was
        taken.
    :param evicted: clients closed for a newer connection while ``max_clients`` were connected,
        after they had been served (the one idle longest each time).
    :param too_long: lines longer than ``max_message_bytes``.
    :param malformed: lines that failed to parse (not counting ``too_long``).
    :param dropped_partial: clients that disconnected in the middle of a line.
    :param slow_disconnects: subscribers disconnected for not reading their events.
    :param idle_timeouts: clients closed after ``idle_timeout_s`` without a line.
    :param partial_timeouts: clients closed after ``partial_timeout_s`` in the middle of a line.
    :param deferred: times a client's input was left for a later poll because the budget of
        the poll or of the cycle was spent.
    """

    clients: int = 0
    accepted: int = 0
    refused: int = 0
    evicted: int = 0
    too_long: int = 0
    malformed: int = 0
    dropped_partial: int = 0
    slow_disconnects: int = 0
    idle_timeouts: int = 0
    partial_timeouts: int = 0
    deferred: int = 0


class Connections:
    """The connected clients of one server, registered on its selector.

    :param selector: the server's selector; clients are registered with their id as data.
    :param max_message_bytes: longest accepted line, newline excluded.
    :param max_pending_bytes_per_client: output queued for one client beyond which an event
        disconnects it as too slow; its requests are not read while half of it is queued.
    :param idle_timeout_s: a client that sends no line for this long is closed (subscribers
        excepted); ``None``: never.
    :param partial_timeout_s: a client that stays in the middle of a line for this long is
        closed; ``None``: never.
    """

    #: Bytes received from one client at a time (only once its earlier lines are all taken).
    RECV_BYTES = 4096
    #: Output queued for all clients together beyond which a client that needs more is
    #: disconnected as too slow.
    MAX_PENDING_BYTES_TOTAL = 16 << 20

    def __init__(
        self,
        selector: selectors.DefaultSelector,
        max_message_bytes: int,
        max_pending_bytes_per_client: int,
        idle_timeout_s: float | None = None,
        partial_timeout_s: float | None = None,
    ) -> None:
        self.max_message_bytes = max_message_bytes
        self.max_pending_bytes_per_client = max_pending_bytes_per_client
        self.idle_timeout_s = idle_timeout_s
        self.partial_timeout_s = partial_timeout_s
        self._selector = selector
        self._clients: dict[int, Connection] = {}
        #: Clients no line of which has been taken yet, in order of admission.
        self._silent: dict[int, None] = {}
        #: Clients that have sent a line, the least recently active first (a line taken, or
        #: an event taken at once).
        self._recent: OrderedDict[int, None] = OrderedDict()
        #: Clients with input waiting for a later poll, in the order they are to be served.
        self._deferred: dict[int, None] = {}
        self._subscribers: dict[Topic, set[int]] = {topic: set() for topic in Topic}
        self._ids = itertools.count(1)
        self._half_closed: set[int] = set()
        self._pending_total = 0
        #: The counters since start (``clients`` is filled in by the snapshot).
        self._counts = ServerCounters()
        #: Set while slow clients are being disconnected (logged once per episode).
        self._slow_episode = 0
        self._slow_since_check = False

    def reply(self, client_id: int, data: bytes) -> bool:
        """Send a reply to a client without blocking; what the kernel does not take is queued
        and flushed by :meth:`~gateway.runtime.server.ControlServer.poll`.  A reply is always
        queued:
        a client's requests are not read while half of ``max_pending_bytes_per_client`` is
        queued for it, which bounds its replies.

        :return: ``False`` if the client is gone.
        """
        client = self._clients.get(client_id)
        return client is not None and self._output(client, data, capped=False)

    def subscribe(self, client_id: int, topics: Iterable[Topic]) -> bool:
        """Add topics to a client's subscriptions.  :return: ``False`` if the client is gone."""
        client = self._clients.get(client_id)
        if client is None or client.read_closed:
            return False
        for topic in topics:
            self._subscribers[topic].add(client_id)
        return True

    def unsubscribe(self, client_id: int) -> bool:
        """Drop all of a client's subscriptions.  :return: ``False`` if the client is gone."""
        for ids in self._subscribers.values():
            ids.discard(client_id)
        return client_id in self._clients

    def has_subscribers(self, topic: Topic) -> bool:
        """Whether anyone listens to ``topic`` (to skip building unwanted events)."""
        return bool(self._subscribers[topic])

    def publish(self, topic: Topic, data: bytes) -> int:
        """Send an event line to every subscriber of ``topic`` without blocking, as
        :meth:`reply` does -- except that a subscriber for which it would take the output
        queued beyond ``max_pending_bytes_per_client`` (or all clients' beyond
        :attr:`MAX_PENDING_BYTES_TOTAL`) is disconnected as too slow instead.  A subscriber
        that takes it at once counts as active: it is evicted after the less active clients.

        :return: to how many clients it was sent or queued.
        """
        count = 0
        now = time.monotonic()
        for cid in tuple(self._subscribers[topic]):
            client = self._clients.get(cid)
            if client is not None and self._output(client, data, capped=True):
                count += 1
                if not client.outbuf:
                    self._touch(client, now, took_line=False)
        return count

    @property
    def client_ids(self) -> frozenset[int]:
        """The ids of the connected clients."""
        return frozenset(self._clients)

    # -- internals: input ---------------------------------------------------------------------

    def _add(self, conn: socket.socket, now_s: float) -> None:
        """Register an admitted, non-blocking connection as a new client."""
        client = Connection(next(self._ids), conn, self.max_message_bytes, now_s)
        self._clients[client.cid] = client
        self._silent[client.cid] = None
        self._selector.register(conn, selectors.EVENT_READ, client.cid)
        self._counts = replace(self._counts, accepted=self._counts.accepted + 1)
        log.debug("control client %d connected", client.cid)

    def _serve(self, ready: deque[Connection], budget: Budget, events: Events,
               now_s: float) -> None:
        """Take lines from the ``ready`` clients round robin, one per client per turn, while
        ``budget`` lasts; a client with input left waits for a later poll (not read meanwhile)."""
        while ready and budget.requests > 0:
            client = ready.popleft()
            if client.cid not in self._clients:
                continue
            turn = self._take(client, budget, events, now_s)
            if turn == _MORE:
                ready.append(client)
            elif turn == _WAIT:
                self._defer(client, counted=True)
            elif turn == _HELD:
                self._defer(client, counted=False)
            elif client.cid in self._clients:  # _DONE, _FULL
                self._undefer(client)
        for client in ready:
            if client.cid in self._clients:
                self._defer(client, counted=True)
        ready.clear()

    def _take(self, client: Connection, budget: Budget, events: Events, now_s: float) -> int:
        """One turn of a client: take its next line, receiving first if none is buffered."""
        if len(client.outbuf) * 2 >= self.max_pending_bytes_per_client:
            return _FULL  # read again once its output drains (see _flush)
        held = client.held
        if held is not None:
            if not _allowed(held.op, budget):
                return _HELD
            client.held = None
            events.append((client.cid, held))
            return _MORE
        framer = client.framer
        item = framer.pop()
        if item is None:
            if client.drained:
                client.drained = False
                return _DONE
            if budget.bytes <= 0:
                return _WAIT
            want = min(self.RECV_BYTES, budget.bytes)
            try:
                data = client.sock.recv(want)
            except (BlockingIOError, InterruptedError):
                return _DONE
            except OSError as err:
                log.debug("control client %d: receive failed: %s", client.cid, err)
                self._count_partial(client)
                self._drop(client, str(err))
                return _DONE
            if not data:
                self._hang_up(client)
                return _DONE
            budget.bytes -= len(data)
            client.drained = len(data) < want
            framer.push(data)
            if not framer.in_line:
                client.partial_since = None
            elif client.partial_since is None or framer.ready:
                client.partial_since = now_s  # a new unfinished line began
            item = framer.pop()
            if item is None:
                return _DONE if client.drained else _MORE
        budget.requests -= 1
        self._touch(client, now_s, took_line=True)
        if isinstance(item, ProtocolError):
            self._counts = replace(self._counts, too_long=self._counts.too_long + 1)
            events.append((client.cid, item))
        elif item.strip():  # blank lines are ignored
            try:
                request = parse_request(item, self.max_message_bytes)
            except ProtocolError as err:
                self._counts = replace(self._counts, malformed=self._counts.malformed + 1)
                events.append((client.cid, err))
            else:
                if not _allowed(request.op, budget):
                    client.held = request
                    self._counts = replace(self._counts, deferred=self._counts.deferred + 1)
                    return _HELD
                events.append((client.cid, request))
        return _MORE

    def _hang_up(self, client: Connection) -> None:
        """The client shut down its writing side: keep it until its output is flushed."""
        self._count_partial(client)
        client.read_closed = True
        self._half_closed.add(client.cid)
        self.unsubscribe(client.cid)
        if client.outbuf:
            self._update_interest(client)
        else:
            self._drop(client, "disconnected")

    def _count_partial(self, client: Connection) -> None:
        if client.framer.pending:
            self._counts = replace(self._counts, dropped_partial=self._counts.dropped_partial + 1)
            log.debug("control client %d: dropped %d bytes of an unfinished line",
                      client.cid, client.framer.pending)

    def _touch(self, client: Connection, now_s: float, took_line: bool) -> None:
        """Note the client as active now (the last to be evicted)."""
        client.last_active = now_s
        if took_line and client.cid in self._silent:
            del self._silent[client.cid]
            self._recent[client.cid] = None
        elif client.cid in self._recent:
            self._recent.move_to_end(client.cid)

    def _defer(self, client: Connection, counted: bool) -> None:
        """Leave the client's input for a later poll; it is not read meanwhile."""
        self._deferred[client.cid] = None
        if counted:
            self._counts = replace(self._counts, deferred=self._counts.deferred + 1)
        if not client.deferred:
            client.deferred = True
            self._update_interest(client)

    def _undefer(self, client: Connection) -> None:
        self._deferred.pop(client.cid, None)
        if client.deferred:
            client.deferred = False
            self._update_interest(client)

    def _expire(self, now_s: float) -> None:
        """Close the clients that stalled in the middle of a line or stayed idle too long.

        A client is held to neither while its input waits for a later poll (the server keeps it
        waiting), nor to the first while it is not read for its queued output."""
        partial_s, idle_s = self.partial_timeout_s, self.idle_timeout_s
        limit = self.max_pending_bytes_per_client
        stalled = idle = 0
        for client in list(self._clients.values()):
            if client.deferred:
                continue
            if (partial_s is not None and client.partial_since is not None
                    and now_s - client.partial_since > partial_s
                    and len(client.outbuf) * 2 < limit):
                self._drop(client, f"in the middle of a line for more than {partial_s:g} s")
                stalled += 1
            elif (idle_s is not None and now_s - client.last_active > idle_s
                  and not any(client.cid in ids for ids in self._subscribers.values())):
                self._drop(client, f"no line for more than {idle_s:g} s")
                idle += 1
        if stalled or idle:
            c = self._counts
            self._counts = replace(c, partial_timeouts=c.partial_timeouts + stalled,
                                   idle_timeouts=c.idle_timeouts + idle)
            log.info("control socket: closed %d client(s) in the middle of a line for more "
                     "than %s s and %d idle for more than %s s", stalled, partial_s, idle, idle_s)
        if self._slow_episode and not self._slow_since_check:
            log.info("control socket: %d slow client(s) disconnected in all, none since",
                     self._slow_episode)
            self._slow_episode = 0
        self._slow_since_check = False

    # -- internals: output --------------------------------------------------------------------

    def _output(self, client: Connection, data: bytes, capped: bool) -> bool:
        """Send or queue ``data``; ``capped``: disconnect the client rather than queue beyond
        the limits.  :return: ``False`` if the client is gone (or was just disconnected)."""
        rest: bytes | memoryview = data
        if not client.outbuf:
            sent = self._send(client, data)
            if sent < 0:
                return False
            if sent == len(data):
                return True
            rest = memoryview(data)[sent:]
        queued = len(client.outbuf) + len(rest)
        if capped and (queued > self.max_pending_bytes_per_client
                       or self._pending_total + len(rest) > self.MAX_PENDING_BYTES_TOTAL):
            self._too_slow(client, queued)
            return False
        client.outbuf += rest
        self._pending_total += len(rest)
        self._update_interest(client)
        return True

    def _too_slow(self, client: Connection, queued: int) -> None:
        self._counts = replace(self._counts, slow_disconnects=self._counts.slow_disconnects + 1)
        self._slow_since_check = True
        self._slow_episode += 1
        level = logging.WARNING if self._slow_episode == 1 else logging.DEBUG
        if queued > self.max_pending_bytes_per_client:
            why = f"{queued} bytes of output pending, more than {self.max_pending_bytes_per_client}"
        else:
            why = (f"{self._pending_total} bytes of output pending for all clients, no room for "
                   f"more (at most {self.MAX_PENDING_BYTES_TOTAL})")
        log.log(level, "control client %d: %s; disconnecting it as too slow%s", client.cid, why,
                " (more such clients are counted, not logged, until none for a while)"
                if self._slow_episode == 1 else "")
        self._drop(client, "too slow")

    def _send(self, client: Connection, data: bytes | bytearray) -> int:
        """Bytes the kernel took, or -1 if the client is gone (and was dropped)."""
        try:
            return client.sock.send(data, _SEND_FLAGS)
        except (BlockingIOError, InterruptedError):
            return 0
        except OSError as err:
            self._drop(client, f"send failed: {err}")
            return -1

    def _flush(self, client: Connection) -> None:
        sent = self._send(client, client.outbuf)
        if sent <= 0:
            return
        full = len(client.outbuf) * 2 >= self.max_pending_bytes_per_client
        del client.outbuf[:sent]
        self._pending_total -= sent
        if not client.outbuf and client.read_closed:
            self._drop(client, "closed its end")
            return
        if full and len(client.outbuf) * 2 < self.max_pending_bytes_per_client:
            self._defer(client, counted=False)  # lines may wait in its framer: served next poll
        self._update_interest(client)

    def _update_interest(self, client: Connection) -> None:
        reading = not (client.read_closed or client.deferred
                       or len(client.outbuf) * 2 >= self.max_pending_bytes_per_client)
        interest = (selectors.EVENT_READ if reading else 0) | (
            selectors.EVENT_WRITE if client.outbuf else 0
        )
        if interest == client.interest:
            return
        if not interest:
            self._selector.unregister(client.sock)
        elif not client.interest:
            self._selector.register(client.sock, interest, client.cid)
        else:
            self._selector.modify(client.sock, interest, client.cid)
        client.interest = interest

    def _drop(self, client: Connection, reason: str) -> None:
        if self._clients.pop(client.cid, None) is None:
            return
        self.unsubscribe(client.cid)
        self._half_closed.discard(client.cid)
        self._silent.pop(client.cid, None)
        self._recent.pop(client.cid, None)
        self._deferred.pop(client.cid, None)
        self._pending_total -= len(client.outbuf)
        client.outbuf.clear()
        if client.interest:
            self._selector.unregister(client.sock)
        client.sock.close()
        log.debug("control client %d closed: %s", client.cid, reason)


def _allowed(op: Op, budget: Budget) -> bool:
    """Whether a request of ``op`` may be given out now (taking its allowance if so)."""
    ops = budget.ops
    if ops is None or op not in ops:
        return True
    if ops[op] < 1.0:
        return False
    ops[op] -= 1.0
    return True
