"""Inputs the CLI takes: twist components bounded the same way in every command (the control
socket's bound: beyond it, or not finite, a usage error with exit status 2, before anything is
computed or sent), the twist command's account of what the robot follows, what ``ik``
imports (start-up), and numpy's BLAS threads."""

from __future__ import annotations

import ast
import os
import subprocess
import sys
from typing import TYPE_CHECKING

import pytest

from gateway.cli import main
from gateway.cli.commands.twist import following
from gateway.core.types import MAX_TWIST_COMPONENT

if TYPE_CHECKING:
    from click.testing import CliRunner


@pytest.mark.parametrize("command", [["ik"], ["frames"], ["twist", "--socket", "/nonexistent/s"]])
@pytest.mark.parametrize(("option", "value"), [
    ("--vx", "1e300"), ("--vy", "-1e9"), ("--wz", str(MAX_TWIST_COMPONENT * 1.01)),
    ("--vx", "nan"), ("--wz", "inf"),
])
def test_a_twist_beyond_the_bound_is_a_usage_error(
        runner: CliRunner, command: list[str], option: str, value: str) -> None:
    result = runner.invoke(main, [*command, option, value])
    assert result.exit_code == 2, result.output
    assert option in result.output


def test_a_twist_at_the_bound_is_computed(runner: CliRunner) -> None:
    result = runner.invoke(main, ["ik", "--vx", str(MAX_TWIST_COMPONENT), "--json"])
    assert result.exit_code == 0, result.output


def test_the_twist_command_says_what_the_robot_follows_and_why() -> None:
    reply = {"ok": True, "twist": {"vx_m_s": 5.0, "vy_m_s": 0.0, "wz_rad_s": 0.0},
             "projected": False, "applied": {"vx_m_s": 1.5, "vy_m_s": -2.776e-17,
                                             "wz_rad_s": -0.0},
             "limited_by": "max_linear_m_s 1.5 m/s"}
    asked = {"vx_m_s": 5.0, "vy_m_s": 0.0, "wz_rad_s": 0.0}
    assert following(reply, asked) == (
        "ok: following vx 1.5 m/s, vy 0 m/s, wz 0 rad/s (asked vx 5 m/s, vy 0 m/s, wz 0 rad/s; "
        "limited by max_linear_m_s 1.5 m/s)")
    plain = {**reply, "applied": reply["twist"], "limited_by": None}
    assert following(plain, asked) == "ok: following vx 5 m/s, vy 0 m/s, wz 0 rad/s"


def test_ik_loads_nothing_it_does_not_use() -> None:
    """Start-up is measured in tools/bench_anchor.py; this guards its cheapest losses: the
    bridge's and the socket's wire formats, python-can, Zenoh, the optional blocks' settings,
    the odometry, the tracking check and difflib are not imported to compute wheel speeds."""
    code = ("import sys\nfrom gateway.cli import main\n"
            "try:\n    main(['ik', '--vx', '0.1'])\nexcept SystemExit:\n    pass\n"
            "print(sorted(sys.modules))\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=60, check=True)
    loaded = set(ast.literal_eval(done.stdout.strip().splitlines()[-1]))
    unwanted = {"can", "zenoh", "foxglove", "gateway.wire.ros2", "gateway.wire.socket",
                "gateway.config.bridge", "gateway.core.bridge_settings", "gateway.runtime",
                "importlib.resources", "zipfile", "tempfile", "gateway.core.kinematics.odometry",
                "gateway.core.tracking", "difflib"}
    assert not unwanted & loaded, sorted(unwanted & loaded)


@pytest.mark.parametrize(("given", "expected"), [(None, "1"), ("2", "2")])
def test_the_cli_runs_numpy_without_blas_worker_threads(given: str | None, expected: str) -> None:
    """OPENBLAS_NUM_THREADS is 1 before numpy loads (no worker threads, which a locked daemon
    would lock too), unless the environment says otherwise."""
    env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_NUM_THREADS"}
    if given is not None:
        env["OPENBLAS_NUM_THREADS"] = given
    code = ("import os\nimport gateway.cli\nimport numpy\n"
            "print(os.environ['OPENBLAS_NUM_THREADS'], len(os.listdir('/proc/self/task')))\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=60, check=True, env=env)
    value, threads = done.stdout.split()
    assert value == expected
    if given is None:
        assert threads == "1"  # (OpenBLAS starts no worker on a 1-CPU machine either way)


@pytest.mark.parametrize("args", [
    ["status", "--socket", ""], ["twist", "--socket", ""], ["check", "-c", ""],
    ["run", "--sim", "--record", ""], ["odom", "--csv", "", "x.log"],
])
def test_an_empty_path_is_a_usage_error_naming_the_option(
        runner: CliRunner, args: list[str]) -> None:
    # (click takes '' as a path: an empty --socket quietly meant the default socket.)
    result = runner.invoke(main, args)
    assert result.exit_code == 2, result.output
    option = args[args.index("") - 1]
    assert f"'{option}'" in result.output and "expected a path, got an empty string" in \
        result.output
