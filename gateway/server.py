"""The local control socket: a non-blocking, selector-based Unix stream server of JSON lines.

A thin edge around :mod:`gateway.protocol`.  The control loop owns it and is its only user
(it is not thread-safe); :meth:`ControlServer.poll` doubles as the loop's inter-cycle sleep, so
a twist that arrives mid-sleep is handled at once.  Nothing a client does makes it raise or
block: bad lines become :class:`~gateway.protocol.ProtocolError` events, and clients that stop
reading are disconnected once :attr:`max_pending_bytes_per_client` of output is queued.

Access control -- the socket file's mode and the peers' credentials -- is described in
:mod:`gateway.access`.

More than ``max_clients`` connections: a new connection is accepted and closed at once (the
client sees end-of-file rather than a connect that hangs in the backlog), and counted in
``refused``.

A client that shuts down its writing side after its requests (``socat``, ``nc -q``) is kept
until the replies queued for it are sent, then closed at the start of the next poll.
"""

from __future__ import annotations

import errno
import itertools
import logging
import selectors
import socket
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, TypeAlias

from gateway.access import (
    ControlSocketError,
    admitted_uids,
    check_socket_path,
    listen,
    peer_credentials,
    remove_own_socket,
    remove_stale_socket,
)
from gateway.errors import ConfigError
from gateway.lifecycle import Closing
from gateway.protocol import (
    MAX_MESSAGE_BYTES,
    LineFramer,
    ProtocolError,
    Request,
    Topic,
    parse_request,
)

if TYPE_CHECKING:
    from collections.abc import Iterable

log = logging.getLogger(__name__)

_SEND_FLAGS = getattr(socket, "MSG_NOSIGNAL", 0)
_RESOURCE_ERRNOS = frozenset({errno.EMFILE, errno.ENFILE, errno.ENOBUFS, errno.ENOMEM})


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


class _Client:
    __slots__ = ("cid", "framer", "interest", "outbuf", "read_closed", "sock")

    def __init__(self, cid: int, sock: socket.socket, max_message_bytes: int) -> None:
        self.cid = cid
        self.sock = sock
        self.framer = LineFramer(max_message_bytes)
        self.outbuf = bytearray()
        self.read_closed = False  # the peer shut down its writing side
        self.interest = selectors.EVENT_READ


@dataclass(slots=True)
class _Tally:
    accepted: int = 0
    refused: int = 0
    too_long: int = 0
    malformed: int = 0
    dropped_partial: int = 0
    slow_disconnects: int = 0


#: What :meth:`ControlServer.poll` returns.
Events: TypeAlias = list[tuple[int, Request | ProtocolError]]


class ControlServer(Closing):
    """The control socket server.

    :param path: the socket file (at most 107 bytes encoded).
    :param mode: file mode of the socket (default ``0o660``).
    :param max_message_bytes: longest accepted line, newline excluded.
    :param max_clients: most clients at once; more are accepted and closed at once.
    :param allowed_uids: uids allowed to connect besides the server's own (Linux only);
        ``None`` leaves access control to the file mode.
    :param max_pending_bytes_per_client: output queued for one client beyond which it is
        disconnected as too slow.
    :raises SocketInUseError: if another process listens on ``path``, or it is not a socket.
    :raises ControlSocketError: if the socket cannot be created (path too long, directory
        missing or not writable).
    :raises ConfigError: for non-positive limits, or ``allowed_uids`` without ``SO_PEERCRED``.
    """

    #: Most connections accepted per select round, so a connection storm cannot stall a cycle.
    ACCEPT_BATCH = 128
    #: Bytes read from one client per select round.
    RECV_BYTES = 65536
    #: ``listen()`` backlog asked for (the kernel caps it at ``net.core.somaxconn``).
    BACKLOG = 4096

    def __init__(
        self,
        path: str | Path,
        mode: int = 0o660,
        max_message_bytes: int = MAX_MESSAGE_BYTES,
        max_clients: int = 1024,
        allowed_uids: frozenset[int] | None = None,
        max_pending_bytes_per_client: int = 1 << 20,
    ) -> None:
        self._closed = True
        for name, value in (
            ("max_message_bytes", max_message_bytes),
            ("max_clients", max_clients),
            ("max_pending_bytes_per_client", max_pending_bytes_per_client),
        ):
            if value < 1:
                raise ConfigError(f"control socket {name}: expected at least 1, got {value}")
        self._allowed = admitted_uids(allowed_uids)
        self.path = Path(path)
        self.max_message_bytes = max_message_bytes
        self.max_clients = max_clients
        self.max_pending_bytes_per_client = max_pending_bytes_per_client
        self.allowed_uids = None if allowed_uids is None else frozenset(allowed_uids)
        check_socket_path(self.path)
        remove_stale_socket(self.path)
        self._selector = selectors.DefaultSelector()
        try:
            self._listener, self._identity = listen(self.path, mode, self.BACKLOG)
        except BaseException:
            self._selector.close()
            raise
        self._selector.register(self._listener, selectors.EVENT_READ, None)
        self._accepting = True
        self._full = False
        self._clients: dict[int, _Client] = {}
        self._subscribers: dict[Topic, set[int]] = {topic: set() for topic in Topic}
        self._ids = itertools.count(1)
        self._half_closed: set[int] = set()
        self._tally = _Tally()
        self._closed = False
        log.info("control socket listening on %s (mode %o)", self.path, mode)

    # -- the loop's interface ---------------------------------------------------------------

    def poll(self, timeout_s: float) -> Events:
        """Wait up to ``timeout_s`` for requests; accept, read, split and parse.

        Returns as soon as one select round produced at least one event, else at the timeout.

        :param timeout_s: longest wait in seconds (0 for a non-blocking pass).
        :return: ``(client id, request or parse error)`` pairs in arrival order per client.
        :raises ControlSocketError: if the server is closed.
        """
        self._check_open()
        events: Events = []
        self._resume_accepting()
        for cid in list(self._half_closed):
            if not self._clients[cid].outbuf:
                self._drop(self._clients[cid], "closed its end")
        deadline = time.monotonic() + max(timeout_s, 0.0)
        while True:
            remaining = deadline - time.monotonic()
            for key, mask in self._selector.select(max(remaining, 0.0)):
                if key.data is None:
                    self._accept()
                    continue
                client = self._clients.get(key.data)
                if client is None:  # dropped earlier in this round
                    continue
                if mask & selectors.EVENT_WRITE:
                    self._flush(client)
                if mask & selectors.EVENT_READ and client.cid in self._clients:
                    self._read(client, events)
            if events or remaining <= 0:
                return events

    def reply(self, client_id: int, data: bytes) -> bool:
        """Send ``data`` to a client without blocking; what the kernel does not take is queued
        and flushed by :meth:`poll`.

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
            self._tally.slow_disconnects += 1
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

    def fileno(self) -> int:
        """The selector's descriptor: readable while a connection, a request or a writable
        client with queued output waits (for waits finer than epoll's milliseconds)."""
        self._check_open()
        return self._selector.fileno()

    @property
    def counters(self) -> ServerCounters:
        """A snapshot of the counters."""
        t = self._tally
        return ServerCounters(
            len(self._clients), t.accepted, t.refused, t.too_long, t.malformed,
            t.dropped_partial, t.slow_disconnects,
        )

    @property
    def client_ids(self) -> frozenset[int]:
        """The ids of the connected clients."""
        return frozenset(self._clients)

    def close(self) -> None:
        """Disconnect every client, stop listening and remove the socket file (if it is still
        the one this server created).  Safe to call twice."""
        if self._closed:
            return
        self._closed = True
        for client in list(self._clients.values()):
            self._drop(client, "server closing")
        self._selector.close()
        self._listener.close()
        remove_own_socket(self.path, self._identity)
        log.info("control socket %s closed", self.path)

    def __del__(self) -> None:
        if not getattr(self, "_closed", True):
            log.warning("control socket %s was not closed", getattr(self, "path", "?"))

    # -- internals ----------------------------------------------------------------------------

    def _check_open(self) -> None:
        if self._closed:
            raise ControlSocketError(f"control socket {self.path}: expected an open server, "
                                     "got a closed one")

    def _peer_uid(self, sock: socket.socket) -> int | None:
        """The uid of a new client (a hook, so tests can stand in for other users)."""
        creds = peer_credentials(sock)
        return None if creds is None else creds.uid

    def _resume_accepting(self) -> None:
        if not self._accepting:
            self._selector.register(self._listener, selectors.EVENT_READ, None)
            self._accepting = True

    def _accept(self) -> None:
        for _ in range(self.ACCEPT_BATCH):
            try:
                conn, _ = self._listener.accept()
            except (BlockingIOError, InterruptedError):
                return
            except OSError as err:
                if err.errno in _RESOURCE_ERRNOS:  # retried at the next poll, not in a spin
                    self._selector.unregister(self._listener)
                    self._accepting = False
                log.warning("control socket %s: accept failed: %s", self.path, err)
                return
            self._admit(conn)

    def _admit(self, conn: socket.socket) -> None:
        conn.setblocking(False)
        if len(self._clients) >= self.max_clients:
            if not self._full:
                log.warning("control socket %s: %d clients connected, refusing more",
                            self.path, len(self._clients))
                self._full = True
            self._tally.refused += 1
            conn.close()
            return
        if self._allowed is not None:
            uid = self._peer_uid(conn)
            if uid is None or uid not in self._allowed:
                log.warning("control socket %s: refused a client with uid %s (allowed: %s)",
                            self.path, uid, sorted(self._allowed))
                self._tally.refused += 1
                conn.close()
                return
        client = _Client(next(self._ids), conn, self.max_message_bytes)
        self._clients[client.cid] = client
        self._selector.register(conn, selectors.EVENT_READ, client.cid)
        self._tally.accepted += 1
        log.debug("control client %d connected", client.cid)

    def _read(self, client: _Client, events: Events) -> None:
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

    def _count_partial(self, client: _Client) -> None:
        if client.framer.pending:
            self._tally.dropped_partial += 1
            log.debug("control client %d: dropped %d bytes of an unfinished line",
                      client.cid, client.framer.pending)

    def _line(self, cid: int, line: bytes | ProtocolError, events: Events) -> None:
        if isinstance(line, ProtocolError):
            self._tally.too_long += 1
            events.append((cid, line))
        elif line.strip():  # blank lines are ignored
            try:
                events.append((cid, parse_request(line, self.max_message_bytes)))
            except ProtocolError as err:
                self._tally.malformed += 1
                events.append((cid, err))

    def _send(self, client: _Client, data: bytes | bytearray) -> int:
        """Bytes the kernel took, or -1 if the client is gone (and was dropped)."""
        try:
            return client.sock.send(data, _SEND_FLAGS)
        except (BlockingIOError, InterruptedError):
            return 0
        except OSError as err:
            self._drop(client, f"send failed: {err}")
            return -1

    def _flush(self, client: _Client) -> None:
        sent = self._send(client, client.outbuf)
        if sent <= 0:
            return
        del client.outbuf[:sent]
        if not client.outbuf:
            if client.read_closed:
                self._drop(client, "closed its end")
            else:
                self._update_interest(client)

    def _update_interest(self, client: _Client) -> None:
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

    def _drop(self, client: _Client, reason: str) -> None:
        if self._clients.pop(client.cid, None) is None:
            return
        self.unsubscribe(client.cid)
        self._half_closed.discard(client.cid)
        if client.interest:
            self._selector.unregister(client.sock)
        client.sock.close()
        self._full = False
        log.debug("control client %d closed: %s", client.cid, reason)

