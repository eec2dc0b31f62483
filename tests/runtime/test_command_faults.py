"""A command a controller's field cannot hold is a fault that names it, never an exception out
of the cycle: the daemon keeps running and the wheels are stopped."""

from __future__ import annotations

import re
import shutil
from typing import TYPE_CHECKING
from unittest import mock

from gateway.core.types import ErrorCode, GatewayState, Twist
from tests.conftest import CONFIG_DIR
from tests.e2e_helpers import Rig, errors_on_can, virtual_config

if TYPE_CHECKING:
    from pathlib import Path


def test_a_speed_beyond_the_controllers_field_faults_instead_of_crashing(
    tmp_path: Path, channel: str
) -> None:
    # The example controller's Target_Velocity holds +-10000 rpm (its DBC's signal range); a
    # max_rpm of 12000 lets the limits pass 11000 rpm, which the codec refuses to encode.
    # Binding refuses such a configuration (drivers.dbc.binding.check_command): this test
    # needs the check off, as a driver without one would be, to reach the loop's safety net.
    shutil.copy(CONFIG_DIR / "example_controller.dbc", tmp_path)
    text = (CONFIG_DIR / "example_dbc.yaml").read_text().replace("max_rpm: 4000",
                                                                 "max_rpm: 12000")
    text = re.sub(r"^limits:\n(  .*\n)*", "", text, flags=re.MULTILINE)  # replaced below
    path = tmp_path / "robot.yaml"
    path.write_text(text + "limits: {max_linear_m_s: 10.0, max_wheel_accel_rad_s2: 100000.0}\n")
    with mock.patch("drivers.dbc.binding.check_command"):
        cfg = virtual_config(path, channel, rate_hz=100.0)
        rig = Rig(cfg)
    with rig:
        rig.enable()
        rig.send_can_twist(Twist(1.0, 0.0, 0.0))
        rig.advance(0.3)
        assert rig.gw.supervisor.state is GatewayState.RUNNING
        assert min(abs(s.wheel_velocity_rad_s) for s in rig.drive_sims) > 5.0
        # 11000 rpm at the motor: 11000 / 12 * 2 pi / 60 rad/s at the wheel.
        rig.send_can_twist(Twist(11000 / 12 * 2 * 3.141592653589793 / 60 * 0.08, 0.0, 0.0))
        seen: list[tuple[GatewayState, str]] = []
        rig.advance(1.0, lambda r: seen.append((r.gw.supervisor.state, r.gw.supervisor.reason)))
        # No exception out of the cycle: a FAULT naming the signal, its range and the value
        # (then the automatic recovery re-enables the drives, at zero speed).
        faults = [why for state, why in seen if state is GatewayState.FAULT]
        assert faults and faults[0].startswith("command not sent: ")
        assert 'signal "Target_Velocity"' in faults[0]
        assert "between -10000 and 10000 rpm" in faults[0]
        assert any(e.code is ErrorCode.MOTOR_FAULT for e in errors_on_can(rig))
        rig.advance(3.0)
        # What reached the wheels: they were commanded to zero and stopped.
        assert max(abs(s.wheel_velocity_rad_s) for s in rig.drive_sims) < 0.05
