"""The control socket's file and its peers: the socket file's mode, stale and foreign files,
creation errors, and which users may connect."""

from __future__ import annotations

import json
import os
import socket
import stat
from typing import TYPE_CHECKING

import pytest

from gateway.core.errors import ConfigError, GatewayError
from gateway.runtime.access import ControlSocketError, SocketInUseError, peer_credentials
from gateway.runtime.client import ClientError, ControlClient
from gateway.runtime.server import ControlServer
from tests.runtime import server_helpers
from tests.runtime.server_helpers import (
    WAIT_S,
    LoopThread,
    open_fds,
    poll_until,
    raw_client,
    respond,
)

if TYPE_CHECKING:
    from collections.abc import Callable
    from pathlib import Path

pytestmark = server_helpers.MARKS


# The shared fixtures (server_helpers.py), bound here so that pytest finds them.
sock_dir = server_helpers.sock_dir
sock_path = server_helpers.sock_path
server = server_helpers.server


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
