"""``wheelgate twist`` and ``wheelgate status`` against a daemon running in a thread."""

from __future__ import annotations

import json
from typing import TYPE_CHECKING

from gateway.cli import main

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
