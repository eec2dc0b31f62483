"""Every worked example of the seeds, re-derived in REP-103 (x forward, y left, CCW positive).

Where a seed prints a wrong number or uses another convention, the test states the corrected
value and why.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from gateway.core.errors import InfeasibleTwistError
from gateway.core.kinematics import PRESETS, RobotModel, Wheel, WheelType
from gateway.core.kinematics.odometry import Odometry, Pose, compose, se2_exp
from gateway.core.types import Twist

SQ3 = math.sqrt(3.0)


def preset(name: str, **params: float | str) -> RobotModel:
    return RobotModel(PRESETS[name].wheels(**params))


def body_to_world(theta: float, t: Twist) -> tuple[float, float, float]:
    """R(theta)^-1 applied to a body twist (seed 000's xi_I = R(theta)^-1 xi_R)."""
    c, s = math.cos(theta), math.sin(theta)
    return (c * t.vx_m_s - s * t.vy_m_s, s * t.vx_m_s + c * t.vy_m_s, t.wz_rad_s)


# --------------------------------------------------------------------------- seed 000


def seed000_differential(l: float = 1.0, r: float = 1.0) -> RobotModel:  # noqa: E741
    return RobotModel(
        [
            Wheel("left", WheelType.FIXED, math.pi / 2, l, 0.0, r),
            Wheel("right", WheelType.FIXED, -math.pi / 2, l, math.pi, r),
        ]
    )


def test_seed000_fixed_wheel_sliding_example() -> None:
    # alpha = beta = 0: the sliding row is (1 0 0), so the wheel forbids x motion.
    w = Wheel("w", WheelType.FIXED, 0.0, 1.0, 0.0, 1.0)
    assert w.sliding_row() == pytest.approx((1.0, 0.0, 0.0))


def test_seed000_rotation_example() -> None:
    # xi_R = R(pi/2) xi_I = (y_I, -x_I, theta_I); equivalently a body motion along +x at
    # heading pi/2 is world motion along +y.
    assert body_to_world(math.pi / 2, Twist(1.0, 0.0, 0.0)) == pytest.approx((0.0, 1.0, 0.0))
    assert body_to_world(math.pi / 2, Twist(0.0, 1.0, 0.0)) == pytest.approx((-1.0, 0.0, 0.0))


def test_seed000_differential_j1_in_rep103() -> None:
    # The seed puts the LEFT wheel at alpha = -pi/2, beta = pi (y to the right), which gives
    # J1f = [[1, 0, l], [1, 0, -l]] for (left, right).  In REP-103 the left wheel sits at
    # alpha = +pi/2, beta = 0, so the rows swap signs: left (1, 0, -l), right (1, 0, +l):
    # a CCW turn slows the left wheel.
    m = seed000_differential(l=0.5)
    assert m.j1() == pytest.approx(np.array([[1.0, 0.0, -0.5], [1.0, 0.0, 0.5]]))
    assert m.c1() == pytest.approx(np.array([[0.0, 1.0, 0.0], [0.0, 1.0, 0.0]]))  # vy = 0


def test_seed000_differential_worked_example() -> None:
    # phi_l = 4, phi_r = 2, r = l = 1, theta = pi/2.  The seed prints xi_I = (0, 3, 1).
    # Its own first formula theta_dot = r phi_r/(2l) - r phi_l/(2l) gives -1: the left wheel
    # is faster, so the robot turns clockwise.  The printed +1 comes from the pseudo-inverse
    # with the seed's swapped wheel order.  Corrected: xi_R = (3, 0, -1), xi_I = (0, 3, -1).
    fk = seed000_differential().fk([4.0, 2.0])
    assert (fk.twist.vx_m_s, fk.twist.vy_m_s, fk.twist.wz_rad_s) == pytest.approx((3, 0, -1))
    assert body_to_world(math.pi / 2, fk.twist) == pytest.approx((0.0, 3.0, -1.0))
    assert fk.residual_m_s == pytest.approx(0.0, abs=1e-12)


def test_seed000_swedish_worked_example() -> None:
    # alpha = (pi/3, pi, -pi/3), beta = gamma = 0, r = l = 1, phi = (4, 1, 2), theta = 0.
    # The seed prints (2/sqrt3, 4/3, -7/3) and labels J1sw itself as its inverse.  Solving
    # J1 xi = J2 phi: rows 1 - 3 give sqrt3 vx = 2, the row sum gives -3 wz = 7, row 2 gives
    # vy - wz = 1, so vy = 1 + wz = -4/3: the seed's +4/3 has a sign error.
    wheels = [
        Wheel(f"w{k}", WheelType.SWEDISH, a, 1.0, 0.0, 1.0)
        for k, a in enumerate((math.pi / 3, math.pi, -math.pi / 3))
    ]
    m = RobotModel(wheels)
    assert m.j1() == pytest.approx(
        np.array([[SQ3 / 2, -0.5, -1.0], [0.0, 1.0, -1.0], [-SQ3 / 2, -0.5, -1.0]])
    )
    fk = m.fk([4.0, 1.0, 2.0])
    t = fk.twist
    assert (t.vx_m_s, t.vy_m_s, t.wz_rad_s) == pytest.approx((2 / SQ3, -4 / 3, -7 / 3))
    assert m.ik(t).wheel_rad_s == pytest.approx((4.0, 1.0, 2.0))


def test_seed000_castor_allows_any_motion() -> None:
    # A castor wheel (d > 0) adds no constraint: any twist is feasible, and the swivel rate
    # satisfies the sliding equation (cos, sin, d + l sin beta) xi + d beta_dot = 0.
    w = Wheel("c", WheelType.CASTOR, math.pi, 0.3, -math.pi / 2, 0.05, d=0.04)
    m = RobotModel([w])
    assert m.mobility.mobility == 3
    t = Twist(0.2, -0.3, 0.7)
    res = m.ik(t, [0.4])
    row = w.sliding_row(0.4)
    rate = res.steer_rate_rad_s[0]
    assert rate is not None
    slide = row[0] * t.vx_m_s + row[1] * t.vy_m_s + row[2] * t.wz_rad_s + w.d * rate
    assert slide == pytest.approx(0.0, abs=1e-12)


# --------------------------------------------------------------------------- seed 001


@pytest.mark.parametrize("theta", [0.0, 0.3, -1.2, 2.5])
def test_seed001_omniwheel_rows(theta: float) -> None:
    # Roller angles gamma1 = gamma3 = -pi/4 (wheels 1 = (l, w) and 3 = (-l, -w)),
    # gamma2 = gamma4 = +pi/4, beta = 0.  u1 = (1/r)[c+s, s-c, -w-l] q_dot: the stacked matrix
    # in the seed prints row 1 as [c-s, s-c, -w-l], a typo; its own per-wheel line has c+s.
    r, lx, ly = 0.05, 0.2, 0.15
    m = preset("mecanum", wheel_radius=r, wheelbase=2 * lx, track=2 * ly)
    order = [m.index(n) for n in ("front_left", "front_right", "rear_right", "rear_left")]
    c, s, k = math.cos(theta), math.sin(theta), lx + ly
    rows = np.array(
        [[c + s, s - c, -k], [c - s, s + c, k], [c + s, s - c, k], [c - s, s + c, -k]]
    ) / r
    q_dot = np.array([0.3, -0.2, 0.5])  # world frame
    body = Twist(c * q_dot[0] + s * q_dot[1], -s * q_dot[0] + c * q_dot[1], q_dot[2])
    speeds = m.ik(body).wheel_rad_s
    assert [speeds[i] for i in order] == pytest.approx(list(rows @ q_dot))


# --------------------------------------------------------------------------- seed 002


def test_seed002_differential_example() -> None:
    # r = 0.1, b = 0.4, v = 0.5, w = 0.3.  The seed defines w = (v_l - v_r)/b (clockwise
    # positive) and prints (omega_l, omega_r) = (5.6, 4.4).  In REP-103 a positive yaw rate
    # turns left, so the right wheel is the faster one: (4.4, 5.6).
    m = preset("differential", wheel_radius=0.1, track=0.4)
    res = m.ik(Twist(0.5, 0.0, 0.3))
    assert res.wheel_rad_s == pytest.approx((4.4, 5.6))
    # The seed's own convention, w -> -w, gives its printed numbers.
    assert m.ik(Twist(0.5, 0.0, -0.3)).wheel_rad_s == pytest.approx((5.6, 4.4))


def test_seed002_tricycle_relations() -> None:
    # omega = v3 sin(gamma) / l, vx = v3 cos(gamma); the rear wheels roll at
    # C3 (cos(gamma) -+ b/(2l) sin(gamma)), inner (left, for a left turn) slower.
    r, l, b = 0.1, 0.6, 0.45  # noqa: E741
    m = preset("tricycle", wheel_radius=r, wheelbase=l, track=b)
    gamma, v3 = 0.4, 1.2
    t = Twist(v3 * math.cos(gamma), 0.0, v3 * math.sin(gamma) / l)
    res = m.ik(t)
    assert res.steer_rad[m.index("front")] == pytest.approx(gamma)
    assert res.wheel_rad_s[m.index("front")] * r == pytest.approx(v3)
    inner = v3 * (math.cos(gamma) - b / (2 * l) * math.sin(gamma))
    outer = v3 * (math.cos(gamma) + b / (2 * l) * math.sin(gamma))
    assert res.wheel_rad_s[m.index("rear_left")] * r == pytest.approx(inner)
    assert res.wheel_rad_s[m.index("rear_right")] * r == pytest.approx(outer)
    # r_c = l cot(gamma)
    assert t.vx_m_s / t.wz_rad_s == pytest.approx(l / math.tan(gamma))


def test_seed002_ackermann_cot_relations() -> None:
    # Virtual middle wheel: cot(gamma_v) = r/l + b/(2l) in the seed, whose angles are
    # positive for a right turn.  In REP-103 (left turn positive) the inner wheel is the left
    # one: cot(gamma_l) = cot(gamma_v) - b/(2l), cot(gamma_r) = cot(gamma_v) + b/(2l).
    l, b = 0.65, 0.5  # noqa: E741
    m = preset("ackermann", wheel_radius=0.12, wheelbase=l, track=b, max_steer=0.9)
    for vx, wz in ((1.0, 0.6), (1.0, -0.6), (-0.7, 0.5)):
        res = m.ik(Twist(vx, 0.0, wz))
        gl, gr = res.steer_rad[m.index("front_left")], res.steer_rad[m.index("front_right")]
        assert gl is not None and gr is not None
        cot_v = (vx / wz) / l
        assert 1 / math.tan(gl) == pytest.approx(cot_v - b / (2 * l))
        assert 1 / math.tan(gr) == pytest.approx(cot_v + b / (2 * l))


def test_seed002_ackermann_cannot_turn_in_place() -> None:
    m = preset("ackermann", wheel_radius=0.12, wheelbase=0.65, track=0.5, max_steer=0.6)
    with pytest.raises(InfeasibleTwistError) as info:
        m.ik(Twist(0.0, 0.0, 1.0))
    err = info.value
    assert err.constraint == "steering limit"
    assert err.wheel in ("front_left", "front_right")
    assert m.feasible(err.nearest)
    assert err.residual_m_s > 0.1


@pytest.mark.parametrize(
    ("wz", "expected", "printed"),
    [
        # 50 * (0.5*0.05 - 0.866*0.05 + 0.09*0.5) = 1.335; the seed prints 1.135 (digit typo).
        (0.5, (-0.25, 1.335, 5.665), (-0.25, 1.135, 5.665)),
        # 50 * (0.025 - 0.0433 - 0.045) = -3.165; the seed prints +3.165 (sign typo).
        (-0.5, (-4.75, -3.165, 1.165), (-4.75, 3.165, 1.165)),
    ],
)
def test_seed002_delta_robot(
    wz: float, expected: tuple[float, ...], printed: tuple[float, ...]
) -> None:
    # r = 0.02 (1/r = 50), b = 0.09, drive directions at 180, -60 and 60 degrees, so the
    # wheels sit at polar angles 90, 210 and 330 degrees.  v = (0.05, 0.05).
    m = preset("omni", wheel_radius=0.02, wheel_distance=0.09, first_wheel_angle=math.pi / 2)
    speeds = m.ik(Twist(0.05, 0.05, wz)).wheel_rad_s
    # The seed rounds sqrt(3)/2 to 0.866: within 0.001 rad/s of the exact values.
    assert speeds == pytest.approx(expected, abs=1e-3)
    assert speeds != pytest.approx(printed, abs=1e-3)


# --------------------------------------------------------------------------- seed 003


def test_seed003_four_wheel_omni() -> None:
    # Wheels: 1 = (L, l) front left, 2 = (L, -l) front right, 3 = (-L, l) rear left,
    # 4 = (-L, -l) rear right.  v1 = vx - vy - (L+l) w, v2 = vx + vy + (L+l) w,
    # v3 = vx + vy - (L+l) w, v4 = vx - vy + (L+l) w; forward kinematics by pseudo-inverse.
    big, small, r = 0.25, 0.2, 0.06
    m = preset("mecanum", wheel_radius=r, wheelbase=2 * big, track=2 * small)
    k = big + small
    h = np.array([[1, -1, -k], [1, 1, k], [1, 1, -k], [1, -1, k]], dtype=float)
    order = [m.index(n) for n in ("front_left", "front_right", "rear_left", "rear_right")]
    xi = np.array([0.4, 0.1, -0.3])
    v = [s * r for s in m.ik(Twist(*xi)).wheel_rad_s]
    assert [v[i] for i in order] == pytest.approx(list(h @ xi))
    measured = np.array([0.5, 0.2, -0.1, 0.3])  # inconsistent: needs least squares
    speeds: list[float | None] = [None] * 4
    for j, i in enumerate(order):
        speeds[i] = float(measured[j] / r)
    fk = m.fk(speeds)
    t = fk.twist
    assert [t.vx_m_s, t.vy_m_s, t.wz_rad_s] == pytest.approx(list(np.linalg.pinv(h) @ measured))
    assert fk.residual_m_s > 0.01  # the slip indicator of a redundant drive


@pytest.mark.parametrize("theta", [0.0, 0.7])
def test_seed003_three_wheel_omni(theta: float) -> None:
    # v_i = -sin(theta + phi_i) x_dot + cos(theta + phi_i) y_dot + L theta_dot, phi_i = 0,
    # 120, 240 degrees (world velocities).
    big, r = 0.2, 0.05
    m = preset("omni", wheel_radius=r, wheel_distance=big, first_wheel_angle=0.0)
    q_dot = (0.3, -0.4, 0.9)
    c, s = math.cos(theta), math.sin(theta)
    body = Twist(c * q_dot[0] + s * q_dot[1], -s * q_dot[0] + c * q_dot[1], q_dot[2])
    v = [x * r for x in m.ik(body).wheel_rad_s]
    for i, phi in enumerate((0.0, 2 * math.pi / 3, 4 * math.pi / 3)):
        expected = (
            -math.sin(theta + phi) * q_dot[0] + math.cos(theta + phi) * q_dot[1] + big * q_dot[2]
        )
        assert v[i] == pytest.approx(expected)


# --------------------------------------------------------------------------- seed 004


def test_seed004_turtlebot3_ik_and_fk() -> None:
    # H = (1/r) [[-D, 1, 0], [D, 1, 0]] on (theta_dot, vx, vy); D = track / 2 = 0.08.
    r, d = 0.033, 0.080
    m = preset("differential", wheel_radius=r, track=2 * d)
    res = m.ik(Twist(0.2, 0.0, 1.5))
    assert res.wheel_rad_s == pytest.approx(((0.2 - d * 1.5) / r, (0.2 + d * 1.5) / r))
    # eq (1): theta_b = r/2 (-phi1/D + phi2/D), vx = r/2 (phi1 + phi2), vy = 0.  (The seed's
    # pseudo-inverse line reads "H^dagger = H^dagger (H H^dagger)^-1"; it means H^T (H H^T)^-1.)
    fk = m.fk([3.0, 5.0])
    assert fk.twist.wz_rad_s == pytest.approx(r / 2 * (-3.0 / d + 5.0 / d))
    assert fk.twist.vx_m_s == pytest.approx(r / 2 * 8.0)
    assert fk.twist.vy_m_s == pytest.approx(0.0, abs=1e-15)


def test_seed004_turtlebot3_refuses_slip() -> None:
    m = preset("differential", wheel_radius=0.033, track=0.16)
    with pytest.raises(InfeasibleTwistError) as info:
        m.ik(Twist(0.1, 0.05, 0.0))
    err = info.value
    assert err.constraint == "sliding"
    assert err.residual_m_s == pytest.approx(0.05)
    assert err.nearest.vx_m_s == pytest.approx(0.1)
    assert err.nearest.vy_m_s == pytest.approx(0.0, abs=1e-12)
    assert "left" in str(err) or "right" in str(err)


def test_seed004_odometry_is_twb_exp() -> None:
    # T_wb' = T_wb * T_bb' with T_bb' = exp(V_b) from the wheel angle increments.
    r, d = 0.033, 0.080
    m = preset("differential", wheel_radius=r, track=2 * d)
    odo = Odometry(m)
    odo.update([0.0, 0.0], 0.0)
    state = odo.update([10.0, 20.0], 1.0)
    vb = m.fk([10.0, 20.0]).twist
    expected = compose(Pose(), se2_exp(vb.vx_m_s, vb.vy_m_s, vb.wz_rad_s))
    assert (state.pose.x_m, state.pose.y_m, state.pose.theta_rad) == pytest.approx(
        (expected.x_m, expected.y_m, expected.theta_rad)
    )
    # Closed form: an arc of radius R = vx / wz.
    big_r = vb.vx_m_s / vb.wz_rad_s
    assert state.pose.x_m == pytest.approx(big_r * math.sin(vb.wz_rad_s))
    assert state.pose.y_m == pytest.approx(big_r * (1 - math.cos(vb.wz_rad_s)))
