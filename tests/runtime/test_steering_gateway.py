"""Steering actuators over CAN: the gateway steering a swerve robot (measured angles in its
odometry, faults, silence, disarm, tracking) and an Ackermann robot through one actuator."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import pytest

from drivers.odrive.codec import OdriveCodec
from drivers.odrive.commands import SetInputPos, decode_command
from drivers.odrive.enums import AxisState, CmdId, ControlMode
from gateway.cli import main
from gateway.config import load_config
from gateway.core.kinematics.odometry import Odometry
from gateway.core.types import ErrorCode, GatewayState, Twist
from gateway.drive.driveset import DriveSet
from gateway.sim.device import SimFault
from tests.conftest import CONFIG_DIR
from tests.e2e_helpers import Rig, errors_on_can, virtual_config
from tests.runtime.steering_helpers import ACKERMANN, SWERVE

if TYPE_CHECKING:
    from click.testing import CliRunner

    from drivers.odrive.sim import OdriveSimulator

pytestmark = pytest.mark.timeout(60)


# ----------------------------------------------------------------------------- the gateway


def _steer_sims(rig: Rig) -> list[OdriveSimulator]:
    return [s for s in rig.sims if s.motor.steering]  # type: ignore[misc]


def test_swerve_steers_sideways_over_can(channel: str) -> None:
    cfg = virtual_config(SWERVE, channel, rate_hz=100.0)
    with Rig(cfg) as rig:
        rig.enable()
        steer = _steer_sims(rig)
        assert len(steer) == 4 and all(s.axis_state == AxisState.CLOSED_LOOP_CONTROL
                                       for s in steer)
        assert all(s.control_mode == ControlMode.POSITION_CONTROL for s in steer)
        rig.advance(2.0, lambda r: r.send_can_twist(Twist(0.0, 0.3, 0.0)))
        # Sideways: every module turned a quarter turn to the left (or right and reversed).
        for sim in steer:
            assert abs(abs(sim.steer_rad) - math.pi / 2) < 0.01, sim.steer_rad
        measured = rig.gw.drives.measured_steer(rig.gw.prev.steer_rad)
        for got, sim in zip(measured, steer, strict=True):
            assert got == pytest.approx(sim.steer_rad, abs=0.01)
        odom = rig.gw.odometry.state
        assert odom.pose.y_m == pytest.approx(rig.truth.state.pose.y_m, abs=0.01)
        assert odom.pose.y_m > 0.4 and abs(odom.pose.x_m) < 0.05
        assert rig.gw.state is GatewayState.RUNNING, rig.gw.supervisor.reason


def test_odometry_uses_measured_angles_when_the_actuator_lags(channel: str) -> None:
    """A slow steering actuator: odometry from the commanded angles is off by the lag; with
    the measured angles it matches the ground truth."""
    cfg = virtual_config(SWERVE, channel, rate_hz=100.0)
    with Rig(cfg) as rig:
        for sim in _steer_sims(rig):
            sim.model.position_gain_1_s = 5.0  # a sluggish module
        rig.enable()
        commanded = Odometry(cfg.model)
        lag = [0.0]

        def each(r: Rig, twist: Twist) -> None:
            r.send_can_twist(twist)
            steer = r.gw.prev.steer_rad
            commanded.update(r.truth_positions(), r.t, steer)
            for c, m in zip(steer, r.gw.drives.measured_steer(steer), strict=True):
                assert c is not None and m is not None
                lag[0] = max(lag[0], abs(c - m))

        for twist in (Twist(0.3, 0.0, 0.6), Twist(0.3, 0.3, 0.0), Twist(0.0, -0.3, 0.3)):
            rig.advance(1.0, lambda r, t=twist: each(r, t))  # type: ignore[misc]
        want = rig.truth.state.pose
        got, naive = rig.gw.odometry.state.pose, commanded.state.pose
        err = math.hypot(got.x_m - want.x_m, got.y_m - want.y_m)
        naive_err = math.hypot(naive.x_m - want.x_m, naive.y_m - want.y_m)
        assert lag[0] > 0.2
        assert err < 0.01 * rig.truth.state.distance_m
        assert naive_err > 1.5 * err  # measured here: 8.0 mm against 4.5 mm
        assert rig.gw.state is GatewayState.RUNNING, rig.gw.supervisor.reason


def test_steering_fault_stops_the_robot_and_names_the_actuator(channel: str) -> None:
    cfg = virtual_config(SWERVE, channel, rate_hz=100.0)
    with Rig(cfg) as rig:
        rig.enable()
        rig.advance(0.5, lambda r: r.send_can_twist(Twist(0.3, 0.0, 0.0)))
        errors_on_can(rig)
        _steer_sims(rig)[2].inject(SimFault.FAULT)
        rig.advance(0.3, lambda r: r.send_can_twist(Twist(0.3, 0.0, 0.0)))
        sup = rig.gw.supervisor
        assert rig.gw.state is GatewayState.FAULT
        assert "motor 'rear_left steering' (node 7) reports a fault" in sup.reason
        reports = [e for e in errors_on_can(rig) if e.code is ErrorCode.MOTOR_FAULT]
        assert reports and reports[0].wheel == cfg.model.index("rear_left")
        assert rig.gw.status_report().faulted_motors == 1 << cfg.model.index("rear_left")
        rig.advance(0.5)
        assert all(abs(s.wheel_velocity_rad_s) < 0.05 for s in rig.drive_sims)


def test_silent_steering_actuator_is_a_feedback_timeout(channel: str) -> None:
    cfg = virtual_config(SWERVE, channel, rate_hz=100.0)
    with Rig(cfg) as rig:
        rig.enable()
        _steer_sims(rig)[0].inject(SimFault.SILENT)
        rig.advance(0.5, lambda r: r.send_can_twist(Twist(0.2, 0.0, 0.0)))
        assert rig.gw.state is GatewayState.FAULT
        assert rig.gw.supervisor.fault_code is ErrorCode.FEEDBACK_TIMEOUT
        assert "front_left steering" in rig.gw.supervisor.reason


def test_frames_preview_includes_steering() -> None:
    cfg = load_config(SWERVE)
    result = cfg.model.ik(Twist(0.0, 0.3, 0.0))
    frames = DriveSet(cfg).preview(result.wheel_rad_s, result.steer_rad)
    kinds = sorted((f.arbitration_id >> 5, f.arbitration_id & 0x1F) for f in frames)
    assert kinds == [(n, CmdId.SET_INPUT_VEL) for n in (1, 2, 3, 4)] + [
        (n, CmdId.SET_INPUT_POS) for n in (5, 6, 7, 9)]
    pos = [decode_command(OdriveCodec(), f) for f in frames if f.arbitration_id & 0x1F == 0xC]
    for cmd, angle in zip(pos, result.steer_rad, strict=True):
        assert isinstance(cmd, SetInputPos) and angle is not None
        assert cmd.pos_turns == pytest.approx(angle * 12.8 / (2 * math.pi), rel=1e-6)


def test_disarm_releases_steering(channel: str) -> None:
    cfg = virtual_config(SWERVE, channel, rate_hz=100.0)
    with Rig(cfg) as rig:
        rig.enable()
        rig.gw.supervisor.estop()
        rig.advance(0.2)
        assert all(s.axis_state == AxisState.IDLE for s in _steer_sims(rig))


def test_blocked_steering_actuator_is_a_tracking_fault(channel: str) -> None:
    """A module that stops turning while its controller reports healthy: the drive wheels
    would push along a heading the robot does not have; the angle check stops them."""
    cfg = virtual_config(SWERVE, channel, rate_hz=100.0)
    with Rig(cfg) as rig:
        rig.enable()
        rig.advance(0.5, lambda r: r.send_can_twist(Twist(0.3, 0.0, 0.0)))
        _steer_sims(rig)[1].inject(SimFault.STALL)
        rig.advance(1.0, lambda r: r.send_can_twist(Twist(0.0, 0.3, 0.0)))
        sup = rig.gw.supervisor
        assert rig.gw.state is GatewayState.FAULT
        assert sup.fault_code is ErrorCode.TRACKING_ERROR
        assert sup.reason.startswith("motor 'front_right steering' (node 6) does not reach its "
                                     "angle: 0.000 rad measured, 1.571 rad commanded")
        assert sup.steer_tracking.worst_ratio > 5.0


def test_cli_frames_and_check_show_the_actuators(runner: CliRunner) -> None:
    frames = runner.invoke(main, ["frames", "-c", str(SWERVE), "--vy", "0.3"])
    assert frames.exit_code == 0, frames.output
    # 90 degrees of the plane is 3.2 motor turns at 12.8:1: float32 0x404CCCCD.
    assert frames.stdout.split() == [
        "02D#CA43CE4000000000", "04D#CA43CE4000000000", "06D#CA43CE4000000000",
        "08D#CA43CE4000000000", "0AC#CDCC4C4000000000", "0CC#CDCC4C4000000000",
        "0EC#CDCC4C4000000000", "12C#CDCC4C4000000000",
    ]
    check = runner.invoke(main, ["check", "-c", str(SWERVE)])
    assert check.exit_code == 0, check.output
    assert ("  rear_right: odrive node 9, gear 12.8, zero at 0 rad, max 3000 rpm (234.4 rpm of "
            "the wheel's plane)") in check.stdout


def test_actuators_take_travel_and_rate_limit_from_their_wheels() -> None:
    tricycle = load_config(CONFIG_DIR / "tricycle.yaml")
    (actuator,) = tricycle.steering
    assert actuator.steer_range_rad == (-math.pi / 2, math.pi / 2)
    front = tricycle.wheels[tricycle.model.index("front")]
    # 80 % of 3000 rpm through 50:1: the commanded angle never outruns the actuator.
    assert front.max_steer_rate == pytest.approx(0.8 * 3000 * 2 * math.pi / 60 / 50)
    # The swerve modules could turn at 19.6 rad/s: the configured 8 rad/s stays.
    assert all(w.max_steer_rate == 8.0 for w in load_config(SWERVE).wheels)


def test_ackermann_turns_both_wheels_through_one_actuator(channel: str) -> None:
    cfg = virtual_config(ACKERMANN, channel, rate_hz=100.0)
    with Rig(cfg) as rig:
        rig.enable()
        rig.advance(2.0, lambda r: r.send_can_twist(Twist(0.5, 0.0, 0.3)))
        (sim,) = _steer_sims(rig)
        want = cfg.model.ik(Twist(0.5, 0.0, 0.3)).steer_rad
        truth = rig.truth_steer()
        measured = rig.gw.drives.measured_steer(rig.gw.prev.steer_rad)
        for i in (cfg.model.index("front_left"), cfg.model.index("front_right")):
            assert truth[i] == pytest.approx(want[i], abs=1e-3)
            assert measured[i] == pytest.approx(want[i], abs=1e-3)
        assert sim.steer_rad == pytest.approx(math.atan(0.65 * 0.3 / 0.5), abs=1e-3)
        assert rig.gw.state is GatewayState.RUNNING, rig.gw.supervisor.reason
