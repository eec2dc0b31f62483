"""The control socket's clients as the server keeps them: who is connected, what is queued for
each, their subscriptions, and closing them.

:class:`ClientTable` is the output half of :class:`gateway.runtime.connections.Connections`,
which adds the input half (lines in, within the budgets, and the timeouts).  Replies and events
go out without blocking: what the kernel does not take is queued, and flushed by
:meth:`~gateway.runtime.server.ControlServer.poll` when the client's socket is writable.

What one client's output can cost the daemon is bounded: a client's requests are not read while
half of :attr:`~ClientTable.max_pending_bytes_per_client` is queued for it, so a client that
pipelines requests and reads its replies slowly is slowed down, not dropped, and its queued
replies stay bounded; an event that would take a subscriber's queue beyond that limit (or all
clients' beyond :attr:`~ClientTable.MAX_PENDING_BYTES_TOTAL`) disconnects it as too slow
instead.

:func:`fit_clients` makes room for the clients under the process's open-file limit, and
:class:`SpareFd` keeps one descriptor for the accept that finds none left.
"""

from __future__ import annotations

import contextlib
import logging
import os
import resource
import select
import selectors
import socket
import time
from collections import OrderedDict
from dataclasses import replace
from typing import TYPE_CHECKING

from gateway.bus.health import since_last
from gateway.core.errors import ConfigError
from gateway.core.status import ServerCounters
from gateway.wire.socket import LineFramer, Request, Topic

if TYPE_CHECKING:
    from collections.abc import Iterable

__all__ = ["ClientTable", "Connection", "SpareFd", "check_settings", "connection_waits",
           "fit_clients", "log_failed_accept", "log_refused_uid"]

#: One logger for the clients' input and output (:mod:`gateway.runtime.connections`).
log = logging.getLogger("gateway.runtime.connections")

_SEND_FLAGS = getattr(socket, "MSG_NOSIGNAL", 0)


def fit_clients(max_clients: int, headroom: int) -> int:
    """``max_clients``, or fewer if that many clients would not leave ``headroom`` file
    descriptors under the soft ``RLIMIT_NOFILE`` -- raised first, as far as the hard limit
    allows, to ``max_clients + headroom`` (systemd starts services with a soft limit of 1024).
    """
    need = max_clients + headroom
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    if soft == resource.RLIM_INFINITY or soft >= need:
        return max_clients
    raised = need if hard == resource.RLIM_INFINITY else min(need, hard)
    if raised > soft:
        try:
            resource.setrlimit(resource.RLIMIT_NOFILE, (raised, hard))
        except (OSError, ValueError) as err:
            log.debug("raising RLIMIT_NOFILE from %d to %d failed: %s", soft, raised, err)
        else:
            log.debug("RLIMIT_NOFILE raised from %d to %d", soft, raised)
            soft = raised
    if soft >= need:
        return max_clients
    fitted = max(1, soft - headroom)
    log.warning("control socket: max_clients %d lowered to %d: the open-file limit "
                "(RLIMIT_NOFILE) is %d (hard limit %d), and the daemon keeps %d descriptors for "
                "itself; raise it (LimitNOFILE= in the systemd unit, ulimit -n) for more",
                max_clients, fitted, soft, hard, headroom)
    return fitted


def check_settings(**settings: float | None) -> None:
    """The control server's sizes (at least 1) and timeouts (positive seconds, or ``None``).

    :raises ConfigError: naming the setting, what was expected and what came.
    """
    for name, value in settings.items():
        if name.endswith("_s"):
            if value is not None and not value > 0:
                raise ConfigError(f"control socket {name}: expected a positive number of "
                                  f"seconds or None, got {value}")
        elif value is None or value < 1:
            raise ConfigError(f"control socket {name}: expected at least 1, got {value}")


def log_failed_accept(path: object, clients: int, err: OSError, count: int,
                      evicting: bool) -> None:
    """The line of a failed accept (``count``: failed since the last line)."""
    room = (" (out of file descriptors: each new connection closes the client idle longest)"
            if evicting else "")
    log.warning("control socket %s: accept failed with %d clients connected%s: %s%s", path,
                clients, room, err, since_last(count, "failed accepts"))


def log_refused_uid(path: object, uid: int | None, allowed: Iterable[int], count: int) -> None:
    """The line of a connection refused for its peer's uid (``count``: refused since the
    last line)."""
    log.warning("control socket %s: refused a client with uid %s (allowed: %s)%s", path, uid,
                sorted(allowed), since_last(count, "refused"))


def connection_waits(listener: socket.socket) -> bool:
    """Whether a connection waits on ``listener`` (``accept()`` fails with ``EMFILE`` even when
    none does).  ``poll()`` needs no descriptor."""
    waiting = select.poll()
    waiting.register(listener, select.POLLIN)
    return bool(waiting.poll(0))


class SpareFd:
    """One descriptor (``/dev/null``) held in reserve for the accept that finds the process out
    of descriptors (``EMFILE``): :meth:`release` frees it, the connection is accepted into its
    place and its peer checked before any client is closed for it, and :meth:`restore` takes
    it back once a descriptor is free again (the usual remedy, e.g. libuv's and nginx's)."""

    def __init__(self) -> None:
        self._fd: int | None = None
        self.restore()

    def release(self) -> bool:
        """Free the spare; whether there was one."""
        if self._fd is None:
            return False
        os.close(self._fd)
        self._fd = None
        return True

    def restore(self) -> None:
        """Hold a spare again, if a descriptor is free (else later)."""
        if self._fd is None:
            with contextlib.suppress(OSError):
                self._fd = os.open(os.devnull, os.O_RDONLY | os.O_CLOEXEC)

    close = release


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



class ClientTable:
    """The connected clients of one server, registered on its selector, and their output.

    :param selector: the server's selector; clients are registered with their id as data.
    :param max_pending_bytes_per_client: output queued for one client beyond which an event
        disconnects it as too slow; its requests are not read while half of it is queued.
    """

    #: Output queued for all clients together beyond which a client that needs more is
    #: disconnected as too slow.
    MAX_PENDING_BYTES_TOTAL = 16 << 20

    def __init__(self, selector: selectors.DefaultSelector,
                 max_pending_bytes_per_client: int) -> None:
        self.max_pending_bytes_per_client = max_pending_bytes_per_client
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
        #: Clients that shut down their writing side, kept until their output is flushed.
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

    # -- internals ----------------------------------------------------------------------------

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

