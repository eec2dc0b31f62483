"""The control socket under abuse: a running daemon keeps its rate and serves everyone.

Each test runs the TurtleBot3 configuration with simulated controllers in a thread (the loop at
200 Hz, as ``wheelgate run --sim`` does), applies one load a local client can make, and checks
counts, not times: the deadlines the loop missed (``scheduler.timer.missed``), the cycles it ran
and the CAN frames it sent in every window of the load, the daemon's memory (this process's
RSS: the daemon is a thread of it), and what the clients got.

=====================================  =======================================================
load                                   bound
=====================================  =======================================================
64 KiB of pipelined ``status`` lines   at most 10 + 50 % of the cycles missed, at least a quarter
                                       of the cycles and some CAN frames in every second, every
                                       request answered in order
1,024 idle connections, then estop     the estop is answered and the gateway is in ESTOP
200 subscribers that never read        all dropped, RSS growth under 20 MB, one warning
30 lines of 60 KB                      one ``too long`` error each, RSS growth under 20 MB
=====================================  =======================================================

The bounds on missed deadlines are generous: the machine is shared, and another user's load
alone makes the idle loop miss a few.  The faults they catch are of another order: before, the
status flood stalled the loop for seconds (every deadline in it missed, the state FAULT).
"""

from __future__ import annotations

import contextlib
import logging
import os
import resource
import socket
import threading
import time
from typing import TYPE_CHECKING, Any

import pytest

from gateway.config import load_config
from gateway.core.types import GatewayState
from gateway.runtime.client import ControlClient
from gateway.runtime.daemon import Daemon
from gateway.runtime.sdnotify import SystemdNotifier
from gateway.runtime.server import ControlServer
from gateway.wire.socket import LineFramer, ProtocolError, parse_message
from tests.conftest import CONFIG_DIR

if TYPE_CHECKING:
    from collections.abc import Iterator

PAGE = os.sysconf("SC_PAGE_SIZE")
MB = 1_000_000


def rss() -> int:
    """This process's resident set, bytes."""
    with open("/proc/self/statm", encoding="ascii") as f:
        return int(f.read().split()[1]) * PAGE


def connect(path: str) -> socket.socket:
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    sock.settimeout(10.0)
    sock.connect(path)
    return sock


def read_lines(sock: socket.socket, count: int, out: list[dict[str, Any]]) -> None:
    """Append the next ``count`` messages on ``sock`` to ``out`` (stops at end of file)."""
    buf = bytearray()
    with contextlib.suppress(OSError):
        while len(out) < count:
            while (newline := buf.find(b"\n")) >= 0 and len(out) < count:
                out.append(parse_message(bytes(buf[:newline])))
                del buf[: newline + 1]
            if len(out) < count and not (chunk := sock.recv(65536)):
                return
            buf += chunk


@contextlib.contextmanager
def running(sock_path: str, channel: str, **loop: object) -> Iterator[Daemon]:
    """The ``daemon`` fixture's daemon, with loop options changed."""
    import dataclasses

    cfg = load_config(CONFIG_DIR / "turtlebot3_burger.yaml", {"channel": channel})
    cfg = dataclasses.replace(cfg, loop=dataclasses.replace(cfg.loop, **loop))  # type: ignore[arg-type]
    d = Daemon(cfg, sim=True, socket_path=sock_path, notifier=SystemdNotifier(None))
    thread = threading.Thread(target=d.run, daemon=True)
    thread.start()
    try:
        end = time.monotonic() + 10
        while d.gateway.state is not GatewayState.RUNNING and time.monotonic() < end:
            time.sleep(0.02)
        yield d
    finally:
        d.request_stop()
        thread.join(timeout=10)


class Watch:
    """The loop's figures, in windows of ``window_s`` while a load runs."""

    def __init__(self, daemon: Daemon, window_s: float = 1.0) -> None:
        self.daemon = daemon
        self.window_s = window_s
        self.missed0 = daemon.scheduler.timer.missed
        #: Per window: its length (s), the cycles run and the CAN frames sent in it.
        self.windows: list[tuple[float, int, int]] = []
        self.faults: list[str] = []  # the states other than RUNNING met, with their reasons
        self._start = time.monotonic()
        self._last = self._now()

    def _now(self) -> tuple[int, int]:
        gw = self.daemon.gateway
        return gw.counts.cycles, gw.edge.counts.frames_sent

    def tick(self, final: bool = False) -> None:
        """Close the window if it is due (call often), or ``final``ly whatever it holds."""
        now_s = time.monotonic()
        length = now_s - self._start
        if length < self.window_s and not (final and length >= 0.1):
            return
        now = self._now()
        self.windows.append((length, now[0] - self._last[0], now[1] - self._last[1]))
        gw = self.daemon.gateway
        if gw.state is not GatewayState.RUNNING:
            self.faults.append(f"{gw.state.name}: {gw.supervisor.reason}")
        self._start, self._last = now_s, now

    @property
    def missed(self) -> int:
        return self.daemon.scheduler.timer.missed - self.missed0

    @staticmethod
    def bound(cycles: float) -> float:
        """The most deadlines that may be missed in ``cycles``: 10 + 50 %.  A stalled loop
        misses nearly all (405 of 408 before the budgets); a loop that keeps its rate on a
        shared, loaded machine (another VM, other test runs) misses up to a third here."""
        return 10 + 0.5 * cycles

    def check(self) -> None:
        """Every window (the last, partial one included) at least a quarter of its cycles with some
        frames out, and at most :meth:`bound` deadlines missed.

        Not that the gateway stayed RUNNING: on a busy shared machine the simulated controllers'
        thread is now and then starved for their 0.2 s liveness (a FAULT, both motors at once,
        from which the gateway recovers), whatever the socket does; a stalled loop shows in the
        cycles and frames."""
        self.tick(final=True)
        rate = self.daemon.config.loop.rate_hz
        assert self.windows, "no window closed"
        for k, (length, cycles, frames) in enumerate(self.windows):
            assert cycles >= 0.25 * rate * length, f"window {k}: {self.windows}; {self.faults}"
            assert frames > 0, f"window {k}: no CAN frame out: {self.windows}; {self.faults}"
        expected = rate * sum(length for length, _, _ in self.windows)
        assert self.missed <= self.bound(expected), (
            f"{self.missed} deadlines missed in {expected:.0f} cycles: {self.windows}; "
            f"{self.faults}")


@pytest.mark.timeout(60)
def test_pipelined_status_flood_neither_stalls_the_loop_nor_loses_a_request(
    daemon: Daemon, sock_path: str
) -> None:
    """64 KiB of status requests at once: answered at the status allowance (200/s) while the
    loop keeps its rate; before, one poll answered all of them and stalled the loop for
    seconds (no frame out, every deadline missed, the state FAULT)."""
    line = b'{"op":"status","id":%d}\n'
    flood = bytearray()
    count = 0
    while len(flood) + len(line % count) <= 64 * 1024:
        flood += line % count
        count += 1
    watch = Watch(daemon)
    replies: list[dict[str, Any]] = []
    with connect(sock_path) as sock:
        sock.settimeout(50.0)
        reader = threading.Thread(target=read_lines, args=(sock, count, replies), daemon=True)
        reader.start()
        sock.sendall(flood)
        while reader.is_alive():
            watch.tick()
            reader.join(0.05)
    assert len(replies) == count
    assert [r["id"] for r in replies] == list(range(count))
    assert all(r["ok"] for r in replies)
    watch.check()
    assert daemon.server.counters.deferred > 0


@pytest.mark.timeout(60)
def test_estop_gets_through_with_1024_idle_connections_held(
    daemon: Daemon, sock_path: str
) -> None:
    """Before, connection 1,025 was accepted and closed at once: the estop got ECONNRESET."""
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    need = 2 * daemon.server.max_clients + 200
    if soft < need:
        if hard != resource.RLIM_INFINITY and hard < need:
            pytest.skip(f"needs {need} file descriptors, the hard limit is {hard}")
        resource.setrlimit(resource.RLIMIT_NOFILE, (need, hard))
    idle: list[socket.socket] = []
    try:
        for _ in range(daemon.server.max_clients):
            idle.append(connect(sock_path))
        end = time.monotonic() + 10
        while daemon.server.counters.clients < daemon.server.max_clients:
            assert time.monotonic() < end, f"not all accepted: {daemon.server.counters}"
            time.sleep(0.01)
        # The loop's rate with them all held (not while this thread opens them: the daemon is
        # a thread of this process, so that measures the interpreter's lock; the benchmark
        # measures the storm from another process).
        watch = Watch(daemon)
        while not watch.windows:
            watch.tick()
            time.sleep(0.05)
        with ControlClient(sock_path, timeout_s=5.0) as client:
            reply = client.request({"op": "estop"})
            counters = daemon.server.counters
        assert reply["ok"] is True and reply["state"] == "estop"
        assert daemon.gateway.state is GatewayState.ESTOP
        # The connection idle longest made room (it never sent a line: counted as refused).
        assert idle[0].recv(1) == b""
        assert (counters.clients, counters.refused, counters.evicted) == (
            daemon.server.max_clients, 1, 0)
        watch.check()
    finally:
        for sock in idle:
            sock.close()
        resource.setrlimit(resource.RLIMIT_NOFILE, (soft, hard))


@pytest.mark.timeout(60)
def test_subscribers_that_never_read_are_dropped_and_memory_stays_bounded(
    sock_path: str, channel: str, caplog: pytest.LogCaptureFixture
) -> None:
    """Before, 1 MiB of output could pile up for each (200 MiB for 200), and nothing dropped
    them for minutes.  Odometry at 200 Hz fills their buffers in seconds."""
    caplog.set_level(logging.WARNING, logger="gateway.runtime.connections")
    count = 200
    with running(sock_path, channel, odom_rate_hz=200.0) as daemon:
        base = rss()
        peak = base
        watch = Watch(daemon)
        mute: list[socket.socket] = []
        try:
            for _ in range(count):
                sock = connect(sock_path)
                sock.sendall(b'{"op":"subscribe","topics":["odometry","status","error"]}\n')
                mute.append(sock)
            end = time.monotonic() + 45
            while daemon.server.counters.slow_disconnects < count:
                assert time.monotonic() < end, (
                    f"not all dropped: {daemon.server.counters}; RSS +{(peak - base) / MB} MB")
                peak = max(peak, rss())
                watch.tick()
                time.sleep(0.05)
            assert all(sock.recv(1 << 20) for sock in mute)  # what the kernel had taken ...
            for sock in mute:
                while sock.recv(1 << 20):  # ... then end of file
                    pass
        finally:
            for sock in mute:
                sock.close()
        assert peak - base < 20 * MB, f"RSS grew by {(peak - base) / MB:.1f} MB"
        assert daemon.server.counters.clients == 0
        watch.check()
    too_slow = [r for r in caplog.records if "as too slow" in r.getMessage()]
    assert len(too_slow) == 1, [r.getMessage() for r in too_slow]  # once per episode


@pytest.mark.timeout(60)
def test_long_lines_are_skipped_unheld_and_each_answered_with_one_error(
    daemon: Daemon, sock_path: str
) -> None:
    """30 lines of 60 KB: one ``too long`` error each, then the next request is answered."""
    count, size = 30, 60_000
    pad = b"x" * (size - len(b'{"op":"stop","pad":""}'))
    payload = (b'{"op":"stop","pad":"' + pad + b'"}\n') * count + b'{"op":"stop","id":"last"}\n'
    base = rss()
    watch = Watch(daemon, window_s=0.2)
    replies: list[dict[str, Any]] = []
    with connect(sock_path) as sock:
        sender = threading.Thread(target=sock.sendall, args=(payload,), daemon=True)
        sender.start()
        reader = threading.Thread(target=read_lines, args=(sock, count + 1, replies),
                                  daemon=True)
        reader.start()
        while reader.is_alive():
            watch.tick()
            reader.join(0.02)
        sender.join(5.0)
    peak = rss()
    limit = daemon.server.max_message_bytes
    assert [r["error"]["message"] for r in replies[:count]] == [
        f"message too long: expected at most {limit} bytes, got more"] * count
    assert replies[count] == {"ok": True, "id": "last", "state": "running"}
    assert daemon.server.counters.too_long == count
    assert peak - base < 20 * MB
    watch.check()


def test_a_long_line_is_never_held_whole() -> None:
    """The framer keeps at most max_bytes + 1 bytes of a line, however it comes."""
    framer = LineFramer(1024)
    line = b"x" * 60_000 + b"\n" + b'{"op":"stop"}\n'
    held = []
    out: list[bytes | ProtocolError] = []
    for start in range(0, len(line), 4096):
        framer.push(line[start : start + 4096])
        held.append(framer.pending)
        while (item := framer.pop()) is not None:
            out.append(item)
    assert max(held) <= 1025
    assert [str(x) if isinstance(x, ProtocolError) else x for x in out] == [
        "message too long: expected at most 1024 bytes, got more", b'{"op":"stop"}']


def test_a_server_holds_no_more_than_a_receive_and_a_line_per_client(sock_path: str) -> None:
    """What the server buffers for a client streaming a long line: one receive's worth."""
    with ControlServer(sock_path) as srv, connect(sock_path) as sock:
        held = 0
        events = []
        for _ in range(60):
            sock.sendall(b"y" * 1000)
            events += srv.poll(0.01)
            for client in srv._clients.values():
                held = max(held, client.framer.pending)
        sock.sendall(b'\n{"op":"stop","id":1}\n')
        end = time.monotonic() + 5
        while len(events) < 2 and time.monotonic() < end:
            events += srv.poll(0.01)
    assert held <= srv.max_message_bytes + 1
    assert [type(item).__name__ for _, item in events] == ["ProtocolError", "CommandRequest"]
