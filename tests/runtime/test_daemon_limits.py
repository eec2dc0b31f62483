"""The daemon as a process at the edges of its environment: systemd's default open-file limit
with more idle connections than ``max_clients``, and a stderr whose reader went away."""

from __future__ import annotations

import contextlib
import os
import resource
import socket
import subprocess
import sys
import time
from typing import TYPE_CHECKING

import can
import pytest
from click.testing import CliRunner

from drivers.odrive.driver import OdriveDriver
from gateway.cli import main
from gateway.core.types import GatewayState
from gateway.runtime.client import ControlClient
from tests.e2e_helpers import Rig, virtual_config
from tests.runtime.safety_helpers import TB3

if TYPE_CHECKING:
    from pathlib import Path

#: Each starts the daemon as a process.
pytestmark = pytest.mark.timeout(60)

#: systemd's default soft RLIMIT_NOFILE for services (the hard one is higher).
SYSTEMD_SOFT_NOFILE = 1024


def daemon_command(sock_path: str, *args: str) -> list[str]:
    return [sys.executable, "-m", "gateway", "run", "--sim", "--socket", sock_path, *args]


def wait_running(sock_path: str, proc: subprocess.Popen[bytes]) -> None:
    end = time.monotonic() + 30
    while True:
        assert proc.poll() is None, "the daemon ended"
        with contextlib.suppress(OSError):
            with ControlClient(sock_path, timeout_s=2.0) as client:
                if client.request({"op": "status"})["state"] == "running":
                    return
        assert time.monotonic() < end, "the daemon did not start"
        time.sleep(0.1)


def test_an_estop_gets_through_more_idle_connections_than_systemds_file_limit(
    sock_path: str,
) -> None:
    """Before, with the soft limit at 1024 (systemd's default) and max_clients 1024, accept()
    failed with EMFILE before max_clients: the estop's connection stayed in the backlog,
    unanswered, and every poll logged a warning (2,792 lines in 7 s)."""
    idle_count = SYSTEMD_SOFT_NOFILE + 76
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    need = idle_count + 100
    if hard != resource.RLIM_INFINITY and hard < need:
        pytest.skip(f"needs {need} file descriptors, the hard limit is {hard}")

    def systemd_limit() -> None:
        resource.setrlimit(resource.RLIMIT_NOFILE, (SYSTEMD_SOFT_NOFILE, hard))

    proc = subprocess.Popen(daemon_command(sock_path), preexec_fn=systemd_limit,  # noqa: PLW1509
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    idle: list[socket.socket] = []
    try:
        if soft < need:
            resource.setrlimit(resource.RLIMIT_NOFILE, (need, hard))
        wait_running(sock_path, proc)
        for _ in range(idle_count):
            sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
            idle.append(sock)
            sock.connect(sock_path)
        time.sleep(1.0)
        with ControlClient(sock_path, timeout_s=5.0) as client:
            reply = client.request({"op": "estop"})
        assert reply["ok"] is True and reply["state"] == "estop"
        proc.terminate()
        assert proc.wait(timeout=10) == 0
    finally:
        for sock in idle:
            sock.close()
        resource.setrlimit(resource.RLIMIT_NOFILE, (soft, hard))
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        _, err = proc.communicate()
    assert err.decode().count("accept failed") <= 2, err.decode()[-2000:]


def test_a_stderr_whose_reader_went_away_does_not_end_the_daemon(
    sock_path: str, tmp_path: Path
) -> None:
    """``wheelgate run --sim 2> fifo`` whose reader closes: before, the next line for the
    person (the motors running, or stopped) raised BrokenPipeError and the daemon ended with
    status 1 (its zero and disarm sent all the same)."""
    record = tmp_path / "run.log"
    proc = subprocess.Popen(daemon_command(sock_path, "--record", str(record), "--duration", "3"),
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        assert proc.stderr is not None
        first = proc.stderr.readline()
        assert first.startswith(b"wheelgate: "), first
        proc.stderr.close()  # the reader goes away: every later write to stderr fails
        code = proc.wait(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert code == 0
    # It ran, and stopped as it should: the motors' last frames were zero and disarm.
    sent = [m for m in can.LogReader(str(record)) if not m.is_rx]
    idle_state = [m for m in sent if m.arbitration_id & 0x1F == 0x07
                  and bytes(m.data[:4]) == b"\x01\x00\x00\x00"]
    assert idle_state, "no disarm (Set_Axis_State IDLE) sent"
    assert not os.path.exists(sock_path)


def test_an_announcement_that_cannot_be_written_does_not_stop_the_loop(
    channel: str, sock_path: str
) -> None:
    """The daemon's own guard, whatever writes its announcements: an OSError from one is
    ignored (before, it ended the loop)."""

    def broken(line: str) -> None:
        raise BrokenPipeError(32, "Broken pipe")

    with Rig(virtual_config(TB3, channel, rate_hz=100.0), sock_path) as rig:
        assert rig.daemon is not None
        rig.daemon.announce = broken
        rig.enable()  # DISABLED -> ENABLING -> RUNNING: the "running on" line
        rig.gw.supervisor.disable()
        rig.advance(0.05)
        assert rig.gw.state is GatewayState.DISABLED


def test_a_drive_failing_in_the_shutdown_grace_still_closes_the_daemon(
    channel: str, sock_path: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The stop goes out first; a drive's step that raises while the shutdown waits for the
    replies is logged and the daemon still closes (its socket file goes)."""
    from gateway.core.errors import IllegalTransitionError

    def refuse(now_s: float) -> list[object]:
        raise IllegalTransitionError("axis calibrating")

    with Rig(virtual_config(TB3, channel, rate_hz=100.0), sock_path) as rig:
        assert rig.daemon is not None
        rig.enable()
        monkeypatch.setattr(rig.gw.drives, "poll", refuse)
        assert os.path.exists(sock_path)
        rig.daemon.shutdown()
        assert not os.path.exists(sock_path)
        rig.daemon.shutdown()  # (twice: nothing left to do)


@pytest.mark.parametrize("bus_takes_it", [True, False])
def test_the_shutdown_says_whether_its_stop_went_out(
    channel: str, sock_path: str, monkeypatch: pytest.MonkeyPatch,
    caplog: pytest.LogCaptureFixture, bus_takes_it: bool,
) -> None:
    """``run``'s last line says "every motor was sent zero and disarm" only when the bus took
    every frame of it (a bus gone at SIGTERM took none, and the line said it anyway)."""
    with Rig(virtual_config(TB3, channel, rate_hz=100.0), sock_path) as rig:
        assert rig.daemon is not None
        rig.enable()
        if not bus_takes_it:
            monkeypatch.setattr(rig.gw.edge, "send", lambda *a, **k: False)
        rig.daemon.shutdown()
        assert rig.daemon.stop_sent is bus_takes_it
        said = "the zero and disarm did not all go out: the bus refused them" in caplog.text
        assert said is not bus_takes_it


def test_the_shutdown_does_not_say_sent_when_a_driver_built_no_stop(
    channel: str, sock_path: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A driver that fails to build its stop (a defect) leaves its wheels without one: the
    shutdown says so (``stop_sent`` false, the wheels in ``drives.unstopped``), though the bus
    took every frame that was built."""
    with Rig(virtual_config(TB3, channel, rate_hz=100.0), sock_path) as rig:
        assert rig.daemon is not None
        rig.enable()
        (drv, _), = rig.gw.drives.groups

        def broken(now_s: float) -> list[object]:
            raise ZeroDivisionError("float divmod()")

        monkeypatch.setattr(drv, "disable", broken)
        rig.daemon.shutdown()
        assert rig.daemon.stop_sent is False
        assert rig.gw.drives.unstopped == tuple(m.wheel for m in drv.motors)


def test_runs_last_line_names_the_wheels_without_a_stop(
    sock_path: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``run``'s last line names the wheels whose driver built no stop, not "every motor was
    sent zero and disarm" (it said so whatever the drivers did)."""
    def broken(self: OdriveDriver, now_s: float) -> list[object]:
        raise ZeroDivisionError("float divmod()")

    monkeypatch.setattr(OdriveDriver, "disable", broken)
    result = CliRunner().invoke(main, ["run", "--sim", "--socket", sock_path, "--duration",
                                       "0.5"])
    assert result.exit_code == 0, result.output
    assert ("stopped; no stop could be built for 'front_left', 'front_right', 'rear_left', "
            "'rear_right': only their controllers' own timeouts stop them") in result.stderr
