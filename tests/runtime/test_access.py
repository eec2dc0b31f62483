"""Access to the daemon: only permitted local users reach the control socket, and the daemon
listens on no network address.

* File mode: the socket is created ``0660`` (``socket_mode``); a user outside the owner and
  group -- here uid/gid 65534 in a forked child, so these tests need root -- is refused by
  the kernel at ``connect()`` with ``0660`` and ``0600``, and admitted with ``0666``.
* Peer credentials (``socket_uids``): a uid not listed is closed at once and counted in
  ``refused``; a listed one is served.
* Network: ``wheelgate run --sim`` as a process holds no socket that appears in
  ``/proc/net/{tcp,tcp6,udp,udp6}``; its only listening socket is the control socket, in
  ``/proc/net/unix``.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import socket
import stat
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import TYPE_CHECKING

import pytest

from gateway.runtime.client import ClientError, ControlClient
from tests.e2e_helpers import Rig, virtual_config

if TYPE_CHECKING:
    from collections.abc import Callable, Iterator

pytestmark = pytest.mark.timeout(60)

NOBODY = 65534
WAIT_S = 10.0  # upper bound of every wait; the tests pass far sooner
needs_root = pytest.mark.skipif(os.geteuid() != 0, reason="needs root to act as another user")


@pytest.fixture
def sock_dir() -> Iterator[Path]:
    """A short private directory that other users may traverse (not list)."""
    path = Path(tempfile.mkdtemp(prefix="wg", dir="/tmp"))
    path.chmod(0o711)
    try:
        yield path
    finally:
        shutil.rmtree(path, ignore_errors=True)


def run_as_nobody(action: Callable[[], str], rig: Rig) -> str:
    """Run ``action`` in a forked child as uid/gid 65534 while the rig's loop runs here."""
    read_fd, write_fd = os.pipe()
    pid = os.fork()
    if pid == 0:  # the child: report through the pipe and leave without any cleanup
        os.close(read_fd)
        try:
            os.setgroups([])
            os.setgid(NOBODY)
            os.setuid(NOBODY)
            out = action()
        except BaseException as err:
            out = f"{type(err).__name__}: {err}"
        os.write(write_fd, out.encode())
        os._exit(0)
    os.close(write_fd)
    os.set_blocking(read_fd, False)
    chunks = []
    try:
        deadline = time.monotonic() + WAIT_S
        while True:
            try:
                chunk = os.read(read_fd, 65536)
            except BlockingIOError:
                assert time.monotonic() < deadline, "the child never reported"
                rig.advance(rig.period)  # serve the child meanwhile
                time.sleep(0.001)
                continue
            if not chunk:
                break
            chunks.append(chunk)
    finally:
        os.close(read_fd)
        os.waitpid(pid, 0)
    return b"".join(chunks).decode()


def status_with_client(path: Path) -> str:
    """Connect with the CLI's client and ask for the state (or the client's error)."""
    try:
        with ControlClient(path, timeout_s=WAIT_S) as client:
            return str(client.request({"op": "status"})["state"])
    except ClientError as err:
        return f"ClientError: {err}"


def status_raw(path: Path) -> str:
    """Connect with a plain socket; the reply line, or ``eof`` if the server hung up."""
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as sock:
        sock.settimeout(WAIT_S)
        sock.connect(str(path))
        sock.sendall(b'{"op": "status", "id": 7}\n')
        data = b""
        try:
            while not data.endswith(b"\n") and (chunk := sock.recv(65536)):
                data += chunk
        except ConnectionResetError:
            pass
        return data.decode() or "eof"


def rig_with(sock_dir: Path, channel: str, **loop: object) -> Rig:
    return Rig(virtual_config(None, channel, rate_hz=100.0, **loop), str(sock_dir / "s.sock"))


# -- file mode -------------------------------------------------------------------------------


@needs_root
@pytest.mark.parametrize("mode", [None, 0o600])
def test_socket_mode_denies_other_users(sock_dir: Path, channel: str, mode: int | None) -> None:
    loop = {} if mode is None else {"socket_mode": mode}
    with rig_with(sock_dir, channel, **loop) as rig:
        path = sock_dir / "s.sock"
        assert stat.S_IMODE(os.stat(path).st_mode) == (0o660 if mode is None else mode)
        assert os.stat(path).st_uid == 0
        out = run_as_nobody(lambda: status_with_client(path), rig)
        assert out == (f"ClientError: permission denied for {path} "
                       "(is your user in the socket's group?)")
        assert rig.daemon is not None
        assert rig.daemon.server.counters.accepted == 0
        assert _serve(rig, lambda: status_with_client(path)) == "disabled"  # the owner


@needs_root
def test_socket_mode_0666_admits_other_users(sock_dir: Path, channel: str) -> None:
    with rig_with(sock_dir, channel, socket_mode=0o666) as rig:
        out = run_as_nobody(lambda: status_with_client(sock_dir / "s.sock"), rig)
        assert out == "disabled"


def _serve(rig: Rig, call: Callable[[], str]) -> str:
    """Run a blocking client call in a thread while the rig's loop serves it here."""
    result: list[str] = []
    thread = threading.Thread(target=lambda: result.append(call()))
    thread.start()
    deadline = time.monotonic() + WAIT_S
    while thread.is_alive():
        assert time.monotonic() < deadline, "no reply"
        rig.advance(rig.period)
        thread.join(0.001)
    assert result, "the client call failed"
    return result[0]


# -- peer credentials ------------------------------------------------------------------------


@needs_root
def test_socket_uids_refuse_a_uid_not_listed(sock_dir: Path, channel: str) -> None:
    with rig_with(sock_dir, channel, socket_mode=0o666, socket_uids=(NOBODY - 1,)) as rig:
        out = run_as_nobody(lambda: status_raw(sock_dir / "s.sock"), rig)
        assert out == "eof"
        assert rig.daemon is not None
        counters = rig.daemon.server.counters
        assert (counters.refused, counters.accepted) == (1, 0)


@needs_root
def test_socket_uids_admit_a_listed_uid(sock_dir: Path, channel: str) -> None:
    with rig_with(sock_dir, channel, socket_mode=0o666, socket_uids=(NOBODY,)) as rig:
        out = run_as_nobody(lambda: status_raw(sock_dir / "s.sock"), rig)
        reply = json.loads(out)
        assert (reply["ok"], reply["id"], reply["state"]) == (True, 7, "disabled")
        assert rig.daemon is not None
        assert rig.daemon.server.counters.refused == 0


# -- no network listener ---------------------------------------------------------------------

#: ``/proc/net/{tcp,udp}[6]``: sl, local, remote, st, queues, tr, retrnsmt, uid, timeout, inode
_NET_LINE = re.compile(r"^\s*\d+:\s+\S+\s+\S+\s+\S+\s+\S+\s+\S+\s+\S+\s+\d+\s+\d+\s+(\d+)")


def net_inodes(table: str) -> set[int]:
    """The socket inodes of a ``/proc/net/{tcp,tcp6,udp,udp6}`` table."""
    out = set()
    for line in table.splitlines()[1:]:
        match = _NET_LINE.match(line)
        if match:
            out.add(int(match.group(1)))
    return out


def unix_listeners(table: str) -> dict[int, str]:
    """inode -> path of the listening sockets in ``/proc/net/unix`` (flag __SO_ACCEPTCON)."""
    out = {}
    for line in table.splitlines()[1:]:
        fields = line.split()
        if len(fields) >= 8 and int(fields[3], 16) & 0x10000:
            out[int(fields[6])] = fields[7]
    return out


def socket_inodes(pid: int) -> set[int]:
    """The inodes of every socket process ``pid`` holds."""
    out = set()
    for fd in os.listdir(f"/proc/{pid}/fd"):
        try:
            target = os.readlink(f"/proc/{pid}/fd/{fd}")
        except FileNotFoundError:  # closed meanwhile
            continue
        if target.startswith("socket:["):
            out.add(int(target[8:-1]))
    return out


def network_inodes() -> set[int]:
    out: set[int] = set()
    for name in ("tcp", "tcp6", "udp", "udp6"):
        table = Path(f"/proc/net/{name}")
        if table.exists():
            out |= net_inodes(table.read_text())
    return out


def test_the_proc_tables_are_read_right() -> None:
    """The check below can fail: a TCP listener and a UDP socket of ours are found."""
    with (
        socket.socket(socket.AF_INET, socket.SOCK_STREAM) as tcp,
        socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as udp,
        socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as unix,
        tempfile.TemporaryDirectory(prefix="wg", dir="/tmp") as folder,
    ):
        tcp.bind(("127.0.0.1", 0))
        tcp.listen()
        udp.bind(("127.0.0.1", 0))
        unix.bind(f"{folder}/u.sock")
        unix.listen()
        mine = socket_inodes(os.getpid())
        inode = {s: os.fstat(s.fileno()).st_ino for s in (tcp, udp, unix)}
        assert set(inode.values()) <= mine
        found = network_inodes()
        assert inode[tcp] in found and inode[udp] in found
        assert inode[unix] not in found
        assert unix_listeners(Path("/proc/net/unix").read_text())[inode[unix]] == \
            f"{folder}/u.sock"


def test_daemon_listens_on_no_network_address(sock_dir: Path) -> None:
    path = sock_dir / "s.sock"
    env = {k: v for k, v in os.environ.items() if k not in ("NOTIFY_SOCKET", "WATCHDOG_USEC")}
    proc = subprocess.Popen(
        [sys.executable, "-m", "gateway", "run", "--sim", "--socket", str(path)],
        env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
    )
    try:
        deadline = time.monotonic() + 30.0
        while True:
            assert proc.poll() is None, proc.communicate()[1].decode()
            try:
                with ControlClient(path) as client:
                    if client.request({"op": "status"})["state"] == "running":
                        break
            except ClientError:
                pass
            assert time.monotonic() < deadline, "the daemon did not come up"
            time.sleep(0.1)
        held = socket_inodes(proc.pid)
        listeners = unix_listeners(Path("/proc/net/unix").read_text())
        network = network_inodes()
    finally:
        proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(timeout=WAIT_S)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
            if proc.stderr is not None:
                proc.stderr.close()
    assert held, "the daemon holds no socket at all"
    assert not held & network, f"sockets on a network address: {sorted(held & network)}"
    mine = {inode: p for inode, p in listeners.items() if inode in held}
    assert list(mine.values()) == [str(path)]
    assert proc.returncode == 0
