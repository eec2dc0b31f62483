"""The daemon's stderr never stalls its loop (:mod:`gateway.cli.stderr`): a reader that does
not read (a paused ``| less``, a stalled journald) filled the pipe, and the loop waited in a
log write -- unanswered requests, a SIGTERM that waited too."""

from __future__ import annotations

import io
import os
import signal
import subprocess
import threading
import time
from typing import TYPE_CHECKING

import pytest

from gateway.cli.stderr import LinePump
from gateway.runtime.client import ControlClient
from tests.runtime.test_daemon_limits import daemon_command, wait_running

if TYPE_CHECKING:
    from pathlib import Path


class Stuck(io.StringIO):
    """A stream whose writes wait until released."""

    def __init__(self) -> None:
        super().__init__()
        self.release = threading.Event()

    def write(self, text: str) -> int:
        self.release.wait()
        return super().write(text)


def test_the_pump_never_blocks_and_says_what_it_dropped() -> None:
    stream = Stuck()
    pump = LinePump(stream, capacity=3)
    start = time.monotonic()
    for n in range(10):
        pump.put(f"line {n}")
    assert time.monotonic() - start < 5.0  # (a blocking write would wait for ever)
    stream.release.set()
    while not pump._queue.empty():  # (the thread empties it now)
        time.sleep(0.01)
    pump.put("after")
    pump.put("last")
    pump.close()
    lines = stream.getvalue().splitlines()
    # Three queued (the thread may have taken the first, stuck in its write, and made room
    # for one more), the rest dropped, said where they were dropped.
    kept = lines.index("after") - 1
    assert lines[:kept] == [f"line {n}" for n in range(kept)] and kept in (3, 4)
    assert lines[kept:] == [
        f"({10 - kept} lines of this log dropped: stderr was not read)", "after", "last"]


@pytest.mark.timeout(120)
def test_a_stderr_nobody_reads_does_not_stall_the_loop(sock_path: str, tmp_path: Path) -> None:
    env = dict(os.environ, STATE_DIRECTORY=str(tmp_path))
    cmd = daemon_command(sock_path)
    proc = subprocess.Popen([*cmd[:3], "-v", *cmd[3:]], stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, env=env)  # never read
    try:
        wait_running(sock_path, proc)
        with ControlClient(sock_path, timeout_s=5.0) as client:
            # Each change of state a cycle sees is a few log lines (about 200 bytes a
            # disable and enable): 700 of them overfill a 64 KiB pipe.
            for _ in range(700):
                assert client.request({"op": "disable"})["ok"]
                time.sleep(0.006)
                assert client.request({"op": "enable"})["ok"]
                time.sleep(0.006)
            assert client.request({"op": "status"})["ok"]
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=10) == 0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        assert proc.stderr is not None
        proc.stderr.close()


def test_the_close_gives_the_log_its_stderr_handler_back() -> None:
    """After ``run`` the root logger writes to stderr itself again (before, its handler fed a
    queue nobody emptied any more: later lines were lost)."""
    import logging
    import sys

    from gateway.cli.stderr import PumpHandler, pump_logging

    root = logging.getLogger()
    original = logging.StreamHandler(sys.stderr)
    root.addHandler(original)
    try:
        pump = pump_logging()
        assert pump is not None
        assert original not in root.handlers
        assert any(isinstance(h, PumpHandler) for h in root.handlers)
        pump.close()
        assert original in root.handlers
        assert not any(isinstance(h, PumpHandler) for h in root.handlers)
    finally:
        root.removeHandler(original)
