"""One robot's drivers together: an enable is all or nothing, and a failed one is named in
the order of the statuses."""

from __future__ import annotations

import pytest

from drivers.odrive import OdriveDriver
from drivers.vesc import VescDriver
from gateway.config import load_config, parse_config
from gateway.core.errors import IllegalTransitionError
from gateway.drive.driveset import DriveSet
from tests.conftest import CONFIG_DIR, MIXED_ROBOT


def test_a_refused_enable_leaves_no_driver_enabled(monkeypatch: pytest.MonkeyPatch) -> None:
    # The Ackermann robot: VESC drive motors first, then an ODrive steering actuator.
    drives = DriveSet(load_config(CONFIG_DIR / "ackermann.yaml"))
    (vesc, _), (odrive, _) = drives.groups
    assert isinstance(vesc, VescDriver) and isinstance(odrive, OdriveDriver)

    def refuse(now_s: float) -> list[object]:
        raise IllegalTransitionError("axis calibrating")

    monkeypatch.setattr(odrive, "enable", refuse)
    with pytest.raises(IllegalTransitionError, match="axis calibrating"):
        drives.enable(0.0)
    # The VESCs got no enable frame: they must not be kept alive with SET_RPM either.
    assert vesc.poll(0.5) == []
    assert vesc.poll(1.0) == []


def test_enable_failed_is_given_in_status_order(monkeypatch: pytest.MonkeyPatch) -> None:
    """``DriveSet.enable_failed`` names the motors whose sequence failed by their position in
    ``status`` (model order here), whichever driver reports them."""
    drives = DriveSet(parse_config(MIXED_ROBOT, "<mixed>"))
    vesc, odrive = (drv for drv, _ in drives.groups)
    assert [m.wheel for m in vesc.motors] == ["front_left", "rear_left"]
    assert drives.enable_failed() == []
    monkeypatch.setattr(vesc, "enable_failed", lambda: [1])
    assert [drives.status(0.0)[i].name for i in drives.enable_failed()] == ["rear_left"]
    monkeypatch.setattr(odrive, "enable_failed", lambda: [0, 1])
    assert [drives.status(0.0)[i].name for i in drives.enable_failed()] == [
        "front_right", "rear_left", "rear_right"]


def test_a_driver_that_cannot_build_its_stop_leaves_the_others_stop(
    monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    drives = DriveSet(load_config(CONFIG_DIR / "ackermann.yaml"))
    (vesc, _), (odrive, _) = drives.groups
    own = odrive.disable(0.0)
    assert own

    def broken(now_s: float) -> list[object]:
        raise ZeroDivisionError("float divmod()")  # a defect, not a GatewayError

    monkeypatch.setattr(vesc, "disable", broken)
    assert drives.disable(0.0) == own
    assert "VescDriver could not build the stop of 'rear_left', 'rear_right'" in caplog.text
    assert "ZeroDivisionError: float divmod()" in caplog.text
