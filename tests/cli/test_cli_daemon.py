"""``wheelgate twist`` and ``wheelgate status`` against a daemon running in a thread."""

from __future__ import annotations

import binascii
import json
import os
from typing import TYPE_CHECKING

from gateway.cli import main
from tests.conftest import CONFIG_DIR

if TYPE_CHECKING:
    from pathlib import Path

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


def test_the_daemon_names_its_file_and_a_copy_with_another_text_is_said(
        runner: CliRunner, daemon: Daemon, sock_path: str, tmp_path: Path) -> None:
    """The status names the file the daemon runs and its text's CRC-32; with -c, the same
    robot from another text is a warning (a tuned copy, an edit the daemon has not read), not
    a refusal."""
    shipped = CONFIG_DIR / "turtlebot3_burger.yaml"
    theirs = f"{binascii.crc32(shipped.read_bytes()):08x}"
    doc = json.loads(runner.invoke(main, ["status", "--socket", sock_path, "--json"]).stdout)
    assert doc["config"] == {"path": os.path.abspath(shipped), "fingerprint": theirs}
    same = runner.invoke(main, ["status", "-c", str(shipped), "--socket", sock_path])
    assert same.exit_code == 0 and "warning" not in same.stderr, same.output
    assert f"config: {os.path.abspath(shipped)}" in same.stdout.splitlines()[0]
    copy = tmp_path / "tb.yaml"
    copy.write_bytes(shipped.read_bytes() + b"# tuned on the robot\n")
    ours = f"{binascii.crc32(copy.read_bytes()):08x}"
    said = (f"the daemon runs the robot 'turtlebot3_burger' from {os.path.abspath(shipped)}, "
            f"whose text differs from {copy}'s (CRC-32 {theirs} and {ours})")
    status = runner.invoke(main, ["status", "-c", str(copy), "--socket", sock_path, "--json"])
    assert status.exit_code == 0, status.output
    assert json.loads(status.stdout)["warnings"] == [said]
    twist = runner.invoke(main, ["twist", "-c", str(copy), "--socket", sock_path, "--vx", "0.05"])
    assert twist.exit_code == 0, twist.output
    assert f"warning: {said}" in twist.stderr and "ok: following" in twist.stdout
