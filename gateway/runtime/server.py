"""The local control socket: a non-blocking, selector-based Unix stream server of JSON lines.

A thin edge around :mod:`gateway.wire.socket`.  The control loop owns it and is its only user
(it is not thread-safe); :meth:`ControlServer.poll` doubles as the loop's inter-cycle sleep, so
a twist that arrives mid-sleep is handled at once.  Nothing a client does makes it raise or
block: bad lines become :class:`~gateway.wire.socket.ProtocolError` events, a client that stops
reading its replies is no longer read, and a subscriber that stops reading its events is
disconnected once :attr:`max_pending_bytes_per_client` of output is queued for it.

No client can stall the loop or lock the others out:

* **Budgets.**  One poll takes at most :attr:`~ControlServer.ROUND_REQUESTS` lines and
  :attr:`~ControlServer.ROUND_BYTES` bytes, round robin over the clients, one line each per
  turn.  A loop that calls :meth:`~ControlServer.begin_cycle` before each cycle's polls also
  bounds the cycle: :attr:`~ControlServer.REQUESTS_PER_S` and
  :attr:`~ControlServer.READ_BYTES_PER_S` times its period (64 requests and 64 KiB at 200 Hz),
  and the costly ops to :attr:`~ControlServer.OP_RATES_PER_S` (``status`` builds a large
  reply, ``estop`` writes the latch file).  What is left waits in the kernel's buffer, unread,
  for the next poll or cycle, whose first turns it gets: a client that sends faster than that
  just waits.
* **Full.**  With ``max_clients`` connected, a new connection closes the client idle longest
  -- first those of which no line was taken yet, oldest first (counted in ``refused``), then
  the least recently active (``evicted``) -- and is served: an ``estop`` on a new connection
  gets through however many idle connections are held.  The soft ``RLIMIT_NOFILE`` is raised
  to fit ``max_clients`` (or ``max_clients`` lowered, with a warning), and an ``accept()`` that
  still fails for want of descriptors (``EMFILE``) closes the client idle longest the same way.
* **Stalls.**  A client in the middle of a line for ``partial_timeout_s``, or without a line
  for ``idle_timeout_s`` (subscribers excepted), is closed; see
  :class:`gateway.runtime.connections.Connections` for the bounds on each client's memory.

Access control -- the socket file's mode and the peers' credentials -- is described in
:mod:`gateway.runtime.access`; the clients' side -- lines in, replies and events out,
subscriptions -- is :class:`gateway.runtime.connections.Connections` (and its base
:class:`gateway.runtime.clients.ClientTable`), which the server extends.

A client that shuts down its writing side after its requests (``socat``, ``nc -q``) is kept
until the replies queued for it are sent, then closed at the start of the next poll.
"""

from __future__ import annotations

import dataclasses
import errno
import logging
import selectors
import time
from collections import deque
from pathlib import Path
from typing import TYPE_CHECKING, ClassVar

from gateway.bus.edge import LOG_EVERY_S
from gateway.bus.health import LogThrottle
from gateway.core.lifecycle import Closing
from gateway.core.status import ServerCounters
from gateway.runtime.access import (
    ControlSocketError,
    admitted_uids,
    check_socket_path,
    listen,
    peer_credentials,
    remove_own_socket,
    remove_stale_socket,
)
from gateway.runtime.clients import (
    SpareFd,
    check_settings,
    connection_waits,
    fit_clients,
    log_failed_accept,
    log_refused_uid,
)
from gateway.runtime.connections import Budget, Connection, Connections, Events
from gateway.wire.socket import MAX_REQUEST_BYTES, Op

if TYPE_CHECKING:
    import socket
    from collections.abc import Mapping

__all__ = ["Budget", "ControlServer", "Events", "ServerCounters"]

log = logging.getLogger(__name__)

_FD_ERRNOS = frozenset({errno.EMFILE, errno.ENFILE})  # a client closed makes room
_RESOURCE_ERRNOS = _FD_ERRNOS | {errno.ENOBUFS, errno.ENOMEM}  # retried at the next poll


class ControlServer(Connections, Closing):
    """The control socket server.

    :param path: the socket file (at most 107 bytes encoded).
    :param mode: file mode of the socket (default ``0o660``).
    :param max_message_bytes: longest accepted line, newline excluded (longer ones are skipped
        as they come, never held, and answered with one error each).
    :param max_clients: most clients at once; a new connection beyond them closes the client
        idle longest (see the module's docstring); lowered, with a warning, to what the
        open-file limit allows (:func:`~gateway.runtime.clients.fit_clients`).
    :param allowed_uids: uids allowed to connect besides the server's own (Linux only);
        ``None`` leaves access control to the file mode.
    :param max_pending_bytes_per_client: output queued for one client beyond which an event
        disconnects it as too slow; its requests are not read while half of it is queued.
    :param idle_timeout_s: a client that sends no line for this long is closed, unless it
        subscribed to something; ``None``: never.
    :param partial_timeout_s: a client that stays in the middle of a line for this long is
        closed; ``None``: never.
    :raises SocketInUseError: if another process listens on ``path``, or it is not a socket.
    :raises ControlSocketError: if the socket cannot be created (path too long, directory
        missing or not writable).
    :raises ConfigError: for non-positive limits, or ``allowed_uids`` without ``SO_PEERCRED``.
    """

    #: Most connections accepted per select round, so a connection storm cannot stall a cycle.
    ACCEPT_BATCH = 128
    #: ``listen()`` backlog asked for (the kernel caps it at ``net.core.somaxconn``).
    BACKLOG = 4096
    #: Most lines (requests, blank and bad lines included) taken in one poll.
    ROUND_REQUESTS = 64
    #: Most bytes received in one poll.
    ROUND_BYTES = 64 * 1024
    #: Lines taken per second of cycles (see :meth:`begin_cycle`): 64 a cycle at 200 Hz, 13 at
    #: 1 kHz.  A twist costs the loop about 30 us of CPU (receive, parse, handle, reply; on
    #: the 2-core development VM): at most about 40 % of each cycle.
    REQUESTS_PER_S = 12_800.0
    #: Bytes received per second of cycles: 64 KiB a cycle at 200 Hz.
    READ_BYTES_PER_S = 64.0 * 1024 * 200
    #: The costly ops' own rates, per second of cycles: ``status`` builds and encodes a reply of
    #: several KB (about 0.5 ms), ``estop`` writes and syncs the latch file (about 1 ms, more on
    #: an SD card); one of each per cycle at 200 Hz.  A request of such an op beyond its
    #: allowance waits for the next cycle; the client's other requests wait behind it, the
    #: other clients do not.
    OP_RATES_PER_S: ClassVar[Mapping[Op, float]] = {Op.STATUS: 200.0, Op.ESTOP: 200.0}
    #: How often the timeouts are checked at most, s (at least twice per timeout).
    SWEEP_S = 0.5
    #: File descriptors kept beyond one per client: the bus, the listener, the selector, the
    #: latch file, logs, the Zenoh bridge's sockets (:func:`.clients.fit_clients`).
    FD_HEADROOM = 64

    def __init__(
        self,
        path: str | Path,
        mode: int = 0o660,
        max_message_bytes: int = MAX_REQUEST_BYTES,
        max_clients: int = 1024,
        allowed_uids: frozenset[int] | None = None,
        max_pending_bytes_per_client: int = 64 * 1024,
        idle_timeout_s: float | None = 60.0,
        partial_timeout_s: float | None = 5.0,
    ) -> None:
        self._closed = True
        check_settings(max_message_bytes=max_message_bytes, max_clients=max_clients,
                       max_pending_bytes_per_client=max_pending_bytes_per_client,
                       idle_timeout_s=idle_timeout_s, partial_timeout_s=partial_timeout_s)
        self._allowed = admitted_uids(allowed_uids)
        self.path = Path(path)
        self.max_clients = fit_clients(max_clients, self.FD_HEADROOM)
        self.allowed_uids = None if allowed_uids is None else frozenset(allowed_uids)
        check_socket_path(self.path)
        remove_stale_socket(self.path)
        selector = selectors.DefaultSelector()
        try:
            self._listener, self._identity = listen(self.path, mode, self.BACKLOG)
        except BaseException:
            selector.close()
            raise
        super().__init__(selector, max_message_bytes, max_pending_bytes_per_client,
                         idle_timeout_s, partial_timeout_s)
        self._selector.register(self._listener, selectors.EVENT_READ, None)
        self._accepting = True
        #: Set while ``max_clients`` are connected (logged once per episode).
        self._full = False
        # Failed accepts and refused uids: a line per LOG_EVERY_S each, with the count.
        self._accept_log = LogThrottle(LOG_EVERY_S)
        self._uid_log = LogThrottle(LOG_EVERY_S)
        self._spare = SpareFd()  # for the accept that finds no descriptor left
        #: Whether a loop calls begin_cycle (else every poll has a budget of its own).
        self._cycles = False
        self._cycle_requests = self.ROUND_REQUESTS
        self._cycle_bytes = self.ROUND_BYTES
        #: The costly ops' allowances (from the first begin_cycle on).
        self._op_tokens: dict[Op, float] | None = None
        self._sweep_s = min(self.SWEEP_S, *(t / 2 for t in (idle_timeout_s, partial_timeout_s)
                                            if t is not None))
        self._next_sweep = time.monotonic() + self._sweep_s
        self._closed = False
        log.info("control socket listening on %s (mode %o)", self.path, mode)

    # -- the loop's interface ---------------------------------------------------------------

    def poll(self, timeout_s: float) -> Events:
        """Wait up to ``timeout_s`` for requests; accept, read, split and parse -- within the
        budget (see the module's docstring): clients whose input was left over by the last poll
        are served first, then the others as they come, round robin.

        Returns as soon as one select round produced at least one event, else at the timeout.

        :param timeout_s: longest wait in seconds (0 for a non-blocking pass).
        :return: ``(client id, request or parse error)`` pairs in arrival order per client.
        :raises ControlSocketError: if the server is closed.
        """
        self._check_open()
        now = time.monotonic()
        if now >= self._next_sweep:
            self._sweep(now)
        self._resume_accepting()
        for cid in list(self._half_closed):
            if not self._clients[cid].outbuf:
                self._drop(self._clients[cid], "closed its end")
        if not self._cycles:
            self._cycle_requests, self._cycle_bytes = self.ROUND_REQUESTS, self.ROUND_BYTES
        budget = Budget(min(self.ROUND_REQUESTS, self._cycle_requests),
                        min(self.ROUND_BYTES, self._cycle_bytes), self._op_tokens)
        requests, received = budget.requests, budget.bytes
        ready: deque[Connection] = deque()
        if self._deferred and budget.requests > 0 and budget.bytes > 0:
            ready.extend(self._clients[cid] for cid in self._deferred)  # still not read
            self._deferred.clear()
        events: Events = []
        deadline = now + max(timeout_s, 0.0)
        try:
            while True:
                selected = self._selector.select(0.0 if ready else max(deadline - now, 0.0))
                now = time.monotonic()
                for key, mask in selected:
                    if key.data is None:
                        self._accept(now)
                        continue
                    client = self._clients.get(key.data)
                    if client is None:  # dropped earlier in this round
                        continue
                    if mask & selectors.EVENT_WRITE:
                        self._flush(client)
                    if mask & selectors.EVENT_READ and client.cid in self._clients:
                        ready.append(client)
                if ready:
                    self._serve(ready, budget, events, now)
                if events or now >= deadline:
                    return events
        finally:
            self._cycle_requests -= requests - budget.requests
            self._cycle_bytes -= received - budget.bytes

    def begin_cycle(self, period_s: float) -> None:
        """Start the budget of a cycle of ``period_s``: the polls until the next call take at
        most :attr:`REQUESTS_PER_S` and :attr:`READ_BYTES_PER_S` times it between them, and the
        costly ops their :attr:`OP_RATES_PER_S` (fractions carry over, so a rate below one per
        cycle still lets one through every few cycles).  Until the first call, every poll is a
        budget of its own.

        :raises ValueError: for a period that is not a positive number of seconds.
        """
        if not period_s > 0:
            raise ValueError(f"control socket cycle: expected a positive period in seconds, "
                             f"got {period_s}")
        self._cycles = True
        self._cycle_requests = max(1, round(self.REQUESTS_PER_S * period_s))
        self._cycle_bytes = max(self.max_message_bytes + 2,
                                round(self.READ_BYTES_PER_S * period_s))
        if self._op_tokens is None:
            self._op_tokens = {}
        tokens = self._op_tokens
        for op, rate in self.OP_RATES_PER_S.items():
            grant = rate * period_s
            cap = max(1.0, grant)
            tokens[op] = min(cap, tokens.get(op, cap) + grant)

    def fileno(self) -> int:
        """The selector's descriptor: readable while a connection, a request or a writable
        client with queued output waits (for waits finer than epoll's milliseconds) -- but not
        for the input of clients that wait for a later poll's budget."""
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
        self._spare.close()
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

    def _sweep(self, now_s: float) -> None:
        """Apply the timeouts; end the episodes logged once."""
        self._next_sweep = now_s + self._sweep_s
        self._expire(now_s)
        if self._full and len(self._clients) < self.max_clients:
            log.info("control socket %s: %d clients connected, fewer than max_clients again",
                     self.path, len(self._clients))
            self._full = False

    def _accept(self, now_s: float) -> None:
        self._spare.restore()  # (none held since the last EMFILE: a descriptor may be free now)
        for _ in range(self.ACCEPT_BATCH):
            try:
                conn, _ = self._listener.accept()
            except (BlockingIOError, InterruptedError):
                return
            except OSError as err:
                if err.errno in _FD_ERRNOS and not connection_waits(self._listener):
                    return  # nothing to accept (accept() fails all the same)
                count = self._accept_log.note(now_s)
                if count is not None:
                    log_failed_accept(self.path, len(self._clients), err, count,
                                      err.errno in _FD_ERRNOS and bool(self._clients))
                if err.errno in _FD_ERRNOS and self._spare.release():
                    # Out of descriptors: accepted into the spare's; room made if admitted.
                    self._accept_spare(now_s)
                    continue
                if err.errno in _FD_ERRNOS and self._clients:
                    self._evict(full=False)  # (no spare: room first, as at max_clients)
                    continue
                if err.errno in _RESOURCE_ERRNOS:  # retried at the next poll, not in a spin
                    self._selector.unregister(self._listener)
                    self._accepting = False
                return
            self._admit(conn, now_s)

    def _accept_spare(self, now_s: float) -> None:
        try:
            conn: socket.socket | None = self._listener.accept()[0]
        except OSError:
            conn = None
        if conn is not None and not self._refused(conn, now_s):
            if self._clients:
                self._evict(full=False)
            self._admit(conn, now_s, checked=True)
        self._spare.restore()

    def _admit(self, conn: socket.socket, now_s: float, checked: bool = False) -> None:
        if not checked and self._refused(conn, now_s):
            return
        while self._clients and len(self._clients) >= self.max_clients:
            self._evict()
        self._add(conn, now_s)

    def _refused(self, conn: socket.socket, now_s: float) -> bool:
        """Close and count a connection whose peer's uid is not allowed."""
        conn.setblocking(False)
        if self._allowed is None:
            return False
        uid = self._peer_uid(conn)
        if uid is not None and uid in self._allowed:
            return False
        count = self._uid_log.note(now_s)
        if count is not None:
            log_refused_uid(self.path, uid, self._allowed, count)
        self._counts = dataclasses.replace(self._counts, refused=self._counts.refused + 1)
        conn.close()
        return True

    def _evict(self, full: bool = True) -> None:
        """Close the client idle longest to make room: first those of which no line was
        taken yet, oldest first; else the least recently active.

        :param full: ``max_clients`` are connected (else: out of file descriptors before).
        """
        silent = next(iter(self._silent), None)
        cid = silent if silent is not None else next(iter(self._recent))
        if full and not self._full:
            log.warning("control socket %s: %d clients connected (max_clients): each new "
                        "connection now closes the one idle longest", self.path,
                        len(self._clients))
            self._full = True
        counts = self._counts
        if silent is not None:
            self._counts = dataclasses.replace(counts, refused=counts.refused + 1)
        else:
            self._counts = dataclasses.replace(counts, evicted=counts.evicted + 1)
        self._drop(self._clients[cid], "closed for a new connection ("
                   + ("max_clients reached)" if full else "out of file descriptors)"))
