"""Access control of the control socket: its file, and who may connect through it.

In order:

1. **File mode.**  The socket file is chmod-ed to ``mode`` (default ``0o660``: owner and group)
   before ``listen()``, so no client can connect through a wider mode in between.  Put the
   users allowed to drive the robot in the socket's group; this is the first line of defence
   and the only one on systems without ``SO_PEERCRED``.
2. **Peer credentials** (Linux ``SO_PEERCRED``), when ``allowed_uids`` is given: a client whose
   uid is neither listed nor the server's own is closed at once and counted in ``refused``.
   Root is not implicitly allowed; list uid 0 if it should be.

The socket file is only ever replaced when it is a socket nobody listens on, and removed on
close only while it is still the one :func:`listen` created.  The connections themselves are
handled by :class:`gateway.runtime.server.ControlServer`.
"""

from __future__ import annotations

import logging
import os
import socket
import stat
import struct
from dataclasses import dataclass
from typing import TYPE_CHECKING

from gateway.core.errors import ConfigError, GatewayError

if TYPE_CHECKING:
    from pathlib import Path

log = logging.getLogger(__name__)

#: Longest socket path in bytes: ``sun_path`` is 108 bytes on Linux, NUL included.
MAX_SOCKET_PATH_BYTES = 107

_UCRED = struct.Struct("=iII")  # struct ucred: pid_t pid; uid_t uid; gid_t gid


class ControlSocketError(GatewayError, OSError):
    """The control socket cannot be created or used; the message names the path."""


class SocketInUseError(ControlSocketError):
    """Another process listens on the control socket path, or the path is not a socket."""


@dataclass(frozen=True, slots=True)
class PeerCredentials:
    """The process at the other end of a Unix socket, as the kernel saw it at connect time."""

    pid: int
    uid: int
    gid: int


def peer_credentials(sock: socket.socket) -> PeerCredentials | None:
    """The peer's credentials by ``SO_PEERCRED``; ``None`` where the platform lacks it."""
    option = getattr(socket, "SO_PEERCRED", None)
    if option is None:
        return None
    try:
        raw = sock.getsockopt(socket.SOL_SOCKET, option, _UCRED.size)
    except OSError:
        return None
    return PeerCredentials(*_UCRED.unpack(raw))


def admitted_uids(allowed_uids: frozenset[int] | None) -> frozenset[int] | None:
    """The uids a server admits by ``SO_PEERCRED``: the listed ones and the process's own.

    :param allowed_uids: uids allowed besides the server's own; ``None`` leaves access control
        to the file mode.
    :return: ``None`` when ``allowed_uids`` is ``None``.
    :raises ConfigError: for ``allowed_uids`` on a platform without ``SO_PEERCRED``.
    """
    if allowed_uids is None:
        return None
    if not hasattr(socket, "SO_PEERCRED"):
        raise ConfigError(
            "control socket allowed_uids: expected a platform with SO_PEERCRED (Linux), "
            f"got {os.name}; rely on the socket's file mode instead"
        )
    return frozenset(allowed_uids) | {os.getuid()}


def check_socket_path(path: Path) -> None:
    """Refuse a path longer than ``sun_path`` can hold.

    :raises ControlSocketError: naming the path, the limit and its length.
    """
    size = len(os.fsencode(path))
    if size > MAX_SOCKET_PATH_BYTES:
        raise ControlSocketError(
            f"control socket {path}: expected a path of at most "
            f"{MAX_SOCKET_PATH_BYTES} bytes (the AF_UNIX limit), got {size}"
        )


def remove_stale_socket(path: Path) -> None:
    """Remove a socket file nobody listens on; refuse if somebody does or it is no socket."""
    try:
        st = os.lstat(path)
    except FileNotFoundError:
        return
    except OSError as err:
        raise ControlSocketError(f"control socket {path}: cannot inspect it: {err}") from err
    if not stat.S_ISSOCK(st.st_mode):
        raise SocketInUseError(
            f"control socket {path}: expected a socket or nothing, got an existing "
            "non-socket file; refusing to replace it"
        )
    probe = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    try:
        probe.setblocking(False)
        probe.connect(str(path))
    except ConnectionRefusedError:
        log.info("control socket %s: removing a stale socket file", path)
        path.unlink(missing_ok=True)
        return
    except FileNotFoundError:
        return
    except BlockingIOError:  # a listener whose backlog is full: alive
        pass
    except OSError as err:
        raise ControlSocketError(f"control socket {path}: cannot probe it: {err}") from err
    finally:
        probe.close()
    raise SocketInUseError(
        f"control socket {path}: another process is listening on it "
        "(is another `wheelgate run` running?)"
    )


def listen(path: Path, mode: int, backlog: int) -> tuple[socket.socket, tuple[int, int]]:
    """Bind, chmod, then listen -- so no connection can happen under a wider mode."""
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    bound = False
    try:
        sock.bind(str(path))
        bound = True
        st = os.lstat(path)
        os.chmod(path, mode)
        sock.listen(backlog)
        sock.setblocking(False)
    except OSError as err:
        sock.close()
        if bound:
            path.unlink(missing_ok=True)
        raise ControlSocketError(f"control socket {path}: cannot create it: {err}") from err
    return sock, (st.st_dev, st.st_ino)


def remove_own_socket(path: Path, identity: tuple[int, int]) -> None:
    """Remove the socket file if it is still the one :func:`listen` created (same device and
    inode); leave whatever has replaced it alone.  Never raises."""
    try:
        st = os.lstat(path)
        if (st.st_dev, st.st_ino) == identity:
            path.unlink()
    except OSError:
        pass
