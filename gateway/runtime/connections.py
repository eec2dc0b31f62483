"""The control socket's connected clients: their lines in, within the budgets, and the timeouts.

:class:`Connections` is the half of :class:`gateway.runtime.server.ControlServer` that deals with a
client once it is admitted: it takes the client's lines one at a time and parses them, and
disconnects clients that hang up, fail or stall.  Its base :class:`~gateway.runtime.clients.
ClientTable` keeps the clients, sends replies and events without blocking (queuing what the
kernel does not take), keeps the subscriptions, and disconnects clients that stop reading.
Listening, accepting, the selector loop and the budgets' sizes are the server's; access control
is :mod:`gateway.runtime.access`.

What one client can cost the daemon is bounded:

* **input**: lines are taken round robin, one per client per turn, while the poll's
  :class:`Budget` lasts (requests, bytes received, and the costly ops' allowances); a client
  with more waits -- unread, in the kernel's buffer -- for a later poll, first in line.  At most
  :attr:`Connections.RECV_BYTES` are received at a time, and only once every line received
  before has been taken, so a client's framer holds at most that plus one unfinished line;
* **output**: see :mod:`gateway.runtime.clients`;
* **time**: a client that stays in the middle of a line for ``partial_timeout_s`` (however
  fast it sends it: an endless line is cut off too), or sends no line for ``idle_timeout_s``
  (subscribers excepted: they are dropped if they stop reading), is disconnected by
  :meth:`Connections._expire`.
"""

from __future__ import annotations

import itertools
import logging
import selectors
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, TypeAlias

from gateway.core.status import ServerCounters
from gateway.runtime.clients import ClientTable, Connection
from gateway.wire.socket import Op, ProtocolError, Request, parse_request

if TYPE_CHECKING:
    import socket
    from collections import deque

__all__ = ["Budget", "Connection", "Connections", "Events", "ServerCounters"]

log = logging.getLogger(__name__)

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


class Connections(ClientTable):
    """The connected clients of one server: their input (see :class:`ClientTable` for the rest).

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

    def __init__(
        self,
        selector: selectors.DefaultSelector,
        max_message_bytes: int,
        max_pending_bytes_per_client: int,
        idle_timeout_s: float | None = None,
        partial_timeout_s: float | None = None,
    ) -> None:
        super().__init__(selector, max_pending_bytes_per_client)
        self.max_message_bytes = max_message_bytes
        self.idle_timeout_s = idle_timeout_s
        self.partial_timeout_s = partial_timeout_s
        self._ids = itertools.count(1)

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

    def _expire(self, now_s: float) -> None:
        """Close the clients that stalled in the middle of a line or stayed idle too long.

        The partial timeout holds for every client whose unfinished line (held, or skipped as
        too long) has not ended for ``partial_timeout_s`` -- one that sends an endless line
        faster than its share of the budget included, though its input always waits for a
        later poll -- except while the server owes it a turn: a line of it already complete
        (or a request held back for its op's allowance) waits to be taken, or its queued
        output keeps it from being read.  The idle timeout holds for no client whose input
        waits for a later poll (the server keeps it waiting)."""
        partial_s, idle_s = self.partial_timeout_s, self.idle_timeout_s
        limit = self.max_pending_bytes_per_client
        stalled = idle = 0
        for client in list(self._clients.values()):
            if (partial_s is not None and client.partial_since is not None
                    and now_s - client.partial_since > partial_s
                    and not client.framer.ready and client.held is None
                    and len(client.outbuf) * 2 < limit):
                self._drop(client, f"in the middle of a line for more than {partial_s:g} s")
                stalled += 1
            elif (idle_s is not None and not client.deferred
                  and now_s - client.last_active > idle_s
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



def _allowed(op: Op, budget: Budget) -> bool:
    """Whether a request of ``op`` may be given out now (taking its allowance if so)."""
    ops = budget.ops
    if ops is None or op not in ops:
        return True
    if ops[op] < 1.0:
        return False
    ops[op] -= 1.0
    return True
