"""``wheelgate sim``: the simulated controllers as a process of their own, with the robot's
true pose; and the monitor's word on a virtual bus."""

from __future__ import annotations

import dataclasses
import json
import os
import select
import signal
import subprocess
import sys
import time
from typing import IO, TYPE_CHECKING

import pytest

from gateway.cli import main
from gateway.control import Source
from gateway.drives import DriveSet
from gateway.simtruth import SimTruth, state_line
from gateway.types import Twist
from tests.conftest import CONFIG_DIR
from tests.e2e_helpers import Rig, path_legs, virtual_config

if TYPE_CHECKING:
    from click.testing import CliRunner


@pytest.mark.parametrize("name", ["mecanum.yaml", "swerve.yaml", "ackermann.yaml"])
def test_the_sim_truth_is_the_end_to_end_truth(name: str, channel: str) -> None:
    """The pose ``wheelgate sim`` reports is the ground truth the in-process end-to-end tests
    use (exact wheel and steering angles, integrated every simulator step)."""
    cfg = virtual_config(CONFIG_DIR / name, channel, rate_hz=100.0)
    with Rig(cfg) as rig:
        truth = SimTruth(cfg, rig.gw.drives, rig.sims)
        assert truth.available
        rig.ctl.on_step = truth.update
        rig.enable()
        truth.odometry.reset()
        for twist, seconds in path_legs(cfg, "square")[:4]:
            rig.gw.twist(twist, rig.t, Source.SOCKET)
            rig.advance(min(seconds, 1.5))
        rig.gw.twist(Twist(), rig.t, Source.SOCKET)
        rig.advance(1.0)
        mine, theirs = truth.odometry.state.pose, rig.truth.state.pose
        assert rig.truth.state.distance_m > 0.3
        assert (mine.x_m, mine.y_m, mine.theta_rad) == pytest.approx(
            (theirs.x_m, theirs.y_m, theirs.theta_rad), abs=1e-9)
        state = truth.snapshot(1.0, 10, 1)
        assert state["pose"] == {"x": mine.x_m, "y": mine.y_m, "theta": mine.theta_rad}
        assert "pose x=" in state_line(state)


def test_a_wheel_steered_without_an_actuator_has_no_truth(channel: str) -> None:
    cfg = dataclasses.replace(virtual_config(CONFIG_DIR / "swerve.yaml", channel), steering=())
    drives = DriveSet(cfg)
    truth = SimTruth(cfg, drives, drives.simulators())
    assert not truth.available
    assert truth.unsimulated == ("front_left", "front_right", "rear_left", "rear_right")
    assert truth.snapshot(0.0)["pose"] is None


class Lines:
    """JSON lines of a child's stdout, read without blocking past a timeout."""

    def __init__(self, stream: IO[bytes]) -> None:
        self.fd = stream.fileno()
        self.buf = b""

    def next(self, timeout_s: float) -> dict[str, object]:
        end = time.monotonic() + timeout_s
        while b"\n" not in self.buf:
            left = end - time.monotonic()
            ready, _, _ = select.select([self.fd], [], [], max(left, 0.0))
            if not ready:
                raise AssertionError(f"no line from wheelgate sim within {timeout_s} s")
            chunk = os.read(self.fd, 65536)
            if not chunk:
                raise AssertionError("wheelgate sim closed its output")
            self.buf += chunk
        line, self.buf = self.buf.split(b"\n", 1)
        parsed: dict[str, object] = json.loads(line)
        return parsed


@pytest.mark.timeout(60)
def test_sim_process_announces_reports_on_sigusr1_and_stops_cleanly(channel: str) -> None:
    proc = subprocess.Popen(
        [sys.executable, "-m", "gateway", "--interface", "virtual", "--channel", channel, "sim",
         "-c", str(CONFIG_DIR / "swerve.yaml"), "--json", "--every", "0", "--rate", "200"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE,
    )
    try:
        assert proc.stdout is not None
        out = Lines(proc.stdout)
        lines = [out.next(30) for _ in range(9)]
        devices = [d for d in lines if d["event"] == "device"]
        assert [(d["name"], d["node_id"], d["role"]) for d in devices[:2]] == [
            ("front_left", 1, "drive"), ("front_right", 2, "drive")]
        assert sum(d["role"] == "steer" for d in devices) == 4
        ready = lines[-1]
        assert ready == {"event": "ready", "interface": "virtual", "channel": channel,
                         "devices": 8, "rate_hz": 200.0, "truth": True}
        proc.send_signal(signal.SIGUSR1)
        state = out.next(10)
        assert state["event"] == "state"
        assert state["pose"] == {"x": 0.0, "y": 0.0, "theta": 0.0}
        assert isinstance(state["steps"], int) and state["steps"] > 0
        assert len(state["devices"]) == 8  # type: ignore[arg-type]
        proc.send_signal(signal.SIGTERM)
        stopped = out.next(10)
        assert stopped["event"] == "stopped"
        assert proc.wait(timeout=10) == 0
    finally:
        if proc.poll() is None:
            proc.kill()
        _, err = proc.communicate()
    assert b"virtual bus exists only inside this process" in err


def test_monitor_on_a_virtual_bus_says_why_it_sees_nothing(runner: CliRunner,
                                                           channel: str) -> None:
    result = runner.invoke(main, ["--interface", "virtual", "--channel", channel, "monitor",
                                  "--bus", "--once", "--window", "0.1"])
    assert result.exit_code == 0, result.output
    assert "exists only inside one process" in result.stderr
    assert "--interface socketcan --channel vcan0" in result.stderr
    assert os.linesep in result.stderr
