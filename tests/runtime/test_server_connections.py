"""The control socket's conversations: ControlServer and ControlClient over real Unix sockets in a
short tmp dir -- lines in, replies out, malformed and too long input, half-closed clients, and
the client's side (other replies, events, errors, timeouts)."""

from __future__ import annotations

import contextlib
import socket
import threading
from typing import TYPE_CHECKING

import pytest

from gateway.apps.jog.link import JogLink
from gateway.core.errors import GatewayError, GatewayTimeoutError
from gateway.core.types import Twist
from gateway.runtime.client import ClientError, ClientTimeoutError, ControlClient
from gateway.runtime.server import ControlServer
from gateway.wire.socket import (
    CommandRequest,
    Op,
    TwistRequest,
    reply_ok,
)
from tests.runtime import server_helpers
from tests.runtime.server_helpers import (
    WAIT_S,
    LoopThread,
    poll_until,
    raw_client,
)

if TYPE_CHECKING:
    from collections.abc import Iterator
    from pathlib import Path

pytestmark = server_helpers.MARKS


# The shared fixtures (server_helpers.py), bound here so that pytest finds them.
sock_dir = server_helpers.sock_dir
sock_path = server_helpers.sock_path
server = server_helpers.server


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


def test_a_client_is_not_refused_by_a_daemon_that_binds_but_does_not_listen_yet(
        sock_path: Path) -> None:
    """The daemon binds its socket file, chmods it, then listens: a client that waits for
    the file and then connects (a script's ``while [ ! -S sock ]``, and
    ``test_kill_9_after_an_estop_restarts_estopped`` once in CI) could come in between and
    be refused.  A refusal while the file is there is tried again for up to 0.5 s."""
    starting = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    starting.bind(str(sock_path))
    later = threading.Timer(0.1, starting.listen, args=(1,))
    later.start()
    try:
        with ControlClient(sock_path, timeout_s=2.0):
            conn, _ = starting.accept()
            conn.close()
    finally:
        later.join()
        starting.close()


def test_a_caller_that_retries_on_its_own_is_not_held_up_by_a_stale_file(
        sock_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """``jog``'s screen reconnects every second by itself: a stale socket file (a daemon
    killed with SIGKILL) must not stop its screen 0.5 s at each try."""
    stale = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    stale.bind(str(sock_path))
    stale.close()
    waited: list[float] = []
    monkeypatch.setattr("gateway.runtime.client.time.sleep", waited.append)
    with pytest.raises(ClientError, match="no gateway is listening"):
        ControlClient(sock_path, refused_retry_s=0.0)
    assert waited == []
    link = JogLink.__new__(JogLink)
    link.path, link.client, link._retry_s = str(sock_path), None, 0.0
    link.retry(force=True)
    assert waited == [] and "no gateway is listening" in link.error


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
