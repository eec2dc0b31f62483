"""The control socket at the process's limits: the open-file limit (raised for ``max_clients``,
or ``max_clients`` lowered to fit; out of descriptors, the client idle longest makes room),
the log lines of failed accepts and refused uids (one per 5 s, with the count), and a client
that sends one endless line faster than its share of the budget (closed at the partial
timeout)."""

from __future__ import annotations

import contextlib
import logging
import os
import resource
import socket
import threading
import time
from types import SimpleNamespace
from typing import TYPE_CHECKING

import pytest

from gateway.runtime import clients
from gateway.runtime.server import ControlServer
from tests.runtime import server_helpers
from tests.runtime.server_helpers import WAIT_S, poll_until, raw_client

if TYPE_CHECKING:
    from collections.abc import Callable, Iterator
    from pathlib import Path

    from tests.runtime.server_helpers import Events

pytestmark = server_helpers.MARKS

# The shared fixtures (server_helpers.py), bound here so that pytest finds them.
sock_dir = server_helpers.sock_dir
sock_path = server_helpers.sock_path
server = server_helpers.server

SERVER_LOG = "gateway.runtime.server"


@contextlib.contextmanager
def soft_limit(soft: int) -> Iterator[None]:
    """RLIMIT_NOFILE's soft limit set to ``soft`` meanwhile (the hard one unchanged)."""
    before, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    resource.setrlimit(resource.RLIMIT_NOFILE, (soft, hard))
    try:
        yield
    finally:
        resource.setrlimit(resource.RLIMIT_NOFILE, (before, hard))


def accepted(srv: ControlServer, count: int) -> Callable[[Events], bool]:
    return lambda _: srv.counters.accepted == count


def refused_count(srv: ControlServer, count: int) -> Callable[[Events], bool]:
    return lambda _: srv.counters.refused == count


def lowest_free_fd() -> int:
    fd = os.open(os.devnull, os.O_RDONLY)
    os.close(fd)
    return fd


# -- the open-file limit ---------------------------------------------------------------------


def test_the_soft_open_file_limit_is_raised_for_max_clients(sock_path: Path) -> None:
    """Before, under systemd's default soft limit of 1024 (= max_clients), accept() failed
    with EMFILE before max_clients were connected, and the eviction never ran."""
    _, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    need = 1024 + ControlServer.FD_HEADROOM
    if hard != resource.RLIM_INFINITY and hard < need:
        pytest.skip(f"the hard limit {hard} is below {need}")
    with soft_limit(1024):
        with ControlServer(sock_path, max_clients=1024) as srv:
            raised = resource.getrlimit(resource.RLIMIT_NOFILE)[0]
        assert srv.max_clients == 1024
        assert raised == need


def test_max_clients_is_lowered_under_a_hard_limit_with_a_warning(
    sock_path: Path, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    set_to: list[tuple[int, int]] = []
    fake = SimpleNamespace(
        RLIMIT_NOFILE=resource.RLIMIT_NOFILE, RLIM_INFINITY=resource.RLIM_INFINITY,
        getrlimit=lambda _: (512, 1024), setrlimit=lambda _, limits: set_to.append(limits))
    monkeypatch.setattr(clients, "resource", fake)
    with ControlServer(sock_path, max_clients=1024) as srv:
        assert srv.max_clients == 1024 - ControlServer.FD_HEADROOM
    assert set_to == [(1024, 1024)]  # raised as far as it goes
    warning = next(r.getMessage() for r in caplog.records if "max_clients" in r.getMessage())
    assert f"max_clients 1024 lowered to {1024 - ControlServer.FD_HEADROOM}" in warning
    assert "(RLIMIT_NOFILE) is 1024 (hard limit 1024)" in warning


def test_out_of_descriptors_the_client_idle_longest_makes_room(
    sock_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    """Before, an accept() that failed with EMFILE below max_clients left the connection in
    the backlog (an estop on it went unanswered) and logged a warning every poll."""
    caplog.set_level(logging.WARNING, logger=SERVER_LOG)
    # This process's own sockets, made before no descriptor is left (connect() needs none).
    new = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    more = [socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) for _ in range(20)]
    try:
        with ControlServer(sock_path) as srv, raw_client(sock_path) as idle, \
                raw_client(sock_path) as talker:
            poll_until(srv, lambda ev: srv.counters.accepted == 2, "two clients")
            talker.send(b'{"op":"stop","id":1}\n')
            poll_until(srv, bool, "the talker's line")
            with soft_limit(lowest_free_fd()):  # no descriptor free: accept() fails, EMFILE
                new.settimeout(WAIT_S)
                new.connect(str(sock_path))
                new.sendall(b'{"op":"estop","id":"e"}\n')
                events = poll_until(srv, bool, "the new client's estop")
                assert [item.id for _, item in events] == ["e"]  # type: ignore[union-attr]
                assert idle.at_eof()  # it never sent a line: closed first
                for n, sock in enumerate(more, start=4):  # failing again and again: one line
                    sock.connect(str(sock_path))
                    poll_until(srv, accepted(srv, n), f"client {n}")
            counters = srv.counters
    finally:
        for sock in (new, *more):
            sock.close()
    # Closed to make room: the idle one, then the talker (less recently active than the new
    # one), then each of the 20 but the last (they never sent a line).
    assert (counters.accepted, counters.refused, counters.evicted, counters.clients) == (
        3 + 20, 1 + 19, 1, 2)
    failed = [r.getMessage() for r in caplog.records if "accept failed" in r.getMessage()]
    assert len(failed) == 1, failed
    assert "out of file descriptors" in failed[0]


def test_the_spare_descriptor_comes_back_after_an_accept_with_no_client_to_close(
    sock_path: Path
) -> None:
    """The first time descriptors run out, no client is connected: the new one takes the
    spare's descriptor and no other is freed.  Once descriptors are free again the spare is
    taken back, so the next time an idle client still makes room for an e-stop (a review saw
    the spare lost for good, and with it the remedy)."""
    first = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    second = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    try:
        with ControlServer(sock_path) as srv:
            with soft_limit(lowest_free_fd()):
                first.connect(str(sock_path))
                poll_until(srv, accepted(srv, 1), "the first client, into the spare's place")
            srv.poll(0.01)  # descriptors free again: the spare is taken back
            with soft_limit(lowest_free_fd()):
                second.settimeout(WAIT_S)
                second.connect(str(sock_path))
                second.sendall(b'{"op":"estop","id":"e"}\n')
                events = poll_until(srv, bool, "the second client's estop")
            assert [item.id for _, item in events] == ["e"]  # type: ignore[union-attr]
            assert (srv.counters.accepted, srv.counters.refused) == (2, 1)  # the first closed
    finally:
        first.close()
        second.close()


def test_accepts_failing_without_a_client_to_close_log_a_line_per_5_s(
    server: ControlServer, sock_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    """Before, 2,792 lines in 7 s: the listener is re-armed every poll and failed again."""
    caplog.set_level(logging.WARNING, logger=SERVER_LOG)
    with raw_client(sock_path):
        with soft_limit(lowest_free_fd()):
            for _ in range(20):
                assert server.poll(0.005) == []
        poll_until(server, lambda ev: server.counters.accepted == 1, "the retry")
    failed = [r for r in caplog.records if "accept failed" in r.getMessage()]
    assert len(failed) == 1


# -- refused uids ----------------------------------------------------------------------------


class ForeignUserServer(ControlServer):
    """Sees every client as uid 4242 (we cannot become another user unprivileged)."""

    def _peer_uid(self, sock: socket.socket) -> int | None:
        return 4242


class SomeForeignServer(ControlServer):
    """Sees the first two clients as this user, every later one as uid 4242."""

    seen = 0

    def _peer_uid(self, sock: socket.socket) -> int | None:
        self.seen += 1
        return os.getuid() if self.seen <= 2 else 4242


def test_out_of_descriptors_a_refused_uid_closes_no_allowed_client(sock_path: Path) -> None:
    """The connection takes the spare descriptor and its uid is checked before any client is
    closed for it: a stranger is refused, the allowed clients stay (a review saw an allowed
    client closed for a stranger that was then refused)."""
    strangers = [socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) for _ in range(2)]
    try:
        with SomeForeignServer(sock_path, allowed_uids=frozenset({1})) as srv, \
                raw_client(sock_path) as a, raw_client(sock_path) as b:
            poll_until(srv, accepted(srv, 2), "two allowed clients")
            with soft_limit(lowest_free_fd()):  # no descriptor free: accept() fails, EMFILE
                for n, stranger in enumerate(strangers, start=1):
                    stranger.connect(str(sock_path))
                    poll_until(srv, refused_count(srv, n), f"stranger {n} refused")
            counters = srv.counters
            a.sock.sendall(b'{"op":"stop","id":1}\n')
            b.sock.sendall(b'{"op":"stop","id":2}\n')
            got = poll_until(srv, lambda ev: len(ev) == 2, "both allowed clients' lines")
            assert sorted(str(item.id) for _, item in got) == ["1", "2"]  # type: ignore[union-attr]
    finally:
        for stranger in strangers:
            stranger.close()
    assert (counters.refused, counters.evicted, counters.clients) == (2, 0, 2)


def test_refused_uids_log_a_line_per_5_s_with_the_count(
    sock_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    """Before, every refused connection logged a WARNING: 63,000 lines in 2 s."""
    caplog.set_level(logging.WARNING, logger=SERVER_LOG)
    with ForeignUserServer(sock_path, allowed_uids=frozenset({1})) as srv:
        for count in range(1, 31):
            with raw_client(sock_path):
                poll_until(srv, refused_count(srv, count), "the refusal")
    refused = [r for r in caplog.records if "refused a client" in r.getMessage()]
    assert len(refused) == 1
    allowed = ", ".join(map(str, sorted({os.getuid(), 1})))
    assert refused[0].getMessage().endswith(f"a client with uid 4242 (allowed: [{allowed}])")


# -- an endless line ---------------------------------------------------------------------------


class TightServer(ControlServer):
    """A byte budget of 1 KiB a cycle at 200 Hz: a local writer is always over it."""

    READ_BYTES_PER_S = 1024.0 * 200


def test_an_endless_line_faster_than_the_budget_is_closed_at_the_partial_timeout(
    sock_path: Path,
) -> None:
    """Before, a client always over its byte budget was skipped by the timeouts (its input
    always waited for a later poll): an endless line kept it connected for ever."""
    stop = threading.Event()
    with TightServer(sock_path, partial_timeout_s=0.5) as srv, raw_client(sock_path) as raw:
        raw.sock.settimeout(0.1)

        def write() -> None:
            chunk = b"x" * 65536
            while not stop.is_set():
                try:
                    raw.sock.sendall(chunk)
                except TimeoutError:
                    continue
                except OSError:
                    return  # closed by the server

        writer = threading.Thread(target=write, daemon=True)
        writer.start()
        try:
            end = time.monotonic() + WAIT_S
            while srv.counters.partial_timeouts == 0:
                assert time.monotonic() < end, f"never closed: {srv.counters}"
                srv.begin_cycle(0.005)
                srv.poll(0.005)
            counters = srv.counters
        finally:
            stop.set()
            writer.join(WAIT_S)
    assert (counters.partial_timeouts, counters.clients) == (1, 0)
    assert counters.deferred > 0  # it was over its budget all along
