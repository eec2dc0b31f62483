"""The daemon's stderr, written by a thread of its own, so that it never stalls the loop.

``wheelgate run`` logs and says its state changes on stderr from the loop's thread.  A write to
a pipe or a journald stream nobody reads blocks once the pipe is full (64 KiB on Linux): a
paused ``| less``, a stalled journald.  Then the loop stopped, the socket went unanswered and
a SIGTERM waited with it, until something read the pipe.  Here every line goes to a bounded
queue, which a daemon thread empties onto stderr; a line that finds the queue full is dropped
and counted, and the next line that finds room is preceded by one that says how many.  A
stderr that went away is pointed at ``/dev/null`` (the recipe of Python's :mod:`signal`
documentation, "Note on SIGPIPE"), as :func:`gateway.cli.commands.run.tell` does too.

This is the pattern of :class:`logging.handlers.QueueHandler` with a bounded queue that drops
instead of raising (a ``queue.Full`` would be reported on stderr itself, by the loop's thread).
"""

from __future__ import annotations

import contextlib
import logging
import os
import queue
import sys
import threading
from typing import TextIO

__all__ = ["CAPACITY", "LinePump", "PumpHandler", "point_at_devnull", "pump_logging"]

#: Lines waiting at most (beyond: dropped and counted).
CAPACITY = 10_000


class LinePump:
    """Lines for ``stream``, written by a daemon thread (see the module docstring).

    :param stream: where the lines go (the process's stderr).
    :param capacity: the most lines waiting.
    """

    def __init__(self, stream: TextIO, capacity: int = CAPACITY) -> None:
        self.stream = stream
        self._queue: queue.Queue[str | None] = queue.Queue(capacity)
        self._lock = threading.Lock()
        #: Lines dropped since the last one written (the queue was full).
        self.dropped = 0
        #: What :func:`pump_logging` moved: the root logger's handler before and after.
        self.moved: tuple[logging.Handler, logging.Handler] | None = None
        self._thread = threading.Thread(target=self._run, name="wheelgate-stderr", daemon=True)
        self._thread.start()

    def put(self, line: str) -> None:
        """Queue ``line`` (without its newline) for stderr; never blocks.  After lines were
        dropped, the first that finds room is preceded by a line that says how many."""
        with self._lock:
            try:
                if self.dropped:
                    self._queue.put_nowait(self._note())
                    self.dropped = 0
                self._queue.put_nowait(line)
            except queue.Full:
                self.dropped += 1

    def close(self, timeout_s: float = 1.0) -> None:
        """Write what is queued, and how many were dropped since, waiting at most about
        ``timeout_s`` for room; then stop the thread."""
        if self.moved is not None:  # later lines go to stderr directly again
            before, after = self.moved
            root = logging.getLogger()
            root.removeHandler(after)
            root.addHandler(before)
            self.moved = None
        with contextlib.suppress(queue.Full):
            with self._lock:
                note = self._note() if self.dropped else None
            if note is not None:
                self._queue.put(note, timeout=timeout_s)
            self._queue.put(None, timeout=timeout_s)
        self._thread.join(timeout_s)

    def _note(self) -> str:
        n = self.dropped
        return f"({n} line{'s' if n != 1 else ''} of this log dropped: stderr was not read)"

    def _run(self) -> None:
        while (line := self._queue.get()) is not None:
            try:
                self.stream.write(line + "\n")
                self.stream.flush()
            except (OSError, ValueError):  # stderr went away: the rest goes nowhere
                point_at_devnull(self.stream)


def point_at_devnull(stream: TextIO) -> None:
    """Point ``stream``'s file descriptor at ``/dev/null`` (best effort): what is still
    written, and the interpreter's last flush, then go nowhere instead of failing."""
    with contextlib.suppress(OSError, ValueError):
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, stream.fileno())
        os.close(devnull)


class PumpHandler(logging.Handler):
    """A logging handler that formats a record in the caller's thread and hands the line to a
    :class:`LinePump`."""

    def __init__(self, pump: LinePump) -> None:
        super().__init__()
        self.pump = pump

    def emit(self, record: logging.LogRecord) -> None:
        try:
            line = self.format(record)
        except Exception:  # (as logging.StreamHandler.emit: a bad record is reported)
            self.handleError(record)
            return
        self.pump.put(line)


def pump_logging() -> LinePump | None:
    """Move the root logger's stderr handler (the CLI's own) onto a :class:`LinePump`, with
    its formatter and level; ``None`` (nothing changed) when the root logger has none, as under
    a test runner that captures logging itself."""
    root = logging.getLogger()
    for handler in root.handlers:
        if (isinstance(handler, logging.StreamHandler) and type(handler) is logging.StreamHandler
                and handler.stream is sys.stderr):
            pump = LinePump(sys.stderr)
            moved = PumpHandler(pump)
            moved.setFormatter(handler.formatter)
            moved.setLevel(handler.level)
            root.removeHandler(handler)
            root.addHandler(moved)
            pump.moved = (handler, moved)
            return pump
    return None
