"""Every number a command takes is bounded the same way (issue point "inputs are bounded the
same way in every command"): beyond its bound, NaN or infinite, a usage error with exit status
2 that names the option (and, for ``fk``, the wheel), what was expected and what came, before
anything is computed, opened or sent."""

from __future__ import annotations

from typing import TYPE_CHECKING

import pytest

import gateway.cli.commands.run as run_command
import gateway.cli.commands.sim as sim_command
from gateway.cli import main
from tests.conftest import CONFIG_DIR

if TYPE_CHECKING:
    from pathlib import Path

    from click.testing import CliRunner

MECANUM = str(CONFIG_DIR / "mecanum.yaml")
SWERVE = str(CONFIG_DIR / "swerve.yaml")
CASTOR = str(CONFIG_DIR / "differential_castor.yaml")
#: The other three mecanum wheels, at a speed within every bound.
OTHERS = ["--wheel", "front_right=1", "--wheel", "rear_left=1", "--wheel", "rear_right=1"]


def _must_not_start(*args: object, **kwargs: object) -> None:
    """Stands for what a refused command must not start (a daemon, the simulators)."""
    raise AssertionError("started with a value that should have been refused")


@pytest.mark.parametrize("value", ["1e300", "1e9", "-60"])
def test_fk_bounds_a_driven_wheel_by_its_motors_max_rpm(runner: CliRunner, value: str) -> None:
    result = runner.invoke(main, ["fk", "-c", MECANUM, "--wheel", f"front_left={value}",
                                  *OTHERS])
    assert result.exit_code == 2, result.output
    err = result.stderr
    assert "--wheel" in err and "wheel 'front_left'" in err
    # 9000 rpm at the motor through 19.2032:1 is 49.08 rad/s at the wheel.
    assert "expected a speed of at most 49.0792 rad/s either way" in err
    assert "max_rpm 9000 through gear ratio 19.2032" in err
    assert f"got {float(value):g}" in err
    assert "e+300" not in result.stdout and result.stdout == ""


def test_fk_at_the_max_rpm_is_computed(runner: CliRunner) -> None:
    result = runner.invoke(main, ["fk", "-c", MECANUM, "--wheel", "front_left=49", *OTHERS])
    assert result.exit_code == 0, result.output


def test_fk_bounds_a_passive_wheel_by_the_twist_bound(runner: CliRunner) -> None:
    result = runner.invoke(main, ["fk", "-c", CASTOR, "--wheel", "left=1", "--wheel", "right=1",
                                  "--wheel", "castor=1e6"])
    assert result.exit_code == 2, result.output
    assert "wheel 'castor'" in result.stderr
    assert "a rim speed of 100 m/s, the bound of a twist" in result.stderr


@pytest.mark.parametrize("value", ["1e300", "-3.2", "4"])
def test_fk_bounds_a_steering_angle_by_the_wheels_range(runner: CliRunner, value: str) -> None:
    result = runner.invoke(main, ["fk", "-c", SWERVE, "--wheel", "front_left=1",
                                  "--wheel", "front_right=1", "--steer", f"front_left={value}"])
    assert result.exit_code == 2, result.output
    assert "--steer" in result.stderr and "wheel 'front_left'" in result.stderr
    assert "expected a steering angle from -3.1416 to 3.1416 rad" in result.stderr
    assert f"got {float(value):g}" in result.stderr


def test_fk_takes_a_steering_angle_at_the_end_of_the_range(runner: CliRunner) -> None:
    result = runner.invoke(main, ["fk", "-c", SWERVE, "--wheel", "front_left=1",
                                  "--wheel", "front_right=1",
                                  "--steer", "front_left=3.141592653589793",
                                  "--steer", "front_right=-3.141592653589793"])
    assert result.exit_code == 0, result.output


@pytest.mark.parametrize(("option", "value", "said"), [
    ("--rate", "nan", "expected a finite number, got nan"),
    ("--duration", "nan", "expected a finite number, got nan"),
    ("--duration", "inf", "inf is not in the range 0.0<=x<=86400.0"),
    ("--duration", "1e300", "1e+300 is not in the range 0.0<=x<=86400.0"),
])
def test_twist_bounds_rate_and_duration(runner: CliRunner, tmp_path: Path, option: str,
                                        value: str, said: str) -> None:
    # The socket does not exist: a check after connecting would exit 1 instead.
    result = runner.invoke(main, ["twist", "--socket", str(tmp_path / "none.sock"),
                                  "--vx", "0.3", "--duration", "1", option, value])
    assert result.exit_code == 2, result.output
    assert option in result.stderr and said in result.stderr


def test_twist_help_gives_the_bounds(runner: CliRunner) -> None:
    text = runner.invoke(main, ["twist", "--help"]).stdout
    assert "0.0<=x<=86400.0" in text and "1.0<=x<=100.0" in text


@pytest.mark.parametrize(("value", "said"), [
    ("nan", "expected a finite number, got nan"),
    ("inf", "inf is not in the range 0.0<x<=86400.0"),
    ("1e300", "1e+300 is not in the range 0.0<x<=86400.0"),
])
def test_run_bounds_its_duration(runner: CliRunner, monkeypatch: pytest.MonkeyPatch,
                                 value: str, said: str) -> None:
    monkeypatch.setattr(run_command, "Daemon", _must_not_start)
    result = runner.invoke(main, ["run", "--sim", "--duration", value])
    assert result.exit_code == 2, result.output
    assert "--duration" in result.stderr and said in result.stderr
    assert "wheelgate: " not in result.stderr  # refused before the daemon started


@pytest.mark.parametrize(("option", "value", "said"), [
    ("--rate", "nan", "expected a finite number, got nan"),
    ("--every", "nan", "expected a finite number, got nan"),
    ("--every", "inf", "inf is not in the range 0.0<=x<=86400.0"),
    ("--every", "1e300", "1e+300 is not in the range 0.0<=x<=86400.0"),
])
def test_sim_bounds_rate_and_every(runner: CliRunner, monkeypatch: pytest.MonkeyPatch,
                                   option: str, value: str, said: str) -> None:
    monkeypatch.setattr(sim_command, "open_controllers", _must_not_start)
    result = runner.invoke(main, ["sim", option, value])
    assert result.exit_code == 2, result.output
    assert option in result.stderr and said in result.stderr
    assert "sim: ready" not in result.stdout


@pytest.mark.parametrize(("option", "value", "said"), [
    ("--min-interval-ms", "1e300", "1e+300 is not in the range 0.0<=x<=60000.0"),
    ("--min-interval-ms", "nan", "expected a finite number, got nan"),
    ("--every", "1000000000000000000000", "is not in the range 1<=x<=1000000"),
    ("--robots", "1000000000", "1000000000 is not in the range 0<=x<=100"),
])
def test_odom_bounds_its_numbers(runner: CliRunner, tmp_path: Path, option: str, value: str,
                                 said: str) -> None:
    log = tmp_path / "robot.log"
    log.write_text("")
    result = runner.invoke(main, ["odom", str(log), option, value,
                                  "--plot", str(tmp_path / "p.png")])
    assert result.exit_code == 2, result.output
    assert option in result.stderr and said in result.stderr
