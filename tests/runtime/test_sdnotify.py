"""The sd_notify client against a fake systemd: an AF_UNIX datagram socket of the test's own."""

from __future__ import annotations

import logging
import os
import select
import shutil
import socket
import tempfile
import uuid
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import pytest

from gateway.core.errors import EncodeError
from gateway.runtime.sdnotify import (
    NOTIFY_SOCKET,
    WATCHDOG_PID,
    WATCHDOG_USEC,
    SystemdNotifier,
    parse_address,
    watchdog_period_s,
)

if TYPE_CHECKING:
    from collections.abc import Iterator


@dataclass
class Listener:
    """The receiving end of ``$NOTIFY_SOCKET``."""

    address: str  # as systemd writes it into the environment
    sock: socket.socket

    def receive(self) -> bytes:
        """The next datagram (fails the test rather than hanging if none comes)."""
        return self.sock.recv(4096)

    def pending(self) -> bool:
        """True if a datagram is waiting."""
        readable, _, _ = select.select([self.sock], [], [], 0)
        return bool(readable)


@pytest.fixture
def short_dir() -> Iterator[Path]:
    """A private directory with a short path (AF_UNIX paths are limited to 107 bytes)."""
    path = Path(tempfile.mkdtemp(prefix="wg-sd-"))
    yield path
    shutil.rmtree(path, ignore_errors=True)


def _bind(target: str) -> socket.socket:
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM | socket.SOCK_CLOEXEC)
    sock.bind(target)
    sock.settimeout(2.0)
    return sock


@pytest.fixture(params=["path", "abstract"])
def listener(request: pytest.FixtureRequest, short_dir: Path) -> Iterator[Listener]:
    """A fake systemd notify socket on a filesystem path or in the abstract namespace."""
    if request.param == "path":
        address = str(short_dir / "notify")
        sock = _bind(address)
    else:
        name = f"wheelgate-test-{os.getpid()}-{uuid.uuid4().hex}"
        address = "@" + name
        sock = _bind("\0" + name)
    with sock:
        yield Listener(address, sock)


@pytest.fixture
def notifier(listener: Listener) -> Iterator[SystemdNotifier]:
    """A notifier connected to the fake systemd."""
    with SystemdNotifier(listener.address) as notifier:
        assert notifier.enabled
        yield notifier


# --- the messages ---------------------------------------------------------------------------


def test_ready_status_watchdog_stopping_bytes(
    listener: Listener, notifier: SystemdNotifier
) -> None:
    assert notifier.ready()
    assert notifier.status("running at 200 Hz")
    assert notifier.watchdog()
    assert notifier.stopping()
    assert [listener.receive() for _ in range(4)] == [
        b"READY=1",
        b"STATUS=running at 200 Hz",
        b"WATCHDOG=1",
        b"STOPPING=1",
    ]
    assert notifier.errors == 0


def test_ready_and_stopping_with_status_in_one_datagram(
    listener: Listener, notifier: SystemdNotifier
) -> None:
    notifier.ready(status="up")
    notifier.stopping(status="bye")
    assert listener.receive() == b"READY=1\nSTATUS=up"
    assert listener.receive() == b"STOPPING=1\nSTATUS=bye"


def test_status_is_one_line(listener: Listener, notifier: SystemdNotifier) -> None:
    notifier.status("bus ok\nREADY=1\r\nmissed 3\r")
    assert listener.receive() == b"STATUS=bus ok READY=1 missed 3 "


def test_notify_fields_raw_and_extend_timeout(
    listener: Listener, notifier: SystemdNotifier
) -> None:
    assert notifier.notify(STATUS="two\nlines", MAINPID=42)
    assert notifier.send_raw("WATCHDOG=trigger")
    assert notifier.extend_timeout(2.5)
    assert listener.receive() == b"STATUS=two lines\nMAINPID=42"
    assert listener.receive() == b"WATCHDOG=trigger"
    assert listener.receive() == b"EXTEND_TIMEOUT_USEC=2500000"


def test_bad_field_name_is_an_encode_error(notifier: SystemdNotifier) -> None:
    with pytest.raises(EncodeError, match="got 'ready'"):
        notifier.notify(ready=1)


def test_socket_is_cloexec(notifier: SystemdNotifier) -> None:
    sock = notifier._sock
    assert sock is not None
    assert not sock.get_inheritable()
    assert sock.type == socket.SOCK_DGRAM


# --- environment ----------------------------------------------------------------------------


def test_from_env_pops_notify_socket(listener: Listener) -> None:
    env = {NOTIFY_SOCKET: listener.address, "PATH": "/usr/bin"}
    with SystemdNotifier.from_env(env) as notifier:
        assert notifier.enabled
        assert env == {"PATH": "/usr/bin"}
        notifier.ready()
    assert listener.receive() == b"READY=1"


def test_from_env_uses_os_environ_by_default(
    listener: Listener, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv(NOTIFY_SOCKET, listener.address)
    monkeypatch.setenv(WATCHDOG_USEC, "1000000")
    monkeypatch.setenv(WATCHDOG_PID, str(os.getpid()))
    with SystemdNotifier.from_env() as notifier:
        assert NOTIFY_SOCKET not in os.environ
        assert notifier.enabled
        assert notifier.watchdog_period_s == 0.5


def test_without_notify_socket_it_is_a_silent_no_op(
    caplog: pytest.LogCaptureFixture,
) -> None:
    env: dict[str, str] = {WATCHDOG_USEC: "1000000"}
    with caplog.at_level(logging.DEBUG, logger="gateway.runtime.sdnotify"):
        notifier = SystemdNotifier.from_env(env)
        assert not notifier.enabled
        assert not notifier.ready()
        assert not notifier.watchdog()
        assert not notifier.status("x")
    assert notifier.errors == 0
    assert notifier.watchdog_period_s is None
    assert caplog.records == []


@pytest.mark.parametrize("address", ["relative/path", "@", "vsock:2:1234", "x"])
def test_invalid_address_disables_with_warning(
    address: str, caplog: pytest.LogCaptureFixture
) -> None:
    env = {NOTIFY_SOCKET: address}
    with caplog.at_level(logging.WARNING, logger="gateway.runtime.sdnotify"):
        notifier = SystemdNotifier.from_env(env)
    assert not notifier.enabled
    assert NOTIFY_SOCKET not in env
    assert notifier.errors == 1
    assert not notifier.ready()
    [record] = caplog.records
    assert record.levelno == logging.WARNING
    assert repr(address) in record.getMessage()


def test_unreachable_path_disables_with_warning(
    short_dir: Path, caplog: pytest.LogCaptureFixture
) -> None:
    with caplog.at_level(logging.WARNING, logger="gateway.runtime.sdnotify"):
        notifier = SystemdNotifier(str(short_dir / "nobody-listens"))
    assert not notifier.enabled
    assert notifier.errors == 1
    assert isinstance(notifier.last_error, FileNotFoundError)
    assert "cannot connect" in caplog.text


def test_parse_address() -> None:
    assert parse_address("/run/systemd/notify") == "/run/systemd/notify"
    assert parse_address("@sd-notify") == "\0sd-notify"
    with pytest.raises(EncodeError, match=r"expected an absolute path or an @abstract name"):
        parse_address("")


# --- failures never escape ------------------------------------------------------------------


def test_send_failure_is_counted_and_warned_once(
    listener: Listener, caplog: pytest.LogCaptureFixture
) -> None:
    with SystemdNotifier(listener.address) as notifier:
        assert notifier.ready()
        assert listener.receive() == b"READY=1"
        listener.sock.close()  # systemd went away
        with caplog.at_level(logging.DEBUG, logger="gateway.runtime.sdnotify"):
            assert not notifier.watchdog()
            assert not notifier.watchdog()
            assert not notifier.status("still alive")
        assert notifier.errors == 3
        assert isinstance(notifier.last_error, OSError)
        warnings = [r for r in caplog.records if r.levelno == logging.WARNING]
        assert len(warnings) == 1
        assert "send failed" in warnings[0].getMessage()


@pytest.mark.timeout(10)
def test_full_receive_queue_does_not_block(listener: Listener) -> None:
    # systemd not reading: the datagram queue fills; MSG_DONTWAIT makes sends fail instead of
    # blocking the control loop (pytest-timeout would catch a hang).
    listener.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1)
    with SystemdNotifier(listener.address) as notifier:
        results = [notifier.watchdog() for _ in range(10_000)]
    assert results[0] is True
    assert results[-1] is False
    assert notifier.errors == results.count(False) > 0


def test_close_is_idempotent_and_disables(listener: Listener) -> None:
    notifier = SystemdNotifier(listener.address)
    notifier.ready()
    assert listener.pending()
    assert listener.receive() == b"READY=1"
    notifier.close()
    notifier.close()
    assert not notifier.enabled
    assert not notifier.ready()
    assert not listener.pending()


# --- watchdog period ------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("env", "expected"),
    [
        ({}, None),
        ({WATCHDOG_USEC: "1000000"}, 0.5),  # no WATCHDOG_PID: it is for us
        ({WATCHDOG_USEC: "1000000", WATCHDOG_PID: "4242"}, 0.5),  # our pid
        ({WATCHDOG_USEC: "1000000", WATCHDOG_PID: "4243"}, None),  # someone else's
        ({WATCHDOG_USEC: "3000000", WATCHDOG_PID: ""}, 1.5),
        ({WATCHDOG_USEC: "0"}, None),
        ({WATCHDOG_USEC: "-5"}, None),
        ({WATCHDOG_USEC: "1s"}, None),
        ({WATCHDOG_USEC: "1000000", WATCHDOG_PID: "me"}, None),
    ],
)
def test_watchdog_period(env: dict[str, str], expected: float | None) -> None:
    assert watchdog_period_s(env, pid=4242) == expected


def test_watchdog_period_defaults_to_our_pid(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(WATCHDOG_USEC, "200000")
    monkeypatch.setenv(WATCHDOG_PID, str(os.getpid()))
    assert watchdog_period_s() == 0.1
    monkeypatch.setenv(WATCHDOG_PID, str(os.getpid() + 1))
    assert watchdog_period_s() is None


def test_malformed_watchdog_usec_is_warned(caplog: pytest.LogCaptureFixture) -> None:
    with caplog.at_level(logging.WARNING, logger="gateway.runtime.sdnotify"):
        assert watchdog_period_s({WATCHDOG_USEC: "soon"}) is None
    assert "WATCHDOG_USEC: expected a positive integer, got 'soon'" in caplog.text


def test_from_env_reads_the_watchdog_for_its_pid(listener: Listener) -> None:
    env = {NOTIFY_SOCKET: listener.address, WATCHDOG_USEC: "1000000", WATCHDOG_PID: "7"}
    with SystemdNotifier.from_env(env, pid=7) as mine:
        assert mine.watchdog_period_s == 0.5
    env[NOTIFY_SOCKET] = listener.address
    with SystemdNotifier.from_env(env, pid=8) as other:
        assert other.watchdog_period_s is None
