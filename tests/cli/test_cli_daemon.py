"""``wheelgate twist`` and ``wheelgate status`` against a daemon running in a thread."""

from __future__ import annotations

import json
from typing import TYPE_CHECKING

from gateway.cli import main
from tests.conftest import CONFIG_DIR

if TYPE_CHECKING:

    from click.testing import CliRunner

    from gateway.runtime.daemon import Daemon


def test_twist_and_status(runner: CliRunner, daemon: Daemon, sock_path: str) -> None:
    result = runner.invoke(main, ["twist", "--socket", sock_path, "--vx", "0.1", "--wz", "0.5",
                                  "--duration", "0.5", "--rate", "20"])
    assert result.exit_code == 0, result.output
    assert "ok: following" in result.stdout
    result = runner.invoke(main, ["status", "--socket", sock_path, "--json"])
    assert result.exit_code == 0, result.output
    doc = json.loads(result.stdout)
    assert doc["state"] == "running"
    assert doc["odometry"]["distance"] > 0.01
    assert [m["name"] for m in doc["motors"]] == ["left", "right"]
    assert doc["timing"]["cycles"] > 10
    # Every twist's latency runs from reading it to its cycle's wheel burst: at most a period
    # (the cycle it waits for) plus the cycle, never negative.
    timing = doc["timing"]
    assert timing["latency_samples"] >= 5
    assert 0.0 < timing["latency_p50_us"] <= timing["latency_max_us"] < 1e6
    assert doc["tracking"]["time_s"] == 0.5 and doc["tracking"]["worst_ratio"] >= 0.0
    result = runner.invoke(main, ["status", "--socket", sock_path])
    assert result.exit_code == 0, result.output
    assert "state: running" in result.stdout
    assert "of the window (1 rad/s + 20 % of the command, 0.5 s)" in result.stdout
    assert "odometry: x=" in result.stdout


def test_twist_errors(runner: CliRunner, daemon: Daemon, sock_path: str) -> None:
    result = runner.invoke(main, ["twist", "--socket", sock_path, "--vy", "0.1"])
    assert result.exit_code == 3
    assert "breaks its sliding constraint" in result.stderr
    result = runner.invoke(main, ["twist", "--socket", sock_path, "--vx", "inf"])
    assert result.exit_code == 2


def test_no_daemon_is_a_clear_error(runner: CliRunner, sock_path: str) -> None:
    result = runner.invoke(main, ["status", "--socket", sock_path])
    assert result.exit_code == 1
    assert sock_path in result.stderr


def test_another_robots_config_is_refused_for_motion_and_warned_for_status(
        runner: CliRunner, daemon: Daemon, sock_path: str) -> None:
    """The daemon runs the TurtleBot: a twist given with the mecanum's configuration would
    drive the wrong robot."""
    mecanum = str(CONFIG_DIR / "mecanum.yaml")
    result = runner.invoke(main, ["twist", "-c", mecanum, "--socket", sock_path, "--vx", "0.1"])
    assert result.exit_code == 2, result.output
    assert "runs the robot 'turtlebot3_burger', not 'mecanum'" in result.stderr
    assert "refusing to drive it" in result.stderr
    status = runner.invoke(main, ["status", "-c", mecanum, "--socket", sock_path])
    assert status.exit_code == 0, status.output
    assert "warning: the daemon on this socket runs the robot 'turtlebot3_burger'" in status.stderr
    same = runner.invoke(main, ["twist", "-c", str(CONFIG_DIR / "turtlebot3_burger.yaml"),
                                "--socket", sock_path, "--vx", "0.1"])
    assert same.exit_code == 0, same.output
