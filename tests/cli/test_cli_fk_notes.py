"""``wheelgate fk`` says what it took for what was not given: a wheel left out when the others
fix the twist, a steering angle taken as 0 rad; and its rank error reads as one sentence."""

from __future__ import annotations

import json
from typing import TYPE_CHECKING

from gateway.cli import main
from tests.conftest import CONFIG_DIR

if TYPE_CHECKING:
    from click.testing import CliRunner

MECANUM = str(CONFIG_DIR / "mecanum.yaml")
SWERVE = str(CONFIG_DIR / "swerve.yaml")
THREE = ["--wheel", "front_left=1", "--wheel", "front_right=1", "--wheel", "rear_left=1"]


def test_a_wheel_left_out_is_named(runner: CliRunner) -> None:
    result = runner.invoke(main, ["fk", "-c", MECANUM, *THREE])
    assert result.exit_code == 0, result.output
    assert "note: not given: rear_right" in result.stderr
    assert "rear_right" not in result.stdout
    doc = json.loads(runner.invoke(main, ["fk", "-c", MECANUM, *THREE, "--json"]).stdout)
    assert doc["not_given"] == ["rear_right"] and doc["steer_taken_as_zero"] == []
    every = runner.invoke(main, ["fk", "-c", MECANUM, *THREE, "--wheel", "rear_right=1"])
    assert "note:" not in every.stderr


def test_steering_angles_taken_as_zero_are_named(runner: CliRunner) -> None:
    args = ["fk", "-c", SWERVE, *(a for w in ("front_left", "front_right", "rear_left",
                                              "rear_right") for a in ("--wheel", f"{w}=1")),
            "--steer", "rear_left=0.1"]
    result = runner.invoke(main, args)
    assert result.exit_code == 0, result.output
    assert ("note: no --steer for front_left, front_right, rear_right: steering angle taken "
            "as 0 rad") in result.stderr
    doc = json.loads(runner.invoke(main, [*args, "--json"]).stdout)
    assert doc["steer_taken_as_zero"] == ["front_left", "front_right", "rear_right"]
    assert doc["not_given"] == []


def test_the_rank_error_is_one_sentence(runner: CliRunner) -> None:
    result = runner.invoke(main, ["fk", "-c", MECANUM, "--wheel", "front_left=1"])
    assert result.exit_code == 2, result.output
    assert "Invalid value for --wheel: expected enough wheel speeds to fix the twist" \
        in result.stderr
