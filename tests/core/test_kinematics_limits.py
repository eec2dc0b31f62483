"""Limits: one factor on the twist, reported; steering rate with cosine drive."""

from __future__ import annotations

import math

import pytest

from gateway.core.errors import KinematicsError
from gateway.core.kinematics import PRESETS, Limits, RobotModel, apply_limits
from gateway.core.types import Twist


def model(name: str, **params: float) -> RobotModel:
    return RobotModel(PRESETS[name].wheels(**params))


def test_speed_limit_scales_whole_twist_and_reports() -> None:
    m = model("differential", wheel_radius=0.1, track=0.4)
    res = m.ik(Twist(2.0, 0.0, 2.0))  # left 16 rad/s, right 24 rad/s
    out, report = apply_limits(m, res, Limits((12.0, 12.0)))
    assert report.speed_scale == pytest.approx(0.5)
    assert report.limited
    assert out.wheel_rad_s == pytest.approx((8.0, 12.0))
    assert out.twist == Twist(1.0, 0.0, 1.0)
    assert report.requested == Twist(2.0, 0.0, 2.0)


def test_untouched_command_reports_nothing() -> None:
    m = model("differential", wheel_radius=0.1, track=0.4)
    res = m.ik(Twist(0.1, 0.0, 0.0))
    out, report = apply_limits(m, res, Limits((100.0, 100.0)), res, 0.01)
    assert out == res
    assert not report.limited
    assert (report.speed_scale, report.accel_scale, report.steer_limited) == (1.0, 1.0, ())


def test_acceleration_limit_ramps_from_rest_on_the_same_path() -> None:
    m = model("differential", wheel_radius=0.1, track=0.4)
    limits = Limits((math.inf, math.inf), max_wheel_accel_rad_s2=10.0)
    prev = m.ik(Twist())
    target = Twist(1.0, 0.0, 1.0)
    for _ in range(5):
        out, report = apply_limits(m, m.ik(target), limits, prev, 0.01)
        assert report.accel_scale < 1.0
        # Same direction and curvature as the target.
        assert out.twist.wz_rad_s / out.twist.vx_m_s == pytest.approx(1.0)
        assert max(abs(a - b) for a, b in zip(out.wheel_rad_s, prev.wheel_rad_s, strict=True)) \
            == pytest.approx(0.1)
        prev = out


def test_acceleration_limit_decelerates_along_old_path_when_interpolation_is_infeasible() -> None:
    # Ackermann: from forward-left to backward-left the straight interpolation passes through
    # turning in place, which the steering limits forbid; the robot slows along its path.
    m = model("ackermann", wheel_radius=0.1, wheelbase=0.5, track=0.4, max_steer=0.6)
    limits = Limits((math.inf,) * 4, max_wheel_accel_rad_s2=1000.0)  # half the change per step
    prev = m.ik(Twist(1.0, 0.0, 0.5))
    out, report = apply_limits(m, m.ik(Twist(-1.0, 0.0, 0.5)), limits, prev, 0.01)
    assert report.accel_scale == 0.0
    assert out.twist.wz_rad_s / out.twist.vx_m_s == pytest.approx(0.5)
    assert 0.0 < out.twist.vx_m_s < 1.0
    assert m.feasible(out.twist)


def test_steering_rate_limit_drives_only_along_actual_heading() -> None:
    m = model("swerve", wheel_radius=0.05, wheelbase=0.5, track=0.5, max_steer=math.pi,
              max_steer_rate=2.0)
    limits = Limits((math.inf,) * 4)
    prev = m.ik(Twist(0.5, 0.0, 0.0))  # all wheels straight ahead
    target = m.ik(Twist(0.0, 0.5, 0.0), prev.steer_rad)  # all wheels at +90 deg
    out, report = apply_limits(m, target, limits, prev, 0.1)
    assert set(report.steer_limited) == set(m.names)
    for i in range(4):
        assert out.steer_rad[i] == pytest.approx(0.2)
        assert out.wheel_rad_s[i] == pytest.approx(10.0 * math.cos(math.pi / 2 - 0.2))


def test_limits_must_match_the_model() -> None:
    m = model("differential", wheel_radius=0.1, track=0.4)
    with pytest.raises(KinematicsError, match="Expected 2 wheel speed limits, but got 1"):
        apply_limits(m, m.ik(Twist()), Limits((1.0,)))
