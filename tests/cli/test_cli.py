"""The CLI as a user types it: check, ik, fk; exit codes 0, 2, 3."""

from __future__ import annotations

import json
import math
from typing import TYPE_CHECKING

import pytest

from gateway.cli import main
from tests.conftest import CONFIG_DIR

if TYPE_CHECKING:
    from pathlib import Path

    from click.testing import CliRunner

TB3 = str(CONFIG_DIR / "turtlebot3_burger.yaml")
MECANUM = str(CONFIG_DIR / "mecanum.yaml")
ACKERMANN = str(CONFIG_DIR / "ackermann.yaml")


def test_check_summarises_the_robot(runner: CliRunner) -> None:
    result = runner.invoke(main, ["check", "-c", TB3])
    assert result.exit_code == 0, result.output
    out = result.stdout
    assert "drive:    differential (wheel_radius=0.033 track=0.16)" in out
    assert "freedom:  mobility 2, steerability 0, maneuverability 2" in out
    assert "left" in out and "right" in out
    assert "odrive node 1" in out
    assert out.rstrip().endswith("ok")


def test_check_embedded_default(runner: CliRunner) -> None:
    result = runner.invoke(main, ["check"])
    assert result.exit_code == 0, result.output
    assert "config:   <embedded default>" in result.stdout


def test_ik_table_and_json(runner: CliRunner) -> None:
    result = runner.invoke(main, ["ik", "-c", TB3, "--vx", "0.2", "--wz", "1.0"])
    assert result.exit_code == 0, result.output
    assert "left" in result.stdout
    result = runner.invoke(main, ["ik", "-c", TB3, "--vx", "0.1", "--wz", "0.5", "--json"])
    assert result.exit_code == 0, result.output
    doc = json.loads(result.stdout)
    wheels = {w["name"]: w for w in doc["wheels"]}
    assert wheels["left"]["speed_rad_s"] == pytest.approx((0.1 - 0.08 * 0.5) / 0.033)
    assert wheels["right"]["speed_rad_s"] == pytest.approx((0.1 + 0.08 * 0.5) / 0.033)
    assert "steer_rad" not in wheels["left"]
    assert wheels["right"]["motor_rpm"] == pytest.approx(
        -wheels["right"]["speed_rad_s"] * 60 / (2 * math.pi)  # inverted motor
    )


def test_ik_steered_wheels_report_steer_rad(runner: CliRunner) -> None:
    result = runner.invoke(main, ["ik", "-c", ACKERMANN, "--vx", "1", "--wz", "0.5", "--json"])
    assert result.exit_code == 0, result.output
    wheels = {w["name"]: w for w in json.loads(result.stdout)["wheels"]}
    assert wheels["front_left"]["steer_rad"] > wheels["front_right"]["steer_rad"] > 0
    assert wheels["front_left"]["motor_rpm"] is None  # passive front wheels


def test_ik_infeasible_exits_3(runner: CliRunner) -> None:
    result = runner.invoke(main, ["ik", "-c", TB3, "--vx", "0.1", "--vy", "0.1"])
    assert result.exit_code == 3
    assert result.stdout == ""
    assert result.stderr.startswith(
        "Error: Twist (vx=0.1 m/s, vy=0.1 m/s, wz=0 rad/s) is infeasible: wheel 'left' "
        "breaks its sliding constraint by 0.1 m/s"
    )
    assert "nearest feasible twist is (vx=0.1 m/s" in result.stderr


def test_ik_infeasible_json_error_object(runner: CliRunner) -> None:
    result = runner.invoke(main, ["ik", "-c", ACKERMANN, "--wz", "1", "--json"])
    assert result.exit_code == 3
    doc = json.loads(result.stdout)
    assert doc["ok"] is False and not result.stderr
    err = doc["error"]
    assert err["code"] == "infeasible_twist" and "type" not in err
    assert err["message"].startswith("Twist (vx=0 m/s, vy=0 m/s, wz=1 rad/s) is infeasible")
    assert err["constraint"] == "steering limit"
    assert err["wheel"] in ("front_left", "front_right")
    assert err["nearest"]["vx_m_s"] > 0


def test_ik_speed_limit_note(runner: CliRunner) -> None:
    result = runner.invoke(main, ["ik", "-c", TB3, "--vx", "1.0"])
    assert result.exit_code == 0
    assert "exceeds a speed limit; the gateway scales it by 0.21" in result.stdout


def test_fk(runner: CliRunner) -> None:
    result = runner.invoke(
        main, ["fk", "-c", TB3, "--wheel", "left=3", "--wheel", "right=5", "--json"]
    )
    assert result.exit_code == 0, result.output
    doc = json.loads(result.stdout)
    assert doc["twist"]["vx_m_s"] == pytest.approx(0.033 * 4)
    assert doc["twist"]["wz_rad_s"] == pytest.approx(0.033 * 2 / 0.16)
    assert doc["residual_m_s"] == pytest.approx(0.0, abs=1e-12)
    result = runner.invoke(main, ["fk", "-c", MECANUM, "--wheel", "front_left=1",
                                  "--wheel", "front_right=1", "--wheel", "rear_left=1",
                                  "--wheel", "rear_right=-1"])
    assert result.exit_code == 0, result.output
    assert "residual:" in result.stdout


def test_fk_with_steering(runner: CliRunner) -> None:
    ik = json.loads(runner.invoke(main, ["ik", "-c", str(CONFIG_DIR / "swerve.yaml"),
                                         "--vx", "0.3", "--vy", "0.2", "--wz", "0.4",
                                         "--json"]).stdout)
    args = ["fk", "-c", str(CONFIG_DIR / "swerve.yaml"), "--json"]
    for w in ik["wheels"]:
        args += ["--wheel", f"{w['name']}={w['speed_rad_s']}",
                 "--steer", f"{w['name']}={w['steer_rad']}"]
    twist = json.loads(runner.invoke(main, args).stdout)["twist"]
    assert (twist["vx_m_s"], twist["vy_m_s"], twist["wz_rad_s"]) == pytest.approx((0.3, 0.2, 0.4))


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["ik", "-c", TB3, "--vx", "fast"],
         "Invalid value for '--vx': 'fast' is not a valid float"),
        (["ik", "-c", TB3, "--vx", "nan"], "Invalid value for --vx: expected a finite number"),
        (["fk", "-c", TB3, "--wheel", "left"], "Invalid value for --wheel: expected NAME=NUMBER"),
        (["fk", "-c", TB3, "--wheel", "middle=1"], "Unknown wheel 'middle'; expected one of: "
                                                  "left, right"),
        (["fk", "-c", TB3, "--wheel", "left=1", "--steer", "left=1"],
         "wheel 'left' is not steered"),
        (["fk", "-c", TB3], "give at least one wheel speed"),
        (["ik", "-c", "missing.yaml"], "Error: missing.yaml: cannot read the file"),
        (["frobnicate"], "No such command 'frobnicate'"),
    ],
)
def test_bad_usage_exits_2(runner: CliRunner, args: list[str], message: str) -> None:
    result = runner.invoke(main, args)
    assert result.exit_code == 2, result.output
    assert message in result.stderr


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["scan", "--json", "--timeout", "-1"], "Invalid value for '--timeout': expected "
                                                "seconds above 0"),
        (["status", "--json", "--bogus"], "No such option '--bogus'"),
        (["spin", "--speed", "x", "--json", "left"], "Invalid value for '--speed'"),
    ],
)
def test_command_line_errors_of_a_json_command_are_json(
        runner: CliRunner, args: list[str], message: str) -> None:
    """click's own parse errors come before the command runs; with --json they are still
    one JSON document on stdout (exit 2), without usage lines; without --json, as click
    prints them."""
    result = runner.invoke(main, args)
    assert result.exit_code == 2, result.output
    doc = json.loads(result.stdout)
    assert doc["ok"] is False and doc["error"]["code"] == "bad_usage"
    assert message in doc["error"]["message"] and not result.stderr
    plain = runner.invoke(main, [a for a in args if a != "--json"])
    assert plain.exit_code == 2 and message in plain.stderr and "Usage:" in plain.stderr
    # A command without --json keeps click's answer to the flag itself; "--json" as another
    # option's value or after "--" is not the flag.
    assert "No such option '--json'" in runner.invoke(main, ["check", "--json"]).stderr
    for not_asked in (["status", "--socket", "--json", "--bogus"], ["odom", "--", "--json"]):
        other = runner.invoke(main, not_asked)
        assert other.exit_code == 2 and not other.stdout and "Usage:" in other.stderr, not_asked


def test_bad_config_exits_2(runner: CliRunner, tmp_path: Path) -> None:
    bad = tmp_path / "robot.yaml"
    bad.write_text("drive: differential\ngeometry: {wheel_radius: 0.1}\n")
    result = runner.invoke(main, ["check", "-c", str(bad)])
    assert result.exit_code == 2
    # every problem at once: the motors: block is checked on the wheels the geometry names
    assert result.stderr == (f"Error: {bad}: geometry.track: required key is missing\n"
                             f"{bad}: motors: required key is missing (a motor block for each "
                             f"driven wheel: left, right)\n")


def test_debug_shows_traceback(runner: CliRunner) -> None:
    result = runner.invoke(main, ["--debug", "ik", "-c", TB3, "--vy", "1"])
    assert result.exit_code == 1
    assert type(result.exception).__name__ == "InfeasibleTwistError"


def test_shell_completion_offers_every_command_and_option() -> None:
    # The README's completion lines (click's _WHEELGATE_COMPLETE protocol) as the shell calls
    # them: every subcommand for "wheelgate ", a command's own options for "wheelgate run --s".
    import os
    import subprocess
    import sys

    from gateway.cli import COMMANDS

    def complete(words: str) -> list[str]:
        env = {**os.environ, "_WHEELGATE_COMPLETE": "bash_complete", "COMP_WORDS": words,
               "COMP_CWORD": str(len(words.split()) - (0 if words.endswith(" ") else 1))}
        done = subprocess.run(
            [sys.executable, "-c", "import sys; from gateway.cli import main; "
             "sys.exit(main(prog_name='wheelgate'))"],
            env=env, capture_output=True, text=True, timeout=30, check=True)
        return [line.split(",", 1)[1] for line in done.stdout.splitlines()]

    assert set(complete("wheelgate ")) == set(COMMANDS)
    assert {"--sim", "--socket"} <= set(complete("wheelgate run --s"))
    # values: init's examples and drives, its drivers, spin's motors of the -c robot
    assert complete("wheelgate init --drive om") == ["omni", "omni3", "omni3_swedish",
                                                     "omni_delta"]
    assert set(complete("wheelgate init --driver ")) == {"cia402", "dbc", "dji", "odrive",
                                                         "vesc"}
    assert complete(f"wheelgate spin -c {CONFIG_DIR / 'swerve.yaml'} front_l") == [
        "front_left", "front_left_steering"]
    source = subprocess.run(
        [sys.executable, "-c", "import sys; from gateway.cli import main; "
         "sys.exit(main(prog_name='wheelgate'))"],
        env={**os.environ, "_WHEELGATE_COMPLETE": "bash_source"}, capture_output=True,
        text=True, timeout=30, check=True).stdout
    assert "_wheelgate_completion" in source and "complete " in source
