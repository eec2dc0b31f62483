"""The control socket's connected clients: their lines in, their replies and events out.

:class:`Connections` is the half of :class:`gateway.server.ControlServer` that deals with a
client once it is admitted: it splits what the client sends into lines and parses them, sends
replies and events without blocking (queuing what the kernel does not take), keeps the
subscriptions, and disconnects clients that hang up, fail or stop reading.  Listening,
accepting and the selector loop are the server's; access control is :mod:`gateway.access`.
"""

from __future__ import annotations

import itertools
import logging
import selectors
import socket
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, TypeAlias

from gateway.protocol import LineFramer, ProtocolError, Request, Topic, parse_request

if TYPE_CHECKING:
    from collections.abc import Iterable

log = logging.getLogger(__name__)

_SEND_FLAGS = getattr(socket, "MSG_NOSIGNAL", 0)

#: What :meth:`gateway.server.ControlServer.poll` returns.
Events: TypeAlias = list[tuple[int, Request | ProtocolError]]


class Connection:
    """One client: its socket, its unfinished line, and the output queued for it."""

    __slots__ = ("cid", "framer", "interest", "outbuf", "read_closed", "sock")

    def __init__(self, cid: int, sock: socket.socket, max_message_bytes: int) -> None:
        self.cid = cid
        self.sock = sock
        self.framer = LineFramer(max_message_bytes)
        self.outbuf = bytearray()
        self.read_closed = False  # the peer shut down its writing side
        self.interest = selectors.EVENT_READ


@dataclass(frozen=True, slots=True)
class ServerCounters:
    """A snapshot of the server's counters (all since start except ``clients``).

    :param clients: clients connected now.
    :param accepted: connections admitted as clients.
    :param refused: connections closed at once: uid not allowed, or ``max_clients`` reached.
    :param too_long: lines longer than ``max_message_bytes``.
    :param malformed: lines that failed to parse (not counting ``too_long``).
    :param dropped_partial: clients that disconnected in the middle of a line.
    :param slow_disconnects: clients disconnected for not reading their output.
    """

    clients: int = 0
    accepted: int = 0
    refused: int = 0
    too_long: int = 0
    malformed: int = 0
    dropped_partial: int = 0
    slow_disconnects: int = 0


class Connections:
    """The connected clients of one server, registered on its selector.

    :param selector: the server's selector; clients are registered with their id as data.
    :param max_message_bytes: longest accepted line, newline excluded.
    :param max_pending_bytes_per_client: output queued for one client beyond which it is
        disconnected as too slow.
    """

    #: Bytes read from one client per select round.
    RECV_BYTES = 65536

    def __init__(
        self,
        selector: selectors.DefaultSelector,
        max_message_bytes: int,
        max_pending_bytes_per_client: int,
    ) -> None:
        self.max_message_bytes = max_message_bytes
        self.max_pending_bytes_per_client = max_pending_bytes_per_client
        self._selector = selector
        self._clients: dict[int, Connection] = {}
        self._subscribers: dict[Topic, set[int]] = {topic: set() for topic in Topic}
        self._ids = itertools.count(1)
        self._half_closed: set[int] = set()
        #: The counters since start (``clients`` is filled in by the snapshot).
        self._counts = ServerCounters()
        #: Set while connections are refused for ``max_clients`` (logged once per episode).
        self._full = False

    def reply(self, client_id: int, data: bytes) -> bool:
        """Send ``data`` to a client without blocking; what the kernel does not take is queued
        and flushed by :meth:`~gateway.server.ControlServer.poll`.

        :return: ``False`` if the client is gone, or was just disconnected as too slow.
        """
        client = self._clients.get(client_id)
        if client is None:
            return False
        if not client.outbuf:
            sent = self._send(client, data)
            if sent < 0:
                return False
            if sent == len(data):
                return True
            client.outbuf += memoryview(data)[sent:]
            self._update_interest(client)
        else:
            client.outbuf += data
        if len(client.outbuf) > self.max_pending_bytes_per_client:
            self._counts = replace(self._counts, slow_disconnects=self._counts.slow_disconnects + 1)
            log.warning(
                "control client %d: %d bytes of output pending, more than %d; disconnecting",
                client_id, len(client.outbuf), self.max_pending_bytes_per_client,
            )
            self._drop(client, "too slow")
            return False
        return True

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
        """Send an event line to every subscriber of ``topic`` (see :meth:`reply`).

        :return: to how many clients it was sent or queued.
        """
        return sum(self.reply(cid, data) for cid in tuple(self._subscribers[topic]))

    @property
    def client_ids(self) -> frozenset[int]:
        """The ids of the connected clients."""
        return frozenset(self._clients)

    # -- internals ----------------------------------------------------------------------------

    def _add(self, conn: socket.socket) -> None:
        """Register an admitted, non-blocking connection as a new client."""
        client = Connection(next(self._ids), conn, self.max_message_bytes)
        self._clients[client.cid] = client
        self._selector.register(conn, selectors.EVENT_READ, client.cid)
        self._counts = replace(self._counts, accepted=self._counts.accepted + 1)
        log.debug("control client %d connected", client.cid)

    def _read(self, client: Connection, events: Events) -> None:
        try:
            data = client.sock.recv(self.RECV_BYTES)
        except (BlockingIOError, InterruptedError):
            return
        except OSError as err:
            log.debug("control client %d: receive failed: %s", client.cid, err)
            self._count_partial(client)
            self._drop(client, str(err))
            return
        if data:
            for line in client.framer.feed(data):
                self._line(client.cid, line, events)
            return
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

    def _line(self, cid: int, line: bytes | ProtocolError, events: Events) -> None:
        if isinstance(line, ProtocolError):
            self._counts = replace(self._counts, too_long=self._counts.too_long + 1)
            events.append((cid, line))
        elif line.strip():  # blank lines are ignored
            try:
                events.append((cid, parse_request(line, self.max_message_bytes)))
            except ProtocolError as err:
                self._counts = replace(self._counts, malformed=self._counts.malformed + 1)
                events.append((cid, err))

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
        del client.outbuf[:sent]
        if not client.outbuf:
            if client.read_closed:
                self._drop(client, "closed its end")
            else:
                self._update_interest(client)

    def _update_interest(self, client: Connection) -> None:
        interest = (0 if client.read_closed else selectors.EVENT_READ) | (
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
        if client.interest:
            self._selector.unregister(client.sock)
        client.sock.close()
        self._full = False
        log.debug("control client %d closed: %s", client.cid, reason)
