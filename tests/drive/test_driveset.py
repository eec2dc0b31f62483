"""One robot's drivers together: an enable is all or nothing."""

from __future__ import annotations

import pytest

from drivers.odrive import OdriveDriver
from drivers.vesc import VescDriver
from gateway.config import load_config
from gateway.core.errors import IllegalTransitionError
from gateway.drive.driveset import DriveSet
from tests.conftest import CONFIG_DIR


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
