"""Odometry: exact SE(2) integration, steering, slip, reset."""

from __future__ import annotations

import math

import pytest

from gateway.core.errors import KinematicsError
from gateway.core.kinematics import PRESETS, RobotModel
from gateway.core.kinematics.odometry import Odometry, Pose, compose, se2_exp
from gateway.core.types import Twist


def model(name: str, **params: float) -> RobotModel:
    return RobotModel(PRESETS[name].wheels(**params))


def drive(m: RobotModel, twist: Twist, seconds: float, steps: int) -> Odometry:
    odo = Odometry(m)
    res = m.ik(twist)
    pos = [0.0] * m.n
    odo.update(pos, 0.0, res.steer_rad)
    dt = seconds / steps
    for k in range(1, steps + 1):
        pos = [p + v * dt for p, v in zip(pos, res.wheel_rad_s, strict=True)]
        odo.update(pos, k * dt, res.steer_rad)
    return odo


def test_full_circle_returns_home_regardless_of_step() -> None:
    m = model("differential", wheel_radius=0.05, track=0.3)
    for steps in (1, 7, 1000):
        # wz = 2 pi / 10 over 10 s: one full turn; one step of a whole circle is exact too.
        odo = drive(m, Twist(0.5, 0.0, 2 * math.pi / 10), 10.0, steps)
        assert odo.state.pose.x_m == pytest.approx(0.0, abs=1e-9)
        assert odo.state.pose.y_m == pytest.approx(0.0, abs=1e-9)
        assert odo.state.distance_m == pytest.approx(5.0)


def test_steered_robot_follows_arc() -> None:
    m = model("ackermann", wheel_radius=0.1, wheelbase=0.5, track=0.4, max_steer=0.6)
    odo = drive(m, Twist(1.0, 0.0, 0.5), 2.0, 50)
    r = 2.0
    assert odo.state.pose.x_m == pytest.approx(r * math.sin(1.0))
    assert odo.state.pose.y_m == pytest.approx(r * (1 - math.cos(1.0)))
    assert odo.state.twist.vx_m_s == pytest.approx(1.0)
    assert odo.state.slip_m_s == pytest.approx(0.0, abs=1e-9)


def test_holonomic_translation_and_slip_indicator() -> None:
    m = model("mecanum", wheel_radius=0.05, wheelbase=0.4, track=0.3)
    odo = drive(m, Twist(0.0, 0.4, 0.0), 1.0, 10)
    assert (odo.state.pose.x_m, odo.state.pose.y_m) == pytest.approx((0.0, 0.4))
    # One wheel spins 1 rad further than the others: the residual shows it.
    last = [0.0, 0.4 / 0.05, 0.4 / 0.05, 0.0]  # wheel angles after 0.4 m sideways
    assert odo.update(last, 1.05).slip_m_s == pytest.approx(0.0, abs=1e-9)
    odo.update([last[0] + 1.0, *last[1:]], 1.1)
    assert odo.state.slip_m_s > 0.1


def test_reset_and_bad_input() -> None:
    m = model("differential", wheel_radius=0.05, track=0.3)
    odo = drive(m, Twist(0.5, 0.0, 0.0), 1.0, 10)
    odo.reset(Pose(1.0, 2.0, 0.5))
    assert odo.state.pose == Pose(1.0, 2.0, 0.5)
    assert odo.state.distance_m == 0.0
    with pytest.raises(KinematicsError, match="Expected 2 wheel positions, but got 3"):
        odo.update([0.0, 0.0, 0.0], 2.0)


def test_compose_is_group_composition() -> None:
    a = se2_exp(0.3, -0.2, 0.7)
    b = se2_exp(-0.1, 0.5, -1.1)
    ab = compose(compose(Pose(), a), b)
    # Rotating both by the first pose's heading: compare with matrix product.
    c, s = math.cos(a.theta_rad), math.sin(a.theta_rad)
    assert ab.x_m == pytest.approx(a.x_m + c * b.x_m - s * b.y_m)
    assert ab.y_m == pytest.approx(a.y_m + s * b.x_m + c * b.y_m)


def test_published_twist_has_the_sign_of_the_motion() -> None:
    # The rates published in WG_Odom_Velocity, the status and ROS 2 odometry: REP-103, a
    # counter-clockwise turn is +wz, a forward move +vx.
    m = model("differential", wheel_radius=0.1, track=0.4)
    for twist in (Twist(0.0, 0.0, 1.0), Twist(0.0, 0.0, -1.0), Twist(0.5, 0.0, 0.0)):
        odo = Odometry(m)
        w = m.ik(twist).wheel_rad_s
        odo.update([0.0, 0.0], 0.0)
        st = odo.update([w[0] * 0.1, w[1] * 0.1], 0.1)
        assert st.pose.theta_rad == pytest.approx(0.1 * twist.wz_rad_s)
        assert (st.twist.vx_m_s, st.twist.wz_rad_s) == pytest.approx(
            (twist.vx_m_s, twist.wz_rad_s))
