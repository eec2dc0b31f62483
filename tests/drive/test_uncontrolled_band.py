"""Wheel speeds a controller does not speed-control (a VESC below its minimum ERPM): reported
by ``ik`` and ``check``, counted in ``status``, and expected as a stopped wheel by the
tracking check, on the shipped tub robot (7 pole pairs, 5:1, factory s_pid_min_erpm 900:
below 2.69 rad/s at the wheel)."""

from __future__ import annotations

import json
import math
from typing import TYPE_CHECKING

import pytest

from gateway.cli import main
from gateway.config import load_config
from gateway.core.settings import TrackingLimits
from gateway.core.tracking import TrackingFault, TrackingMonitor
from gateway.core.types import WheelFeedback
from gateway.drive.driveset import DriveSet
from tests.conftest import CONFIG_DIR

if TYPE_CHECKING:
    from click.testing import CliRunner

TUB = CONFIG_DIR / "differential_tub.yaml"
HIGH = 900.0 / (5.0 * 7.0) * math.tau / 60.0  # rad/s at the wheel


def test_the_drive_set_gives_each_wheels_band() -> None:
    bands = DriveSet(load_config(TUB)).uncontrolled_bands()
    assert len(bands) == 2
    for band in bands:
        assert band is not None
        assert band[0] == 0.0
        assert band[1] == pytest.approx(HIGH, rel=1e-9)
    assert DriveSet(load_config(CONFIG_DIR / "turtlebot3_burger.yaml")).uncontrolled_bands() \
        == [None, None]


def test_ik_and_check_report_the_band(runner: CliRunner) -> None:
    slow = runner.invoke(main, ["ik", "-c", str(TUB), "--vx", "0.1", "--wz", "0", "--json"])
    assert slow.exit_code == 0, slow.output
    wheels = json.loads(slow.output)["wheels"]
    assert [w["not_speed_controlled"]["below_rad_s"] for w in wheels] == pytest.approx(
        [HIGH, HIGH])
    text = runner.invoke(main, ["ik", "-c", str(TUB), "--vx", "0.1", "--wz", "0"]).output
    assert "note: wheel 'left' at 1 rad/s is below its controller's slowest controlled speed" \
        in text
    fast = runner.invoke(main, ["ik", "-c", str(TUB), "--vx", "0.5", "--wz", "0", "--json"])
    assert all("not_speed_controlled" not in w for w in json.loads(fast.output)["wheels"])
    check = runner.invoke(main, ["check", "-c", str(TUB)]).output
    assert "wheel 'left': |speed| below 2.693 rad/s (0.269 m/s) is not speed-controlled" in check


def test_tracking_expects_a_stopped_wheel_in_the_band() -> None:
    """A wheel commanded 2 rad/s that stands still is no fault in the band, and a wheel that
    turns at 2 rad/s there (not what the controller does) is one."""
    limits = TrackingLimits(0.5, 0.2, 0.5)
    banded = TrackingMonitor(limits)
    banded.dead_bands = [(0.0, HIGH)]
    plain = TrackingMonitor(limits)
    faults: dict[str, TrackingFault | None] = {"banded": None, "plain": None, "turning": None}
    turning = TrackingMonitor(limits)
    turning.dead_bands = [(0.0, HIGH)]
    for k in range(100):
        t = k * 0.01
        still = [WheelFeedback(0.0, 0.0, t)]
        faults["banded"] = faults["banded"] or banded.check([2.0], still, t)
        faults["plain"] = faults["plain"] or plain.check([2.0], still, t)
        moving = [WheelFeedback(0.0, 2.0, t)]
        faults["turning"] = faults["turning"] or turning.check([2.0], moving, t)
    assert faults["banded"] is None
    assert faults["plain"] is not None
    assert faults["turning"] is not None
