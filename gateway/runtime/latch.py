"""The e-stop latch on disk: an e-stop outlives the process that took it.

A robot that was e-stopped must not move again because its gateway crashed and was restarted
(``Restart=on-failure``, ``enable_on_start``): the latch is a small file written when the
e-stop is taken and removed only by an explicit enable.  The daemon reads it at start and, if
it is there, starts in ESTOP with the recorded reason.

Where it lives: ``gateway.state_file`` when set; else ``$STATE_DIRECTORY/estop`` (systemd sets
``STATE_DIRECTORY`` for a unit with ``StateDirectory=wheelgate``, systemd.exec(5)); else
``$XDG_STATE_HOME/wheelgate/estop-<robot>`` (``~/.local/state`` when unset, XDG Base Directory
Specification).  Writes are atomic (a temporary file renamed over the old one), so a crashed
process leaves the old latch or the new one, never half of one.

Durable, off the loop: the caller (the loop thread) only writes and renames, which the page
cache takes at once; the fsyncs of the file and of its directory, which a slow SD card can stall
for seconds, run in a short thread of their own (:meth:`EstopLatch.wait_durable` waits for them;
the daemon does at its close).  A power cut before they end may lose the latch or leave it empty
(the rename reached the disk before the data): an empty or damaged latch reads as latched, so
the worst case is the e-stop that was never written, as a power cut a moment earlier.
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import threading
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
        #: The fsync threads not yet waited for (see :meth:`wait_durable`).
        self._syncs: list[threading.Thread] = []

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
        """Write the latch (once for one e-stop: again only after :meth:`clear`); made durable
        in the background.

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
            tmp.replace(self.path)
            self._written = reason
        except OSError as err:
            log.error("e-stop latch %s could not be written (%s): the e-stop holds until this "
                      "process ends, but not across a restart", self.path, err)
            with contextlib.suppress(OSError):
                tmp.unlink(missing_ok=True)  # (no half-written file left beside it)
            return False
        self._sync(file=True)
        return True

    def clear(self) -> None:
        """Remove the latch (an explicit enable released the e-stop); made durable in the
        background."""
        self._written = None
        try:
            self.path.unlink(missing_ok=True)
        except OSError as err:
            log.error("e-stop latch %s could not be removed (%s): the next start will be "
                      "e-stopped again", self.path, err)
            return
        self._sync(file=False)

    def wait_durable(self, timeout_s: float = 5.0) -> bool:
        """Wait up to ``timeout_s`` for the fsyncs started so far.

        :return: whether they all ended (a failed one is logged, and counts as ended; one
            still running is logged).
        """
        end = time.monotonic() + timeout_s
        for thread in self._syncs:
            thread.join(max(0.0, end - time.monotonic()))
        self._syncs = [t for t in self._syncs if t.is_alive()]
        if self._syncs:
            log.warning("e-stop latch %s: still not flushed to disk after %g s", self.path,
                        timeout_s)
        return not self._syncs

    def _sync(self, *, file: bool) -> None:
        # (Started by the loop thread, it inherits its SCHED_FIFO, as the simulators' thread
        # does: it holds the GIL for microseconds and waits for the disk without it.)
        self._syncs = [t for t in self._syncs if t.is_alive()]
        thread = threading.Thread(target=self._fsync, args=(file,), daemon=True,
                                  name="wheelgate-latch-sync")
        self._syncs.append(thread)
        thread.start()

    def _fsync(self, file: bool) -> None:
        """The file's fsync (when it was written), then its directory's: in a thread."""
        try:
            if file:
                with contextlib.suppress(FileNotFoundError):  # (cleared since: nothing to keep)
                    _fsync_path(self.path)
            _fsync_path(self.path.parent)
        except OSError as err:
            log.error("e-stop latch %s: %s, but not flushed to disk (%s): a power cut now may "
                      "undo it", self.path, "written" if file else "removed", err)


def _fsync_path(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)
