"""A command on a real pseudo-terminal, for the screens of ``jog`` and ``monitor``.

The child runs on the slave side of a pty of a given size (its stdin and stdout are terminals,
so it takes raw or cbreak mode and fits its screen); the test writes keys to the master side
and reads back what was drawn.  Every wait is bounded; :meth:`Pty.close` kills the child.
"""

from __future__ import annotations

import fcntl
import os
import re
import select
import struct
import subprocess
import termios
import time
from typing import TYPE_CHECKING

from tests.conftest import REPO

if TYPE_CHECKING:
    from collections.abc import Callable, Mapping

#: An ANSI control sequence (cursor, erase, colour).
ANSI = re.compile(r"\x1b\[[0-9;?]*[A-Za-z]")
#: Where a frame of ``jog`` begins and ends, and where one of ``monitor`` begins.
JOG_FRAME = ("\x1b[H", "\x1b[J")
MONITOR_FRAME = "\x1b[H\x1b[2J"


class Pty:
    """``command`` running on a pseudo-terminal of ``cols`` x ``rows``.

    :param env: changes to the environment (``None``: remove the variable); ``COLUMNS`` and
        ``LINES`` are always removed, so the terminal's own size counts.
    :param cleared: each frame begins with a clear (``monitor``), rather than being enclosed
        in home and erase-below (``jog``).
    """

    def __init__(self, command: list[str], cols: int = 140, rows: int = 50,
                 env: Mapping[str, str | None] | None = None, cleared: bool = False) -> None:
        self.cleared = cleared
        environ = {k: v for k, v in os.environ.items() if k not in ("COLUMNS", "LINES")}
        for key, value in (env or {}).items():
            if value is None:
                environ.pop(key, None)
            else:
                environ[key] = value
        master, slave = os.openpty()
        try:
            fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", rows, cols, 0, 0))
            self.proc = subprocess.Popen(
                command, stdin=slave, stdout=slave, stderr=slave, cwd=REPO, env=environ,
                start_new_session=True,
            )
        except BaseException:
            os.close(master)
            raise
        finally:
            os.close(slave)
        self.fd = master
        self.raw = b""
        self.eof = False

    def pump(self, timeout_s: float) -> None:
        """Read whatever the child wrote within ``timeout_s``."""
        if self.eof:
            time.sleep(timeout_s)
            return
        ready, _, _ = select.select([self.fd], [], [], timeout_s)
        if ready:
            try:
                chunk = os.read(self.fd, 65536)
            except OSError:  # EIO: every slave descriptor is closed, the child is gone
                chunk = b""
            self.raw += chunk
            self.eof = not chunk

    @property
    def text(self) -> str:
        """Everything written, escape codes removed."""
        return ANSI.sub("", self.raw.decode("utf-8", "replace")).replace("\r", "")

    def raw_screen(self) -> str:
        """The last complete frame as written, escape codes and all: between ``ESC [ H`` and
        ``ESC [ J`` (``jog``), or between the last two clears (``monitor``)."""
        text = self.raw.decode("utf-8", "replace")
        if not self.cleared:
            end = text.rfind(JOG_FRAME[1])
            start = text.rfind(JOG_FRAME[0], 0, max(end, 0))
            return "" if start < 0 else text[start + len(JOG_FRAME[0]):end]
        end = text.rfind(MONITOR_FRAME)
        start = text.rfind(MONITOR_FRAME, 0, max(end, 0))
        return "" if start < 0 else text[start + len(MONITOR_FRAME):end]

    def screen(self) -> str:
        """The last complete frame as the user sees it (escape codes removed)."""
        return ANSI.sub("", self.raw_screen()).replace("\r", "")

    def wait_for(self, what: str, check: Callable[[str], bool], timeout_s: float = 8.0) -> str:
        """Pump until ``check(screen)`` holds; the screen then."""
        end = time.monotonic() + timeout_s
        while time.monotonic() < end:
            self.pump(0.05)
            if check(self.screen()):
                return self.screen()
        raise AssertionError(f"timed out waiting for {what}; screen:\n{self.screen()}\n"
                             f"output tail:\n{self.text[-2000:]}")

    def send(self, keys: bytes) -> None:
        os.write(self.fd, keys)

    def hold(self, key: bytes, seconds: float, every_s: float = 0.04) -> None:
        """Auto-repeat: ``key`` every ``every_s`` for ``seconds``, reading meanwhile."""
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.send(key)
            self.pump(every_s)

    def wait_exit(self, timeout_s: float = 10.0) -> int:
        end = time.monotonic() + timeout_s
        while self.proc.poll() is None and time.monotonic() < end:
            self.pump(0.05)
        code = self.proc.wait(timeout=max(0.1, end - time.monotonic()))
        while not self.eof:
            self.pump(0.05)
        return code

    def close(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait(timeout=5)
        os.close(self.fd)
