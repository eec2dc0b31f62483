"""Tests of DJI C620 / C610 steering actuators in a driver: wheels and actuators mixed, the
position cascade on a virtual bus, and a swerve configuration with DJI steering."""

from __future__ import annotations

from typing import TYPE_CHECKING

import pytest
import yaml

from drivers.dji import (
    M3508_GEAR_RATIO,
    DjiDriver,
    DjiFeedback,
    PositionLoop,
)
from drivers.dji.codec import RAD_S_PER_RPM, decode_command, encode_feedback
from drivers.dji.sim import DjiSimulator
from gateway.bus.can_bus import send_frames
from gateway.config import parse_config
from gateway.core.errors import ConfigError
from gateway.core.types import DriveFault, DriveState, Frame
from gateway.drive.driveset import DriveSet
from gateway.sim.device import SimFault
from tests.conftest import CONFIG_DIR
from tests.drivers.dji_helpers import Rig, _rig, currents_in
from tests.drivers.steering_dji_helpers import ACK, COUNT_RAD, TWO_PI, drive, steer

if TYPE_CHECKING:
    from collections.abc import Sequence


def fb_frame(esc_id: int, angle: int, rpm: int = 0, temp: int = 35, t: float = 0.0) -> Frame:
    return encode_feedback(DjiFeedback(esc_id, angle, rpm, 0, temp)).stamped(t)


# ===================================================================== mixed driver


def test_mixed_driver_slots_and_loops() -> None:
    """Drive motors (speed loop) and steering actuators (position cascade) in one instance,
    in any order: every motor's current goes in its own ESC slot of 0x200 / 0x1FF."""
    motors = [steer(2, zero_rad=1.0), drive(1), drive(6), steer(5, zero_rad=0.5, invert=True)]
    drv = DjiDriver(motors)
    t = 0.0
    for esc, count in ((2, round(1.0 / COUNT_RAD)), (1, 0), (6, 0), (5, round(0.5 / COUNT_RAD))):
        drv.on_frame(fb_frame(esc, count, t=t))
    drv.enable(t)
    frames = drv.command([0.0, 0.0, 0.0, 0.0], 0.001)
    assert [f.arbitration_id for f in frames] == [0x200, 0x1FF]
    assert currents_in(frames) == dict.fromkeys(range(1, 9), 0)  # all where they should be
    frames = drv.command([0.2, 5.0, -5.0, 0.2], 0.002)
    cur = currents_in(frames)
    assert cur[1] > 0 > cur[6]  # wheels: speed loop, sign of the speed
    assert cur[2] > 0 > cur[5]  # steering: position error, inverted actuator negative
    # the steering current is the cascade's: feed-forward 0.2 * gear / 1 ms clipped to max_rpm
    lim = 3000.0 * TWO_PI / 60.0
    loop = PositionLoop(35.0, 0.7, lim)
    error = 0.2 * M3508_GEAR_RATIO + (1.0 - round(1.0 / COUNT_RAD) * COUNT_RAD)
    speed = loop.speed_target(error, 0.2 * M3508_GEAR_RATIO / 0.001, 0.0)
    assert speed == lim
    expected_a = min(0.1 * speed + 1.0 * speed * 0.001, 20.0)
    assert drv.currents_a[0] == pytest.approx(expected_a)
    assert all(f.arbitration_id != 0x700 for f in frames)
    # disable: zero current for every motor, steering included
    assert currents_in(drv.disable(0.003)) == dict.fromkeys(range(1, 9), 0)
    assert all(drv.state(i, 0.003) is DriveState.DISABLED for i in range(4))


def test_feed_forward_only_between_commands_after_enable() -> None:
    m = steer(1, gear=1.0, zero_rad=0.0, steer_kd=0.0, max_rpm=9000.0, ki=0.0)
    drv = DjiDriver([m])
    drv.on_frame(fb_frame(1, 0, t=0.0))
    drv.enable(0.0)
    drv.command([0.5], 0.0)  # first call: no feed-forward, only P
    assert drv.currents_a[0] == pytest.approx(0.1 * 35.0 * 0.5)
    drv.on_frame(fb_frame(1, 0, t=0.01))
    drv.command([0.6], 0.01)  # 0.1 rad in 10 ms: 10 rad/s of feed-forward
    assert drv.currents_a[0] == pytest.approx(0.1 * (10.0 + 35.0 * 0.6))
    drv.enable(0.01)  # re-arming forgets the last target
    drv.command([0.6], 0.02)
    assert drv.currents_a[0] == pytest.approx(0.1 * 35.0 * 0.6)


# ===================================================================== on the virtual bus


@pytest.mark.parametrize(
    ("esc", "period_ms"), [("c620", 1), ("c620", 5), ("c610", 1), ("c610", 5), ("c620", 20)]
)
def test_step_settles_in_about_0_3_s(channel: str, esc: str, period_ms: int) -> None:
    """A 0.5 rad step of the wheel's plane with the default gains, at 1 kHz, 200 Hz and 50 Hz:
    within 2 % (0.01 rad) from 0.33 s on, overshoot under 2 %."""
    motors = [drive(1), steer(5, esc=esc, zero_rad=4.0)]
    sims = [DjiSimulator(m) for m in motors]
    one_count = COUNT_RAD / motors[1].gear_ratio

    def check(rig: Rig) -> None:
        rig.drv.enable(rig.t)
        held = rig.run(0.1, [3.0, 0.0], period_ms, probe=sims[1])
        assert max(abs(a) for a in held) < 0.002  # holds neutral while the wheel turns
        trace = rig.run(0.6, [3.0, 0.5], period_ms, probe=sims[1])
        assert max(trace) < 0.5 * 1.02
        late = trace[330:]
        assert max(abs(a - 0.5) for a in late) < 0.01, f"settled at {_settle_s(trace):.3f} s"
        fb = rig.drv.feedback(1)
        assert fb is not None
        assert abs(fb.position_rad - sims[1].steer_rad) < one_count + 1e-3
        assert sims[1].steer_rad == pytest.approx(0.5, abs=2e-3)
        assert sims[0].wheel_velocity_rad_s == pytest.approx(3.0, rel=0.02)

    _rig(channel, motors, sims, check)


def _settle_s(trace: Sequence[float]) -> float:
    last_out = max((k for k, a in enumerate(trace) if abs(a - 0.5) >= 0.01), default=-1)
    return (last_out + 1) * 0.001


def test_fault_zero_current_and_recover(channel: str) -> None:
    """Over-temperature on the steering ESC: FAULT, zero current in its slot (the wheel on the
    same frame keeps its own), recovery after cooling and an enable, back to the angle."""
    motors = [drive(1), steer(2, zero_rad=0.2)]
    sims = [DjiSimulator(m) for m in motors]

    def check(rig: Rig) -> None:
        rig.drv.enable(rig.t)
        rig.run(0.5, [3.0, -0.4])
        assert sims[1].steer_rad == pytest.approx(-0.4, abs=2e-3)
        sims[1].inject(SimFault.FAULT)
        rig.run(0.05, [3.0, -0.4])
        status = rig.drv.status(rig.t)[1]
        assert status.state is DriveState.FAULT
        assert status.faults == DriveFault.OVER_TEMPERATURE
        assert sims[1].command_raw == 0 and rig.drv.currents_a[1] == 0.0
        assert rig.drv.state(0, rig.t) is DriveState.ENABLED and sims[0].command_raw != 0
        sims[1].clear(SimFault.FAULT)
        rig.run(0.05, [3.0, 0.3])
        assert rig.drv.state(1, rig.t) is DriveState.DISABLED  # cool, but not re-armed
        assert sims[1].command_raw == 0
        rig.drv.enable(rig.t)
        rig.run(0.6, [3.0, 0.3])
        assert rig.drv.state(1, rig.t) is DriveState.ENABLED
        fb = rig.drv.feedback(1)
        assert fb is not None
        assert sims[1].steer_rad == pytest.approx(0.3, abs=2e-3)
        assert fb.position_rad == pytest.approx(sims[1].steer_rad, abs=1e-3)
        send_frames(rig.gw, rig.drv.disable(rig.t))
        rig.run(0.01, [3.0, 0.3])
        assert [s.command_raw for s in sims] == [0, 0]

    _rig(channel, motors, sims, check)


def test_follows_a_turning_target_without_lag(channel: str) -> None:
    """A steady steering rate: the feed-forward makes the angle follow closely."""
    motors = [steer(3, zero_rad=0.0)]
    sims = [DjiSimulator(m) for m in motors]

    def check(rig: Rig) -> None:
        rig.drv.enable(rig.t)
        rig.run(0.05, [0.0])
        angle = 0.0
        for _ in range(80):  # 1 rad/s for 0.4 s, commanded at 200 Hz
            angle += 0.005
            rig.run(0.005, [angle], period_ms=5)
        assert sims[0].steer_rad == pytest.approx(angle, abs=0.01)

    _rig(channel, motors, sims, check)


# ===================================================================== through the config


def test_swerve_config_with_dji_steering() -> None:
    """The swerve preset with C610 / M2006 steering actuators: the ``steering:`` block takes
    the DJI protocol keys, and the gains reach the driver that also serves no drive motor."""
    doc = yaml.safe_load((CONFIG_DIR / "swerve.yaml").read_text())
    doc["steering_defaults"] = {
        "driver": "dji",
        "esc": "c610",
        "gear_ratio": 72.0,  # the M2006's 36:1 and a 2:1 belt to the module
        "max_rpm": 15000,
        "zero_rad": 1.5,
        **ACK,
    }
    doc["steering"] = {
        "front_left": {"node_id": 1, "steer_kp": 30},
        "front_right": {"node_id": 2},
        "rear_left": {"node_id": 3},
        "rear_right": {"node_id": 4, "invert": True},
    }
    cfg = parse_config(doc, "robot.yaml")
    assert "steer_kd" not in cfg.steering[0].options  # defaults are the driver's
    drives = DriveSet(cfg)
    (dji,) = [drv for drv, _ in drives.groups if isinstance(drv, DjiDriver)]
    assert [m.wheel for m in dji.motors][:1] == ["front_left steering"]
    lim = 15000.0 * RAD_S_PER_RPM
    assert dji._axes[0].loop == PositionLoop(30.0, 0.7, lim)
    assert dji._axes[3].loop == PositionLoop(35.0, 0.7, lim)
    frames = drives.preview([0.0] * 4, [0.0, 0.01, 0.0, 0.01])
    (current,) = [f for f in frames if f.arbitration_id == 0x200]
    cur = decode_command(current)
    assert cur is not None
    assert cur[1] == cur[3] == 0 and cur[2] > 0 > cur[4]  # the inverted module the other way
    doc["motors"]["front_left"] = {"node_id": 1, "steer_kd": 1.0}
    with pytest.raises(ConfigError, match="steer_kd: unknown key"):
        parse_config(doc, "robot.yaml")  # an ODrive drive motor does not take it
