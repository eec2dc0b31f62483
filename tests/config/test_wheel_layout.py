"""A layout whose driven wheels cannot tell a motion apart (gateway.config.wheels.wheel_layout):
refused when they cannot at all, a warning when they barely can; every shipped robot is sound.

The case is a typo that passed every earlier check: the right wheel of a differential drive
written as a copy of the left wheel's line (same alpha and beta).  ``ik --wz 0.5`` then turned
both wheels alike, which drives the robot backwards instead of turning it."""

from __future__ import annotations

from typing import TYPE_CHECKING

import pytest
import yaml

from gateway.cli import main
from gateway.config import load_config, parse_config
from gateway.core.errors import ConfigError
from tests.conftest import CONFIG_DIR

if TYPE_CHECKING:
    from pathlib import Path

    from click.testing import CliRunner

CASTOR = CONFIG_DIR / "differential_castor.yaml"


def _typo(right_l: float) -> dict[str, object]:
    """differential_castor.yaml with its right wheel at the left wheel's angles."""
    raw = yaml.safe_load(CASTOR.read_text())
    assert isinstance(raw, dict)
    right = raw["wheels"][1]
    assert right["name"] == "right"
    right.update(alpha=raw["wheels"][0]["alpha"], beta=raw["wheels"][0]["beta"], l=right_l)
    return raw


@pytest.mark.parametrize("path", sorted(CONFIG_DIR.glob("*.yaml")), ids=lambda p: p.stem)
def test_no_shipped_robot_is_warned_about(path: Path) -> None:
    assert not [w for w in load_config(path).warnings if ": wheels: " in w]


def test_wheels_that_cannot_tell_a_turn_from_standing_still_are_refused() -> None:
    with pytest.raises(ConfigError) as info:
        parse_config(_typo(0.2), "robot.yaml")
    assert str(info.value) == (
        "robot.yaml: wheels: turning about the point x 0 m, y 0.2 m of the body frame (the "
        "twist (vx=0.6247 m/s, vy=0 m/s, wz=3.1235 rad/s), its fastest wheel at 1 m/s) turns "
        "no driven wheel and no fixed or steerable wheel resists it, so wheelgate could "
        "neither drive nor measure it; expected driven wheels that tell every motion apart: "
        "check each wheel's position and angles (REP-103: x forward, y left, angles "
        "counter-clockwise; `wheelgate check` lists them); wheels 'left' and 'right' are "
        "mounted 0 mm apart")


def test_wheels_that_barely_tell_it_are_a_warning() -> None:
    cfg = parse_config(_typo(0.2001), "robot.yaml")
    said = [w for w in cfg.warnings if ": wheels: " in w]
    assert said == [
        "robot.yaml: wheels: turning about the point x 0 m, y 0.2001 m of the body frame (the "
        "twist (vx=0.6248 m/s, vy=0 m/s, wz=3.1232 rad/s), its fastest wheel at 1 m/s) turns "
        "the driven wheels, or pushes the fixed or steerable ones sideways, by at most "
        "0.16 mm/s, so odometry would read a wheel-speed error of 1 mm/s as up to 6,403 mm/s "
        "of motion (a sound layout: 1 to 2 mm/s); check each wheel's position and angles "
        "(REP-103: x forward, y left, angles counter-clockwise; `wheelgate check` lists them); "
        "wheels 'left' and 'right' are mounted 0.1 mm apart"]
    # 5 mm apart: a pair is named only closer than 1 % of the farthest wheel (2.5 mm);
    # 1 cm apart: noticed at 16 mm/s per 1 m/s, above the warning's 10
    odd = parse_config(_typo(0.205), "robot.yaml").warnings
    assert [w for w in odd if "by at most 7.8 mm/s" in w and "mounted" not in w]
    assert not [w for w in parse_config(_typo(0.21), "r.yaml").warnings if ": wheels: " in w]


def test_check_warns_and_ik_and_run_refuse(runner: CliRunner, tmp_path: Path) -> None:
    near, same = tmp_path / "near.yaml", tmp_path / "same.yaml"
    near.write_text(yaml.safe_dump(_typo(0.2001)))
    same.write_text(yaml.safe_dump(_typo(0.2)))
    result = runner.invoke(main, ["check", "-c", str(near)])
    assert result.exit_code == 0, result.output
    assert f"warning:  {near}: wheels: turning about the point" in result.stdout
    for args in (["check"], ["ik", "--wz", "0.5"], ["run", "--sim", "--duration", "0.1"]):
        result = runner.invoke(main, [args[0], "-c", str(same), *args[1:]])
        assert result.exit_code == 2, (args, result.output)
        assert result.stderr.startswith(f"Error: {same}: wheels: turning about the point "
                                        f"x 0 m, y 0.2 m"), args
