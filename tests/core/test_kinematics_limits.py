"""Limits: one factor on the twist, reported; steering rate with cosine drive."""

from __future__ import annotations

import dataclasses
import itertools
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


def test_speed_limit_caps_reverse_wheel_speeds_too() -> None:
    # A fixed example of what the property tests find only by chance: the cap holds for
    # |speed|, so a reversing turn is scaled like a forward one.
    m = model("differential", wheel_radius=0.1, track=0.4)
    out, report = apply_limits(m, m.ik(Twist(-2.0, 0.0, -2.0)), Limits((12.0, 12.0)))
    assert report.speed_scale == pytest.approx(0.5)
    assert out.wheel_rad_s == pytest.approx((-8.0, -12.0))
    assert out.twist == Twist(-1.0, 0.0, -1.0)


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


@pytest.mark.parametrize("accel", [20.0, 60.0, 200.0])
def test_steering_never_turns_past_the_requested_angle_on_an_interpolated_way(
        accel: float) -> None:
    """A synchro drive (steering range +-pi) going backwards (wheels at pi) asked to drive
    right: the wheels end at pi/2 driving backwards.  The acceleration limit interpolates the
    twist, whose direction starts just past pi, beyond the range: the interpolated wheel angle
    starts near 0 (reversed) and sweeps up to pi/2.  The wheels turn from pi straight to pi/2
    and wait there; they never swing down toward 0 and back (the actuator would overshoot on
    the reversal)."""
    wheels = PRESETS["synchro"].wheels(wheel_radius=0.06, wheel_distance=0.2)
    # (The rate comes from the steering actuator's max_rpm through its gear ratio.)
    m = RobotModel([dataclasses.replace(w, max_steer_rate=8.4) for w in wheels])
    limits = Limits((math.inf,) * 3, max_wheel_accel_rad_s2=accel)
    prev = m.ik(Twist(-0.4, 0.0, 0.0), (math.pi,) * 3)
    assert prev.steer_rad == (math.pi,) * 3
    ask = Twist(0.0, -0.4, 0.0)
    angles = [math.pi]
    for _ in range(300):
        out, _report = apply_limits(m, m.ik(ask, prev.steer_rad), limits, prev, 0.01)
        turret = [a for a in out.steer_rad if a is not None]
        assert len(turret) == 3 and max(turret) - min(turret) < 1e-12  # one turret
        angles.append(turret[0])
        prev = out
    assert all(b <= a for a, b in itertools.pairwise(angles))  # one way only
    assert min(angles) == pytest.approx(math.pi / 2)
    assert prev.twist == ask and prev.wheel_rad_s == pytest.approx((-0.4 / 0.06,) * 3)


def test_limits_must_match_the_model() -> None:
    m = model("differential", wheel_radius=0.1, track=0.4)
    with pytest.raises(KinematicsError, match="Expected 2 wheel speed limits, but got 1"):
        apply_limits(m, m.ik(Twist()), Limits((1.0,)))


def test_deceleration_has_its_own_limit_and_a_reversal_takes_the_smaller() -> None:
    m = model("differential", wheel_radius=0.1, track=0.4)
    limits = Limits((math.inf, math.inf), max_wheel_accel_rad_s2=10.0,
                    max_wheel_decel_rad_s2=40.0)
    cruise = m.ik(Twist(1.0))  # both wheels 10 rad/s
    steps = {}
    for name, target in (("brake", Twist()), ("faster", Twist(2.0)), ("reverse", Twist(-1.0))):
        out, report = apply_limits(m, m.ik(target), limits, cruise, 0.01)
        assert report.accel_scale < 1.0, name
        steps[name] = max(abs(a - b) for a, b in
                          zip(out.wheel_rad_s, cruise.wheel_rad_s, strict=True))
    assert steps == pytest.approx({"brake": 0.4, "faster": 0.1, "reverse": 0.1})
    # A wheel slowing while the other speeds up: each wheel within its own step.
    out, _ = apply_limits(m, m.ik(Twist(1.0, 0.0, 5.0)), limits, cruise, 0.01)
    left, right = (a - b for a, b in zip(out.wheel_rad_s, cruise.wheel_rad_s, strict=True))
    assert left < 0.0 < right and right == pytest.approx(0.1) and abs(left) <= 0.4
    # Unset, deceleration is the acceleration limit (the behaviour before the key existed).
    same = Limits((math.inf, math.inf), max_wheel_accel_rad_s2=10.0)
    out, _ = apply_limits(m, m.ik(Twist()), same, cruise, 0.01)
    assert out.wheel_rad_s == pytest.approx((9.9, 9.9))


@pytest.mark.parametrize("name", ["swerve", "mecanum", "ackermann"])
def test_equal_steps_give_the_single_limit_factor(name: str) -> None:
    # change_scale with accel == decel is exactly the one-limit factor, steered or not.
    params = {"wheel_radius": 0.05, "wheelbase": 0.5, "track": 0.4}
    m = model(name, **params)
    prev = Twist(0.4, 0.0, 0.3)
    for d in ((0.1, 0.0, 0.2), (-0.8, 0.0, -0.3), (0.2, 0.0, 0.0)):
        expected = min(1.0, 0.05 / m.max_wheel_change(*d))
        assert m.change_scale(prev, d, 0.05, 0.05) == pytest.approx(expected)
