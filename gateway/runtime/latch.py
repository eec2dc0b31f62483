"""The e-stop latch on disk: an e-stop outlives the process that took it.

A robot that was e-stopped must not move again because its gateway crashed and was restarted
(``Restart=on-failure``, ``enable_on_start``): the latch is a small file written when the
e-stop is taken and removed only by an explicit enable.  The daemon reads it at start and, if
it is there, starts in ESTOP with the recorded reason.

Where it lives: ``gateway.state_file`` when set; else ``$STATE_DIRECTORY/estop`` (systemd sets
``STATE_DIRECTORY`` for a unit with ``StateDirectory=wheelgate``, systemd.exec(5)); else
``$XDG_STATE_HOME/wheelgate/estop-<robot>`` (``~/.local/state`` when unset, XDG Base Directory
Specification).  Writes are atomic (a temporary file renamed over the old one, then fsync of
the directory), so a crash leaves the old latch or the new one, never half of one.
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import time
from pathlib import Path

log = logging.getLogger(__name__)

#: The longest latch file read (bytes): it holds one short JSON object.
MAX_BYTES = 4096


def latch_path(state_file: str, robot: str) -> Path:
    """Where the latch of robot ``robot`` lives (see the module's doc)."""
    if state_file:
        return Path(state_file)
    state_dir = os.environ.get("STATE_DIRECTORY", "").split(":")[0]
    if state_dir:
        return Path(state_dir) / "estop"
    base = os.environ.get("XDG_STATE_HOME") or str(Path.home() / ".local" / "state")
    safe = "".join(c if c.isalnum() or c in "-_." else "_" for c in robot) or "robot"
    return Path(base) / "wheelgate" / f"estop-{safe}"


class EstopLatch:
    """The latch file of one daemon.

    :param path: the file (its directory is created when the latch is first written).
    """

    def __init__(self, path: Path) -> None:
        self.path = path
        #: The reason last written by :meth:`set` (``None`` after :meth:`clear`): the same
        #: e-stop is written once, however many paths report it.
        self._written: str | None = None
        #: The supervisor's e-stop count at the last :meth:`track` (an e-stop the daemon
        #: restored from this file counts as tracked: it is on disk already).
        self.counted = 0

    def read(self) -> str | None:
        """The reason of a latched e-stop, ``None`` when there is none.

        A latch that cannot be read or parsed still counts as latched (it stands for an
        e-stop whose record was damaged): its reason says so.
        """
        try:
            with self.path.open("rb") as f:
                data = f.read(MAX_BYTES + 1)
        except FileNotFoundError:
            return None
        except OSError as err:
            return f"e-stop latch {self.path} exists but cannot be read ({err.strerror})"
        try:
            record = json.loads(data[:MAX_BYTES])
            reason = str(record["reason"])
            since = time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(float(record["time"])))
        except (ValueError, KeyError, TypeError, OverflowError, OSError):
            return f"e-stop latch {self.path} exists but is damaged; treated as latched"
        return f"{reason} (latched since {since}, kept across restarts)"

    def track(self, estops: int, reason: str | None) -> None:
        """Write the latch for every e-stop counted since the last call, whichever path took
        it (the socket, CAN, the bridge), even one after an enable the caller never saw.

        :param estops: the supervisor's e-stop count.
        :param reason: its reason while the state is ESTOP, else ``None`` (an e-stop already
            released: nothing to write).
        """
        if estops != self.counted:
            self.counted = estops
            if reason is not None:
                self.set(reason)

    def set(self, reason: str) -> bool:
        """Write the latch (once for one e-stop: again only after :meth:`clear`).

        :return: whether it was written (a failure is logged: the e-stop itself holds in
            memory regardless).
        """
        if reason == self._written:
            return True
        tmp = self.path.with_name(self.path.name + ".tmp")
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            with tmp.open("w", encoding="utf-8") as f:
                json.dump({"reason": reason, "time": time.time()}, f)
                f.flush()
                os.fsync(f.fileno())
            tmp.replace(self.path)
            self._sync_dir()
            self._written = reason
        except OSError as err:
            log.error("e-stop latch %s could not be written (%s): the e-stop holds until this "
                      "process ends, but not across a restart", self.path, err)
            with contextlib.suppress(OSError):
                tmp.unlink(missing_ok=True)  # (no half-written file left beside it)
            return False
        return True

    def clear(self) -> None:
        """Remove the latch (an explicit enable released the e-stop)."""
        self._written = None
        try:
            self.path.unlink(missing_ok=True)
            self._sync_dir()
        except OSError as err:
            log.error("e-stop latch %s could not be removed (%s): the next start will be "
                      "e-stopped again", self.path, err)

    def _sync_dir(self) -> None:
        fd = os.open(self.path.parent, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)
