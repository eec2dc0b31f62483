"""Calibration and braking as ros2_control users know them: ``kinematics:`` multipliers on the
track and on each wheel's radius, and a deceleration limit apart from the acceleration one,
judged on what reaches the simulated controllers."""

from __future__ import annotations

import dataclasses
import itertools
import math
from typing import TYPE_CHECKING

import pytest

from gateway.config import load_config
from gateway.core.control import Source
from gateway.core.errors import ConfigError
from gateway.core.types import Twist
from tests.conftest import CONFIG_DIR
from tests.e2e_helpers import Rig, virtual_config
from tests.runtime.safety_helpers import commanded

if TYPE_CHECKING:
    from pathlib import Path

TB3 = CONFIG_DIR / "turtlebot3_burger.yaml"  # wheel_radius 0.033, track 0.160


def calibrated(tmp_path: Path, kinematics: str) -> Path:
    path = tmp_path / "tb3.yaml"
    path.write_text(TB3.read_text() + f"kinematics: {kinematics}\n")
    return path


def test_multipliers_scale_the_track_and_each_radius_in_the_model(tmp_path: Path) -> None:
    cfg = load_config(calibrated(
        tmp_path, "{wheel_separation_multiplier: 1.25, wheel_radius_multipliers: {left: 1.1}}"))
    left, right = cfg.model.wheels
    assert (left.radius, right.radius) == pytest.approx((0.033 * 1.1, 0.033))
    assert (left.l, right.l) == pytest.approx((0.1, 0.1))  # half of 0.160 x 1.25
    assert cfg.geometry["track"] == 0.160  # as written; the model has the correction
    assert dict(cfg.calibration) == {"radius left": 1.1, "wheel_separation_multiplier": 1.25}
    # Inverse and forward kinematics both use it: a turn in place needs wheel speeds
    # +-(track/2) * wz / radius, and the wheels' speeds give the twist back.
    ik = cfg.model.ik(Twist(0.0, 0.0, 1.0))
    assert ik.wheel_rad_s == pytest.approx((-0.1 / (0.033 * 1.1), 0.1 / 0.033))
    assert cfg.model.fk(ik.wheel_rad_s).twist.wz_rad_s == pytest.approx(1.0)
    assert not load_config(TB3).calibration


def test_a_calibrated_radius_changes_what_the_controller_is_told(
    tmp_path: Path, channel: str
) -> None:
    cfg = virtual_config(calibrated(tmp_path, "{wheel_radius_multipliers: {left: 1.05}}"),
                         channel, rate_hz=100.0)
    with Rig(cfg) as rig:
        rig.enable()
        for _ in range(10):
            rig.gw.twist(Twist(0.1), rig.t, Source.SOCKET)
            rig.advance(0.2)
        left, right = commanded(rig)
    # TB3's right motor is inverted: the simulator reports its wheel in the robot's sense.
    assert (left, right) == pytest.approx((0.1 / (0.033 * 1.05), 0.1 / 0.033), rel=1e-5)


@pytest.mark.parametrize(("kinematics", "expected"), [
    ("{wheel_radius_multipliers: {lefft: 1.01}}", "did you mean 'left'?"),
    ("{wheel_radius_multipliers: {left: 3}}", "expected a factor from 0.5 to 2.0, got 3"),
    ("{wheel_radius_multipliers: [1.01, 0.99]}", "expected dict, got"),
    ("{wheel_separation_multiplier: 0.1}", "wheel_separation_multiplier: expected at least"),
])
def test_bad_multipliers_name_the_key_and_what_was_expected(
    tmp_path: Path, kinematics: str, expected: str
) -> None:
    with pytest.raises(ConfigError, match=expected) as info:
        load_config(calibrated(tmp_path, kinematics))
    assert "kinematics.wheel_" in str(info.value)


def test_the_separation_multiplier_needs_a_drive_with_a_track(tmp_path: Path) -> None:
    path = tmp_path / "omni.yaml"
    path.write_text((CONFIG_DIR / "omni3.yaml").read_text()
                    + "kinematics: {wheel_separation_multiplier: 1.1}\n")
    with pytest.raises(ConfigError, match="expected a drive with a track"):
        load_config(path)


def test_braking_follows_the_deceleration_limit_on_the_bus(channel: str) -> None:
    cfg = virtual_config(TB3, channel, rate_hz=100.0)
    cfg = dataclasses.replace(cfg, limits=dataclasses.replace(
        cfg.limits, max_wheel_accel_rad_s2=10.0, max_wheel_decel_rad_s2=40.0))
    history: list[tuple[float, ...]] = []
    with Rig(cfg) as rig:
        rig.enable()
        for _ in range(4):  # renewed within the command timeout (0.5 s)
            rig.gw.twist(Twist(0.15), rig.t, Source.SOCKET)
            rig.advance(0.2, lambda r: history.append(commanded(r)))
        cruise = len(history)
        rig.gw.twist(Twist(), rig.t, Source.SOCKET)
        rig.advance(0.3, lambda r: history.append(commanded(r)))
    up = [max(abs(a - b) for a, b in zip(x, y, strict=True))
          for x, y in itertools.pairwise(history[:cruise])]
    down = [max(abs(a - b) for a, b in zip(x, y, strict=True))
            for x, y in itertools.pairwise(history[cruise - 1:])]
    # 100 Hz: at most 0.1 rad/s a cycle up, 0.4 down (float32 on the wire: each speed below
    # 5 rad/s within 3e-7, so a difference within 1e-6).
    assert max(up) <= 0.1 + 1e-6 and max(down) <= 0.4 + 1e-6, (max(up), max(down))
    assert max(up) == pytest.approx(0.1, rel=1e-4) and max(down) == pytest.approx(0.4, rel=1e-4)
    assert history[-1] == (0.0, 0.0)
    assert math.isclose(abs(history[cruise - 1][0]), 0.15 / 0.033, rel_tol=1e-5)
