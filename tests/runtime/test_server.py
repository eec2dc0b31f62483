"""The control socket: ControlServer and ControlClient over real Unix sockets in a short tmp dir."""

from __future__ import annotations

import contextlib
import json
import os
import queue
import resource
import shutil
import socket
import stat
import tempfile
import threading
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pytest

from gateway.core.errors import ConfigError, GatewayError, GatewayTimeoutError
from gateway.core.types import GatewayState, Twist
from gateway.runtime.access import ControlSocketError, SocketInUseError, peer_credentials
from gateway.runtime.client import ClientError, ClientTimeoutError, ControlClient
from gateway.runtime.server import ControlServer, ServerCounters
from gateway.wire.socket import (
    CommandRequest,
    Op,
    ProtocolError,
    Request,
    ResetOdometryRequest,
    SubscribeRequest,
    Topic,
    TwistRequest,
    event,
    reply_ok,
    reply_protocol_error,
)

if TYPE_CHECKING:
    from collections.abc import Callable, Iterator

pytestmark = [
    pytest.mark.timeout(30),
    # A socket closed by the garbage collector instead of by us is a leak.
    pytest.mark.filterwarnings("error::ResourceWarning"),
    pytest.mark.filterwarnings("error::pytest.PytestUnraisableExceptionWarning"),
]

WAIT_S = 5.0  # upper bound of every wait; tests pass far sooner


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


# -- requests and replies --------------------------------------------------------------------


def test_twist_round_trip(server: ControlServer, sock_path: Path) -> None:
    with LoopThread(server), ControlClient(sock_path) as client:
        assert client.request({"op": "twist", "vx": 0.1, "wz": 0.2}) == {
            "ok": True,
            "id": 1,
            "twist": {"vx_m_s": 0.1, "vy_m_s": 0.0, "wz_rad_s": 0.2},
        }
        assert client.request({"op": "status"}) == {"ok": True, "id": 2, "op": "status"}
        assert client.request({"op": "stop", "id": "s"}) == {"ok": True, "id": "s", "op": "stop"}
        assert client.request({"op": "twist", "vx": "fast"}) == {
            "ok": False,
            "id": 3,
            "error": {
                "code": "bad_command",
                "message": 'twist.vx: expected a finite number, got "fast"',
            },
        }
        assert client.request({"op": "stop", "id": 1.5}) == {  # unreadable id: answered anyway
            "ok": False,
            "id": None,
            "error": {
                "code": "bad_command",
                "message": "request.id: expected an integer (64-bit) or a string of at most 64 "
                "characters, got 1.5",
            },
        }
    counters = server.counters
    assert (counters.accepted, counters.malformed, counters.refused) == (1, 2, 0)


def test_poll_splits_lines_and_skips_blank_ones(server: ControlServer, sock_path: Path) -> None:
    with raw_client(sock_path) as raw:
        raw.send(b'{"op":"enable","id":1}\n\n  \r\n{"op":"twist","vx":0.5}\r\n{"op":"st')
        events = poll_until(server, lambda ev: len(ev) >= 2, "two requests")
        (cid,) = server.client_ids
        assert events == [
            (cid, CommandRequest(Op.ENABLE, 1)),
            (cid, TwistRequest(Twist(0.5))),
        ]
        raw.send(b'op"}\n')
        assert poll_until(server, bool, "the rest") == [(cid, CommandRequest(Op.STOP))]
    assert server.poll(0.0) == []


def test_poll_keeps_waiting_after_a_connect_and_wakes_on_data(
    server: ControlServer, sock_path: Path
) -> None:
    with raw_client(sock_path) as raw:
        timer = threading.Timer(0.05, raw.send, args=(b'{"op":"estop"}\n',))
        timer.start()
        try:
            # One call: the accept alone does not end the wait, the request does.
            events = server.poll(WAIT_S * 2)
        finally:
            timer.join(WAIT_S)
        assert [item for _, item in events] == [CommandRequest(Op.ESTOP)]


def test_malformed_json_gets_an_error_reply_and_the_connection_continues(
    server: ControlServer, sock_path: Path
) -> None:
    with LoopThread(server), raw_client(sock_path) as raw:
        raw.send(b'{bad\n[]\n{"op":"status","id":5}\n')
        assert raw.line() == {
            "ok": False,
            "id": None,
            "error": {
                "code": "bad_command",
                "message": "request: expected valid JSON, got expecting property name "
                "enclosed in double quotes at offset 1",
            },
        }
        assert raw.line()["error"]["message"] == "request: expected a JSON object, got an array"
        assert raw.line() == {"ok": True, "id": 5, "op": "status"}
    assert server.counters.malformed == 2


def test_too_long_message_is_reported_and_skipped(server: ControlServer, sock_path: Path) -> None:
    with LoopThread(server), raw_client(sock_path) as raw:
        raw.send(b'{"op":"stop","id":1,"pad":"' + b"x" * 5000 + b'"}\n{"op":"status","id":2}\n')
        assert raw.line() == {
            "ok": False,
            "id": None,
            "error": {
                "code": "bad_command",
                "message": "message too long: expected at most 1024 bytes, got more",
            },
        }
        assert raw.line() == {"ok": True, "id": 2, "op": "status"}
    counters = server.counters
    assert (counters.too_long, counters.malformed, counters.accepted) == (1, 0, 1)


def test_too_long_is_reported_before_its_newline_and_only_once(
    sock_path: Path,
) -> None:
    with ControlServer(sock_path, max_message_bytes=64) as srv:
        with LoopThread(srv), raw_client(sock_path) as raw:
            raw.send(b"x" * 100)  # no newline yet: reported as soon as it exceeds the limit
            error = raw.line()["error"]
            assert error["message"] == "message too long: expected at most 64 bytes, got more"
            raw.send(b"y" * 100)
            raw.send(b'z\n{"op":"status","id":2}\n')
            assert raw.line() == {"ok": True, "id": 2, "op": "status"}
            raw.send(b'{"op":"status","id":3}'.ljust(64) + b"\r\n")  # exactly at the limit
            assert raw.line() == {"ok": True, "id": 3, "op": "status"}
            raw.send(b'{"op":"status","id":4}'.ljust(65) + b"\n")  # one byte over
            assert raw.line()["error"]["code"] == "bad_command"
            raw.send(b'{"op":"status","id":5}\n')
            assert raw.line()["id"] == 5
        counters = srv.counters
    assert (counters.too_long, counters.malformed, counters.dropped_partial) == (2, 0, 0)


def test_disconnect_mid_message_drops_the_partial_line(
    server: ControlServer, sock_path: Path
) -> None:
    with raw_client(sock_path) as raw:
        raw.send(b'{"op":"stop","id":1}\n{"op":"sto')
    events = poll_until(server, lambda ev: server.counters.dropped_partial == 1, "the drop")
    assert [item for _, item in events] == [CommandRequest(Op.STOP, 1)]
    with raw_client(sock_path) as raw:  # a clean goodbye is not a dropped partial
        raw.send(b'{"op":"stop","id":2}\n')
    events = poll_until(server, lambda ev: server.counters.accepted == 2 and not
                        server.client_ids, "the second client")
    assert [item for _, item in events] == [CommandRequest(Op.STOP, 2)]
    counters = server.counters
    assert (counters.clients, counters.dropped_partial, counters.malformed) == (0, 1, 0)


def test_half_closed_client_still_gets_its_reply(server: ControlServer, sock_path: Path) -> None:
    with LoopThread(server), raw_client(sock_path) as raw:
        raw.send(b'{"op":"status","id":1}\n')
        raw.sock.shutdown(socket.SHUT_WR)  # as `socat` and `nc -q` do at the end of input
        assert raw.line() == {"ok": True, "id": 1, "op": "status"}
        assert raw.at_eof()


def test_half_closed_client_is_kept_until_its_output_is_flushed(
    server: ControlServer, sock_path: Path
) -> None:
    big = reply_ok(1, {"pad": "x" * 600_000})  # more than the kernel buffers at once
    received = bytearray()
    with raw_client(sock_path) as raw:
        raw.send(b'{"op":"status","id":1}\n')
        ((cid, _),) = poll_until(server, bool, "the request")
        assert server.reply(cid, big)
        raw.sock.shutdown(socket.SHUT_WR)
        server.poll(0.05)  # sees the end of input; output is still pending
        assert server.client_ids == {cid}

        def drain() -> None:
            while chunk := raw.sock.recv(1 << 16):
                received.extend(chunk)

        reader = threading.Thread(target=drain, name="test-drain", daemon=True)
        reader.start()
        poll_until(server, lambda ev: not server.client_ids, "the flush and close")
        reader.join(WAIT_S)
        assert not reader.is_alive()
    assert bytes(received) == big
    assert server.counters.slow_disconnects == 0


# -- the socket file -------------------------------------------------------------------------


def test_socket_file_mode(server: ControlServer, sock_path: Path, sock_dir: Path) -> None:
    assert stat.S_ISSOCK(os.stat(sock_path).st_mode)
    assert stat.S_IMODE(os.stat(sock_path).st_mode) == 0o660
    with ControlServer(sock_dir / "private.sock", mode=0o600):
        assert stat.S_IMODE(os.stat(sock_dir / "private.sock").st_mode) == 0o600


def test_stale_socket_file_is_replaced(sock_path: Path) -> None:
    stale = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    stale.bind(str(sock_path))
    stale.close()  # the file stays, nobody listens
    assert sock_path.is_socket()
    with ControlServer(sock_path) as srv, LoopThread(srv), ControlClient(sock_path) as client:
        assert client.request({"op": "status"})["ok"] is True
    assert not sock_path.exists()


def test_socket_in_use_by_another_server(server: ControlServer, sock_path: Path) -> None:
    with pytest.raises(SocketInUseError) as info:
        ControlServer(sock_path)
    assert str(info.value) == (
        f"control socket {sock_path}: another process is listening on it "
        "(is another `wheelgate run` running?)"
    )
    assert isinstance(info.value, OSError)
    assert isinstance(info.value, GatewayError)
    with LoopThread(server), ControlClient(sock_path) as client:  # the first one is unharmed
        assert client.request({"op": "status"})["ok"] is True


def test_non_socket_file_is_never_replaced(sock_path: Path) -> None:
    sock_path.write_text("precious")
    with pytest.raises(SocketInUseError) as info:
        ControlServer(sock_path)
    assert str(info.value) == (
        f"control socket {sock_path}: expected a socket or nothing, got an existing "
        "non-socket file; refusing to replace it"
    )
    assert sock_path.read_text() == "precious"


def test_socket_creation_errors(sock_dir: Path) -> None:
    before = open_fds()
    long_path = sock_dir / ("x" * 120)
    size = len(os.fsencode(long_path))
    with pytest.raises(ControlSocketError) as info:
        ControlServer(long_path)
    assert str(info.value) == (
        f"control socket {long_path}: expected a path of at most 107 bytes "
        f"(the AF_UNIX limit), got {size}"
    )
    missing = sock_dir / "missing" / "gw.sock"
    with pytest.raises(ControlSocketError, match=r"cannot create it: \[Errno 2\]"):
        ControlServer(missing)
    with pytest.raises(ConfigError, match="control socket max_clients: expected at least 1, got 0"):
        ControlServer(sock_dir / "gw.sock", max_clients=0)
    assert not (sock_dir / "gw.sock").exists()
    assert open_fds() == before


def test_close_is_idempotent_and_removes_only_its_own_file(sock_path: Path) -> None:
    srv = ControlServer(sock_path)
    srv.close()
    srv.close()
    assert not sock_path.exists()
    with pytest.raises(ControlSocketError, match="expected an open server, got a closed one"):
        srv.poll(0.0)
    srv = ControlServer(sock_path)
    sock_path.unlink()
    sock_path.write_text("someone else's")
    srv.close()
    assert sock_path.read_text() == "someone else's"


# -- access control --------------------------------------------------------------------------

FOREIGN_UID = 4242


class ForeignUserServer(ControlServer):
    """Sees every client as uid FOREIGN_UID (we cannot become another user unprivileged)."""

    def _peer_uid(self, sock: socket.socket) -> int | None:
        return FOREIGN_UID


def test_peer_credentials_of_a_socketpair() -> None:
    left, right = socket.socketpair(socket.AF_UNIX)
    with left, right:
        creds = peer_credentials(left)
    assert creds is not None
    assert (creds.pid, creds.uid, creds.gid) == (os.getpid(), os.getuid(), os.getgid())


def test_allowed_uids_refuse_a_foreign_uid(sock_path: Path) -> None:
    with ForeignUserServer(sock_path, allowed_uids=frozenset({FOREIGN_UID + 1})) as srv:
        with raw_client(sock_path) as raw:
            poll_until(srv, lambda ev: srv.counters.refused == 1, "the refusal")
            assert raw.at_eof()
        assert (srv.counters.accepted, srv.counters.clients) == (0, 0)


def test_allowed_uids_admit_listed_uids_and_the_owner(sock_path: Path, sock_dir: Path) -> None:
    with ForeignUserServer(sock_path, allowed_uids=frozenset({FOREIGN_UID})) as srv:
        with LoopThread(srv), ControlClient(sock_path) as client:
            assert client.request({"op": "status"})["ok"] is True
    # Real SO_PEERCRED: our own uid is admitted although it is not listed.
    other = FOREIGN_UID if os.getuid() != FOREIGN_UID else FOREIGN_UID + 1
    with ControlServer(sock_dir / "own.sock", allowed_uids=frozenset({other})) as srv:
        with LoopThread(srv), ControlClient(sock_dir / "own.sock") as client:
            assert client.request({"op": "status"})["ok"] is True
        assert (srv.counters.accepted, srv.counters.refused) == (1, 0)


NOBODY = 65534


def run_as_nobody(action: Callable[[], str], meanwhile: Callable[[], object]) -> str:
    """Run ``action`` in a forked child as uid/gid 65534; ``meanwhile`` runs here meanwhile."""
    read_fd, write_fd = os.pipe()
    pid = os.fork()
    if pid == 0:  # the child: report through the pipe and leave without any cleanup
        os.close(read_fd)
        try:
            os.setgid(NOBODY)
            os.setuid(NOBODY)
            out = action()
        except BaseException as err:
            out = f"{type(err).__name__}: {err}"
        os.write(write_fd, out.encode())
        os._exit(0)
    os.close(write_fd)
    try:
        meanwhile()
        with os.fdopen(read_fd, "rb", closefd=False) as pipe:  # the child's sockets time out
            return pipe.read().decode()
    finally:
        os.close(read_fd)
        os.waitpid(pid, 0)


def connect_and_read(path: Path, request: bytes) -> str:
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as sock:
        sock.settimeout(WAIT_S)
        sock.connect(str(path))
        if request:
            sock.sendall(request)
        try:
            data = sock.recv(65536)
        except ConnectionResetError:
            data = b""
        return data.decode() or "eof"


needs_root = pytest.mark.skipif(os.geteuid() != 0, reason="needs root to act as another user")


@needs_root
def test_allowed_uids_with_a_real_other_user(sock_dir: Path) -> None:
    sock_dir.chmod(0o711)
    path = sock_dir / "gw.sock"
    with ControlServer(path, mode=0o666, allowed_uids=frozenset({FOREIGN_UID})) as srv:
        out = run_as_nobody(
            lambda: connect_and_read(path, b""),
            lambda: poll_until(srv, lambda ev: srv.counters.refused == 1, "the refusal"),
        )
        assert out == "eof"
    with ControlServer(path, mode=0o666, allowed_uids=frozenset({NOBODY})) as srv:

        def serve() -> None:
            ((cid, item),) = poll_until(srv, bool, "the request")
            srv.reply(cid, respond(srv, cid, item))

        out = run_as_nobody(lambda: connect_and_read(path, b'{"op":"status","id":1}\n'), serve)
        assert json.loads(out) == {"ok": True, "id": 1, "op": "status"}
        assert srv.counters.refused == 0


@needs_root
def test_client_permission_denied(server: ControlServer, sock_path: Path, sock_dir: Path) -> None:
    sock_dir.chmod(0o711)  # the socket itself stays 0660, owned by root

    def attempt() -> str:
        try:
            ControlClient(sock_path)
        except ClientError as err:
            return str(err)
        return "connected"

    out = run_as_nobody(attempt, lambda: None)
    assert out == f"permission denied for {sock_path} (is your user in the socket's group?)"


# -- output, subscriptions and slow readers --------------------------------------------------


def test_publish_reaches_only_subscribers(server: ControlServer, sock_path: Path) -> None:
    with (
        LoopThread(server) as loop,
        ControlClient(sock_path) as odometry,
        ControlClient(sock_path) as status,
        ControlClient(sock_path) as idle,
    ):
        assert odometry.request({"op": "subscribe", "topics": ["odometry"]})["topics"] == [
            "odometry"
        ]
        assert status.request({"op": "subscribe", "topics": ["status", "odometry"]})["ok"]
        assert idle.request({"op": "status"})["ok"]
        loop.outbox.put((Topic.ODOMETRY, event(Topic.ODOMETRY, {"x": 1.0})))
        loop.outbox.put((Topic.STATUS, event(Topic.STATUS, {"state": GatewayState.RUNNING})))
        assert next(odometry.events(WAIT_S)) == {"event": "odometry", "x": 1.0}
        stream = status.events(WAIT_S)
        assert next(stream) == {"event": "odometry", "x": 1.0}
        assert next(stream) == {"event": "status", "state": "running"}
        # Both events were published before this reply was sent; none reached `idle`.
        assert idle.request({"op": "status"})["ok"]
        with pytest.raises(ClientTimeoutError):
            next(idle.events(0.01))
        # After unsubscribing, `status` gets the next event but `odometry` does not.
        assert odometry.request({"op": "unsubscribe"})["ok"]
        loop.outbox.put((Topic.ODOMETRY, event(Topic.ODOMETRY, {"x": 2.0})))
        assert next(stream) == {"event": "odometry", "x": 2.0}
        assert odometry.request({"op": "status"})["ok"]
        with pytest.raises(ClientTimeoutError):
            next(odometry.events(0.01))


def test_slow_subscriber_is_disconnected(sock_path: Path) -> None:
    with (
        ControlServer(sock_path, max_pending_bytes_per_client=65536) as srv,
        raw_client(sock_path) as raw,
    ):
        raw.send(b'{"op":"subscribe","topics":["status"],"id":1}\n')
        ((cid, item),) = poll_until(srv, bool, "the subscription")
        srv.reply(cid, respond(srv, cid, item))
        assert srv.has_subscribers(Topic.STATUS)
        data = event(Topic.STATUS, {"pad": "x" * 1000})
        published = 0
        while srv.publish(Topic.STATUS, data):  # the client never reads
            published += 1
            assert published < 10_000, "the slow subscriber was never disconnected"
        counters = srv.counters
        assert (counters.slow_disconnects, counters.clients) == (1, 0)
        assert not srv.has_subscribers(Topic.STATUS)
        assert srv.reply(cid, b"late\n") is False
        # What the kernel took is still readable, then the stream ends.
        assert raw.line() == {"ok": True, "id": 1, "topics": ["status"]}
        received = 0
        while chunk := raw.sock.recv(1 << 16):
            received += len(chunk)
        assert 0 < received <= published * len(data)


def test_unknown_client_ids_are_ignored(server: ControlServer) -> None:
    assert server.reply(999, b"x\n") is False
    assert server.subscribe(999, {Topic.STATUS}) is False
    assert server.unsubscribe(999) is False
    assert server.publish(Topic.STATUS, b"x\n") == 0
    assert server.counters == ServerCounters()


def test_a_thousand_clients_at_once_displace_the_oldest_silent_ones(sock_path: Path) -> None:
    """Each connection beyond max_clients closes the oldest that has sent nothing yet: the
    last 600 are served, the first 400 were displaced (counted as refused)."""
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    need = 3000
    if soft < need:
        if hard != resource.RLIM_INFINITY and hard < need:
            pytest.skip(f"needs {need} file descriptors, the hard limit is {hard}")
        resource.setrlimit(resource.RLIMIT_NOFILE, (need, hard))
    try:
        before = open_fds()
        served, counters = _thousand_clients(sock_path, total=1000, max_clients=600)
        assert open_fds() == before
    finally:
        resource.setrlimit(resource.RLIMIT_NOFILE, (soft, hard))
    assert served == list(range(400, 1000))
    assert (counters.accepted, counters.refused, counters.evicted) == (1000, 400, 0)


def _thousand_clients(path: Path, total: int, max_clients: int) -> tuple[list[int], ServerCounters]:
    """Connect ``total`` clients one after the other, then send a status request on each:
    the indices of those answered."""
    served: list[int] = []
    clients: list[socket.socket] = []
    with ControlServer(path, max_clients=max_clients) as srv:
        try:
            with LoopThread(srv):
                for _ in range(total):
                    sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
                    clients.append(sock)
                    sock.settimeout(WAIT_S)
                    sock.connect(str(path))
                deadline = time.monotonic() + WAIT_S
                while srv.counters.accepted < total:  # all accepted before anyone sends
                    assert time.monotonic() < deadline, f"accepted only {srv.counters}"
                    time.sleep(0.01)
                for index, sock in enumerate(clients):
                    with contextlib.suppress(BrokenPipeError, ConnectionResetError):
                        sock.sendall(b'{"op":"status","id":%d}\n' % index)
                for index, sock in enumerate(clients):
                    data = b""
                    with contextlib.suppress(ConnectionResetError):
                        while not data.endswith(b"\n") and (chunk := sock.recv(4096)):
                            data += chunk
                    if data:
                        assert json.loads(data) == {"ok": True, "id": index, "op": "status"}
                        served.append(index)
        finally:
            for sock in clients:
                sock.close()
        counters = srv.counters
    return served, counters


def test_running_out_of_file_descriptors_pauses_accepting(
    server: ControlServer, sock_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    clients = [socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) for _ in range(3)]
    try:
        for sock in clients:
            sock.connect(str(sock_path))  # waits in the backlog
        lowest_free = os.open(os.devnull, os.O_RDONLY)
        os.close(lowest_free)
        resource.setrlimit(resource.RLIMIT_NOFILE, (lowest_free, hard))  # no fd is free
        try:
            assert server.poll(0.02) == []  # accept fails with EMFILE: no exception
        finally:
            resource.setrlimit(resource.RLIMIT_NOFILE, (soft, hard))
        assert "accept failed" in caplog.text
        assert server.counters.accepted == 0
        poll_until(server, lambda ev: server.counters.accepted == 3, "the retry")
    finally:
        for sock in clients:
            sock.close()


# -- budgets, timeouts and eviction ----------------------------------------------------------


def lines(op: str, count: int, start: int = 0) -> bytes:
    return b"".join(b'{"op":"%s","id":%d}\n' % (op.encode(), k) for k in range(start, count))


def ids(events: Events) -> list[object]:
    """The request ids of ``events`` (a parse error's when it could be read)."""
    return [item.request_id if isinstance(item, ProtocolError) else item.id for _, item in events]


def test_a_poll_takes_at_most_its_budget_round_robin(
    server: ControlServer, sock_path: Path
) -> None:
    with raw_client(sock_path) as flood, raw_client(sock_path) as other:
        flood.send(lines("stop", 200))
        other.send(b'{"op":"estop","id":"e"}\n')
        batches: list[Events] = []
        while sum(map(len, batches)) < 201:
            assert len(batches) < 50, f"only {sum(map(len, batches))} requests in 50 polls"
            batches.append(server.poll(0.05))
        first = next(batch for batch in batches if batch)
    assert max(map(len, batches)) == ControlServer.ROUND_REQUESTS
    # One line per client per turn: the other client's estop is not behind the flood.
    assert CommandRequest(Op.ESTOP, "e") in [item for _, item in first[:2]]
    flood_ids = [rid for batch in batches for rid in ids(batch) if rid != "e"]
    assert flood_ids == list(range(200))
    assert server.counters.deferred >= 3


def test_a_cycle_budget_spans_its_polls_and_the_rest_waits_unread(
    server: ControlServer, sock_path: Path
) -> None:
    with raw_client(sock_path) as raw:
        raw.send(lines("stop", 100))
        server.begin_cycle(0.005)  # 12,800 requests/s: 64 in this cycle, whatever the polls
        taken = poll_until(server, bool, "the first requests")
        for _ in range(3):
            taken += server.poll(0.0)
        assert len(taken) == 64
        cpu = time.thread_time()
        assert server.poll(0.1) == []  # the rest waits unread: a real wait, no spin
        assert time.thread_time() - cpu < 0.05
        server.begin_cycle(0.005)
        taken += poll_until(server, lambda ev: len(ev) >= 36, "the rest")
    assert ids(taken) == list(range(100))


def test_costly_ops_wait_for_their_allowance_without_holding_up_others(
    server: ControlServer, sock_path: Path
) -> None:
    with raw_client(sock_path) as monitor, raw_client(sock_path) as pilot:
        monitor.send(lines("status", 3) + b'{"op":"stop","id":3}\n')
        pilot.send(b'{"op":"twist","vx":0.1,"id":"t"}\n{"op":"estop","id":"e"}\n')
        cycles = []
        for _ in range(4):
            server.begin_cycle(0.005)  # status and estop: 200/s each, one per cycle
            taken: Events = []
            for _ in range(3):
                taken += server.poll(0.02)
            cycles.append(set(ids(taken)))
    # The monitor's statuses come one per cycle, its stop behind them; the pilot's twist and
    # estop are not held up by them.
    assert cycles == [{0, "t", "e"}, {1}, {2, 3}, set()]


def test_a_full_server_closes_the_longest_idle_client_for_a_new_one(sock_path: Path) -> None:
    def connected(count: int) -> None:
        poll_until(srv, lambda ev: srv.counters.accepted == count, f"connection {count}")

    def answered(raw: RawClient, rid: int) -> None:
        raw.send(b'{"op":"stop","id":%d}\n' % rid)
        assert ids(poll_until(srv, bool, f"request {rid}")) == [rid]

    with (
        ControlServer(sock_path, max_clients=3) as srv,
        raw_client(sock_path) as silent,
        raw_client(sock_path) as older,
        raw_client(sock_path) as newer,
    ):
        connected(3)
        answered(older, 2)
        answered(newer, 3)
        with raw_client(sock_path) as fourth:
            connected(4)  # closes the one that never sent a line
            assert silent.at_eof()
            assert (srv.counters.refused, srv.counters.evicted) == (1, 0)
            answered(fourth, 4)
            with raw_client(sock_path) as fifth:
                connected(5)  # nobody silent: closes the one idle longest
                assert older.at_eof()
                assert (srv.counters.refused, srv.counters.evicted) == (1, 1)
                answered(fifth, 5)
                answered(newer, 6)
                assert srv.counters.clients == 3


def test_idle_and_half_line_clients_are_closed_subscribers_and_talkers_kept(
    sock_path: Path,
) -> None:
    with ControlServer(sock_path, idle_timeout_s=0.5, partial_timeout_s=0.5) as srv:
        with (
            raw_client(sock_path) as idle,
            raw_client(sock_path) as half,
            raw_client(sock_path) as listener,
            raw_client(sock_path) as talker,
        ):
            half.send(b'{"op":"st')
            listener.send(b'{"op":"subscribe","topics":["error"],"id":1}\n')
            end = time.monotonic() + 1.5
            while time.monotonic() < end:
                talker.send(b"\n")  # a blank line is a sign of life too
                for cid, item in srv.poll(0.05):
                    srv.reply(cid, respond(srv, cid, item))
            assert idle.at_eof()
            assert half.at_eof()
            assert listener.line()["topics"] == ["error"]
            counters = srv.counters
    assert (counters.idle_timeouts, counters.partial_timeouts, counters.clients) == (1, 1, 2)
    assert counters.dropped_partial == 0  # closed by the server, not a disconnect


def test_a_client_that_does_not_read_its_replies_is_slowed_not_dropped(sock_path: Path) -> None:
    count = 400
    with (
        ControlServer(sock_path, max_pending_bytes_per_client=16384) as srv,
        raw_client(sock_path) as raw,
    ):
        raw.send(lines("status", count))
        answered = 0
        received: list[int] = []

        def serve(seconds: float) -> None:
            """Poll and answer (and flush) until every reply has been read, or ``seconds``."""
            nonlocal answered
            end = time.monotonic() + seconds
            while time.monotonic() < end and len(received) < count:
                for cid, item in srv.poll(0.01):
                    assert isinstance(item, CommandRequest)
                    srv.reply(cid, reply_ok(item.id, {"pad": "x" * 2000}))
                    answered += 1

        serve(0.5)
        # The kernel's buffer and 8 KiB of queue filled up: its requests are no longer read.
        assert 0 < answered < count

        def drain() -> None:
            while len(received) < count:
                received.append(raw.line()["id"])

        reader = threading.Thread(target=drain, name="test-drain", daemon=True)
        reader.start()
        serve(WAIT_S)
        reader.join(WAIT_S)
        assert received == list(range(count))
        assert (srv.counters.slow_disconnects, srv.counters.clients) == (0, 1)


def test_all_subscribers_queues_together_are_capped(
    sock_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    with (
        ControlServer(sock_path) as srv,
        raw_client(sock_path) as first,
        raw_client(sock_path) as second,
    ):
        srv.MAX_PENDING_BYTES_TOTAL = 48 * 1024  # less than one client's own 64 KiB
        first.send(b'{"op":"subscribe","topics":["status"]}\n')
        second.send(b'{"op":"subscribe","topics":["status"]}\n')
        for cid, item in poll_until(srv, lambda ev: len(ev) == 2, "the subscriptions"):
            srv.reply(cid, respond(srv, cid, item))
        data = event(Topic.STATUS, {"pad": "x" * 1000})
        published = 0
        while srv.counters.slow_disconnects == 0:  # neither reads
            srv.publish(Topic.STATUS, data)
            published += 1
            assert published < 5000, "no subscriber was disconnected"
        assert srv.counters.clients == 1
    assert "bytes of output pending for all clients, no room for more (at most 49152)" in (
        caplog.text
    )


# -- client errors ---------------------------------------------------------------------------


@contextlib.contextmanager
def scripted_gateway(path: Path, lines: list[bytes]) -> Iterator[None]:
    """A fake gateway: accept one client, read one line, send ``lines``, hang up."""
    listener = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    listener.bind(str(path))
    listener.listen(1)
    listener.settimeout(WAIT_S)

    def serve() -> None:
        conn, _ = listener.accept()
        with conn:
            conn.settimeout(WAIT_S)
            data = b""
            while not data.endswith(b"\n") and (chunk := conn.recv(4096)):
                data += chunk
            conn.sendall(b"".join(lines))

    thread = threading.Thread(target=serve, name="scripted-gateway", daemon=True)
    thread.start()
    try:
        yield
    finally:
        thread.join(WAIT_S)
        listener.close()


def test_client_skips_other_replies_and_keeps_events(sock_path: Path) -> None:
    lines = [b'{"ok":true,"id":99}\n', b'{"event":"status","n":1}\n', b'{"ok":true,"id":1}\n',
             b'{"ok":true,"id":7}\n', b'{"event":"status","n":2}\n']
    with scripted_gateway(sock_path, lines), ControlClient(sock_path) as client:
        assert client.request({"op": "status"}) == {"ok": True, "id": 1}
        stream = client.events(WAIT_S)
        assert next(stream) == {"event": "status", "n": 1}
        assert next(stream) == {"event": "status", "n": 2}  # the stray reply is skipped
        with pytest.raises(ClientError) as info:
            next(stream)
    assert str(info.value) == (
        f"the gateway closed the connection on {sock_path} before sending an event"
    )


@pytest.mark.parametrize(
    ("lines", "message"),
    [
        ([], "the gateway closed the connection on {path} before sending the reply to request 1"),
        ([b"nope\n"], "{path}: gateway message: expected a JSON object, got Expecting value: "
                      "line 1 column 1 (char 0)"),
        ([b"[]\n"], "{path}: gateway message: expected a JSON object, got an array"),
    ],
)
def test_client_errors_from_a_broken_gateway(
    sock_path: Path, lines: list[bytes], message: str
) -> None:
    with scripted_gateway(sock_path, lines), ControlClient(sock_path) as client:
        with pytest.raises(ClientError) as info:
            client.request({"op": "status"})
    assert str(info.value) == message.format(path=sock_path)


def test_client_errors_name_the_socket(sock_path: Path) -> None:
    expected = f"no gateway is listening on {sock_path} (is `wheelgate run` running?)"
    with pytest.raises(ClientError) as info:
        ControlClient(sock_path)
    assert str(info.value) == expected
    assert isinstance(info.value, ConnectionError)
    assert isinstance(info.value, GatewayError)
    stale = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    stale.bind(str(sock_path))
    stale.close()
    with pytest.raises(ClientError) as info:
        ControlClient(sock_path)
    assert str(info.value) == expected


def test_client_timeout_and_use_after_close(server: ControlServer, sock_path: Path) -> None:
    client = ControlClient(sock_path, timeout_s=0.05)  # nobody polls the server
    with client, pytest.raises(ClientTimeoutError) as info:
        client.request({"op": "status"})
    assert str(info.value) == f"timed out waiting for the reply to request 1 from {sock_path}"
    assert isinstance(info.value, TimeoutError)
    assert isinstance(info.value, GatewayTimeoutError)
    client.close()
    with pytest.raises(ClientError) as info2:
        client.request({"op": "status"})
    assert str(info2.value) == f"the connection to {sock_path} is closed"
