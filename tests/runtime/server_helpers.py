"""Shared fixtures and helpers of the control-socket tests (test_server_*): a server in a short
tmp dir (``sock_dir``, ``sock_path``, ``server``), a raw client, a loop thread, waiting on the
server's events, and lines of requests."""

from __future__ import annotations

import contextlib
import json
import os
import queue
import shutil
import socket
import tempfile
import threading
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pytest

from gateway.runtime.server import ControlServer
from gateway.wire.socket import (
    Op,
    ProtocolError,
    Request,
    ResetOdometryRequest,
    SubscribeRequest,
    Topic,
    TwistRequest,
    reply_ok,
    reply_protocol_error,
)

if TYPE_CHECKING:
    from collections.abc import Callable, Iterator

WAIT_S = 5.0  # upper bound of every wait; tests pass far sooner

#: The marks of every server test module: a timeout, and a socket closed by the garbage
#: collector instead of by us is a leak.
MARKS = [
    pytest.mark.timeout(30),
    pytest.mark.filterwarnings("error::ResourceWarning"),
    pytest.mark.filterwarnings("error::pytest.PytestUnraisableExceptionWarning"),
]


@pytest.fixture
def sock_dir() -> Iterator[Path]:
    """A short private directory: AF_UNIX paths must stay under 108 bytes."""
    path = Path(tempfile.mkdtemp(prefix="wg"))
    try:
        yield path
    finally:
        shutil.rmtree(path, ignore_errors=True)


@pytest.fixture
def sock_path(sock_dir: Path) -> Path:
    return sock_dir / "gw.sock"


@pytest.fixture
def server(sock_path: Path) -> Iterator[ControlServer]:
    with ControlServer(sock_path) as srv:
        yield srv


def respond(server: ControlServer, cid: int, item: Request | ProtocolError) -> bytes:
    """What a minimal control loop answers."""
    if isinstance(item, ProtocolError):
        return reply_protocol_error(item)
    if isinstance(item, TwistRequest):
        return reply_ok(item.id, {"twist": item.twist})
    if isinstance(item, SubscribeRequest):
        server.subscribe(cid, item.topics)
        return reply_ok(item.id, {"topics": sorted(t.value for t in item.topics)})
    if isinstance(item, ResetOdometryRequest):
        return reply_ok(item.id, {"pose": item.pose})
    if item.op is Op.UNSUBSCRIBE:
        server.unsubscribe(cid)
    return reply_ok(item.id, {"op": item.op})


class LoopThread:
    """A tiny control loop: poll, reply, publish what the test queued.  Only this thread touches
    the server while it runs."""

    def __init__(self, server: ControlServer) -> None:
        self.server = server
        self.outbox: queue.SimpleQueue[tuple[Topic, bytes]] = queue.SimpleQueue()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="test-loop", daemon=True)

    def _run(self) -> None:
        while not self._stop.is_set():
            for cid, item in self.server.poll(0.01):
                self.server.reply(cid, respond(self.server, cid, item))
            while True:
                try:
                    topic, data = self.outbox.get_nowait()
                except queue.Empty:
                    break
                self.server.publish(topic, data)

    def __enter__(self) -> LoopThread:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join(WAIT_S)
        assert not self._thread.is_alive(), "the test loop did not stop"


class RawClient:
    """A plain socket speaking bytes, for what ControlClient refuses to send."""

    def __init__(self, path: Path) -> None:
        self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        self.sock.settimeout(WAIT_S)
        self.sock.connect(str(path))
        self.buf = b""

    def send(self, data: bytes) -> None:
        self.sock.sendall(data)

    def line(self) -> dict[str, Any]:
        while b"\n" not in self.buf:
            chunk = self.sock.recv(65536)
            assert chunk, "connection closed while waiting for a line"
            self.buf += chunk
        line, self.buf = self.buf.split(b"\n", 1)
        result: dict[str, Any] = json.loads(line)
        return result

    def at_eof(self) -> bool:
        """Whether the server closed the connection (waits up to WAIT_S)."""
        try:
            return self.sock.recv(65536) == b""
        except ConnectionResetError:
            return True

    def close(self) -> None:
        self.sock.close()


@contextlib.contextmanager
def raw_client(path: Path) -> Iterator[RawClient]:
    client = RawClient(path)
    try:
        yield client
    finally:
        client.close()


Events = list[tuple[int, Request | ProtocolError]]


def poll_until(server: ControlServer, done: Callable[[Events], bool], what: str) -> Events:
    """Poll (in this thread) until ``done(events so far)``; fail after WAIT_S."""
    events: Events = []
    deadline = time.monotonic() + WAIT_S
    while not done(events):
        assert time.monotonic() < deadline, f"timed out waiting for {what}; got {events}"
        events += server.poll(0.01)
    return events


def open_fds() -> set[str]:
    return set(os.listdir("/proc/self/fd"))


def lines(op: str, count: int, start: int = 0) -> bytes:
    return b"".join(b'{"op":"%s","id":%d}\n' % (op.encode(), k) for k in range(start, count))
