"""The local control socket: a non-blocking, selector-based Unix stream server of JSON lines.

A thin edge around :mod:`gateway.protocol`.  The control loop owns it and is its only user
(it is not thread-safe); :meth:`ControlServer.poll` doubles as the loop's inter-cycle sleep, so
a twist that arrives mid-sleep is handled at once.  Nothing a client does makes it raise or
block: bad lines become :class:`~gateway.protocol.ProtocolError` events, and clients that stop
reading are disconnected once :attr:`max_pending_bytes_per_client` of output is queued.

Access control -- the socket file's mode and the peers' credentials -- is described in
:mod:`gateway.access`; the clients' side -- lines in, replies and events out, subscriptions --
is :class:`gateway.connections.Connections`, which the server extends.

More than ``max_clients`` connections: a new connection is accepted and closed at once (the
client sees end-of-file rather than a connect that hangs in the backlog), and counted in
``refused``.

A client that shuts down its writing side after its requests (``socat``, ``nc -q``) is kept
until the replies queued for it are sent, then closed at the start of the next poll.
"""

from __future__ import annotations

import dataclasses
import errno
import logging
import selectors
import time
from pathlib import Path
from typing import TYPE_CHECKING

from gateway.access import (
    ControlSocketError,
    admitted_uids,
    check_socket_path,
    listen,
    peer_credentials,
    remove_own_socket,
    remove_stale_socket,
)
from gateway.connections import Connections, Events, ServerCounters
from gateway.errors import ConfigError
from gateway.lifecycle import Closing
from gateway.protocol import MAX_MESSAGE_BYTES

if TYPE_CHECKING:
    import socket

__all__ = ["ControlServer", "Events", "ServerCounters"]

log = logging.getLogger(__name__)

_RESOURCE_ERRNOS = frozenset({errno.EMFILE, errno.ENFILE, errno.ENOBUFS, errno.ENOMEM})


class ControlServer(Connections, Closing):
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
        self.max_clients = max_clients
        self.allowed_uids = None if allowed_uids is None else frozenset(allowed_uids)
        check_socket_path(self.path)
        remove_stale_socket(self.path)
        selector = selectors.DefaultSelector()
        try:
            self._listener, self._identity = listen(self.path, mode, self.BACKLOG)
        except BaseException:
            selector.close()
            raise
        super().__init__(selector, max_message_bytes, max_pending_bytes_per_client)
        self._selector.register(self._listener, selectors.EVENT_READ, None)
        self._accepting = True
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

    def fileno(self) -> int:
        """The selector's descriptor: readable while a connection, a request or a writable
        client with queued output waits (for waits finer than epoll's milliseconds)."""
        self._check_open()
        return self._selector.fileno()

    @property
    def counters(self) -> ServerCounters:
        """A snapshot of the counters."""
        return dataclasses.replace(self._counts, clients=len(self._clients))

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
            self._counts = dataclasses.replace(self._counts, refused=self._counts.refused + 1)
            conn.close()
            return
        if self._allowed is not None:
            uid = self._peer_uid(conn)
            if uid is None or uid not in self._allowed:
                log.warning("control socket %s: refused a client with uid %s (allowed: %s)",
                            self.path, uid, sorted(self._allowed))
                self._counts = dataclasses.replace(self._counts, refused=self._counts.refused + 1)
                conn.close()
                return
        self._add(conn)
