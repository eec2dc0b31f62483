"""Property tests of the general model on random wheel layouts."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume, example, given, settings
from hypothesis import strategies as st

from gateway.core.errors import InfeasibleTwistError, KinematicsError
from gateway.core.kinematics import PRESETS, Limits, RobotModel, Wheel, WheelType, apply_limits
from gateway.core.kinematics.forward import FkSolver
from gateway.core.kinematics.odometry import Odometry
from gateway.core.types import Twist

angles = st.floats(-math.pi, math.pi, allow_nan=False)
speeds = st.floats(-2.0, 2.0, allow_nan=False)
twists = st.builds(Twist, speeds, speeds, speeds)


@st.composite
def wheels(draw: st.DrawFn, name: str) -> Wheel:
    kind = draw(st.sampled_from(list(WheelType)))
    lim = draw(st.floats(0.3, math.pi))
    return Wheel(
        name=name,
        type=kind,
        alpha=draw(angles),
        l=draw(st.floats(0.05, 1.0)),
        beta=draw(angles),
        radius=draw(st.floats(0.02, 0.3)),
        gamma=draw(st.floats(-1.2, 1.2)) if kind is WheelType.SWEDISH else 0.0,
        d=draw(st.floats(0.01, 0.2)) if kind is WheelType.CASTOR else 0.0,
        steer_min=-lim,
        steer_max=lim,
    )


@st.composite
def robots(draw: st.DrawFn) -> RobotModel:
    n = draw(st.integers(1, 5))
    return RobotModel([draw(wheels(f"w{i}")) for i in range(n)], slip_tolerance_m_s=1e-6)


def constraint_residuals(model: RobotModel, t: Twist, res: object) -> list[float]:
    """Every rolling and sliding equation of every wheel, evaluated on an IK result."""
    from gateway.core.kinematics import IkResult

    assert isinstance(res, IkResult)
    xi = (t.vx_m_s, t.vy_m_s, t.wz_rad_s)
    out = []
    for i, w in enumerate(model.wheels):
        sigma = res.steer_rad[i] or 0.0
        roll = w.rolling_row(sigma)
        rolled = sum(a * b for a, b in zip(roll, xi, strict=True))
        out.append(rolled - w.radius * res.wheel_rad_s[i])
        if w.type in (WheelType.FIXED, WheelType.STEERABLE):
            slide = w.sliding_row(sigma)
            out.append(sum(a * b for a, b in zip(slide, xi, strict=True)))
        if w.type is WheelType.CASTOR:
            slide = w.sliding_row(sigma)
            rate = res.steer_rate_rad_s[i]
            assert rate is not None
            out.append(sum(a * b for a, b in zip(slide, xi, strict=True)) + w.d * rate)
    return out


@settings(max_examples=300, deadline=None)
@given(robots(), twists, st.lists(angles, min_size=5, max_size=5))
def test_ik_satisfies_every_constraint_or_is_rejected(
    model: RobotModel, t: Twist, current: list[float]
) -> None:
    steer = [current[i] if w.steered and w.steer_min <= current[i] <= w.steer_max else
             (0.0 if w.steered else None) for i, w in enumerate(model.wheels)]
    try:
        res = model.ik(t, steer)
    except InfeasibleTwistError as err:
        assert err.residual_m_s > model.slip_tolerance_m_s
        assert model.feasible(err.nearest, steer)
        return
    for value in constraint_residuals(model, t, res):
        assert abs(value) <= 1e-6 + 1e-9 * abs(value)
    for i, w in enumerate(model.wheels):
        if w.type is WheelType.STEERABLE:
            sigma = res.steer_rad[i]
            assert sigma is not None
            assert w.steer_min - 1e-9 <= sigma <= w.steer_max + 1e-9


@settings(max_examples=300, deadline=None)
@given(robots(), twists)
def test_infeasible_twists_are_always_caught(model: RobotModel, t: Twist) -> None:
    # A twist is feasible exactly when no fixed wheel slides beyond the tolerance and every
    # steerable wheel can point along its contact velocity within its limits.
    xi = (t.vx_m_s, t.vy_m_s, t.wz_rad_s)
    worst = 0.0
    for w in model.wheels:
        if w.type is WheelType.FIXED:
            worst = max(worst, abs(sum(a * b for a, b in zip(w.sliding_row(), xi, strict=True))))
    if worst > 2e-6:
        with pytest.raises(InfeasibleTwistError):
            model.ik(t)


@settings(max_examples=300, deadline=None)
@given(robots(), twists)
@example(
    RobotModel([Wheel("a", WheelType.SPHERICAL, 0.0, 1.0, 0.0, 0.25),
                Wheel("b", WheelType.SPHERICAL, 0.0, 1.0, 2.061698142643885e-09, 0.25),
                Wheel("c", WheelType.SPHERICAL, 1.0, 1.0, 0.0, 0.25)], slip_tolerance_m_s=1e-6),
    Twist(0.0, 0.0, 1.0),
)
def test_fk_inverts_ik(model: RobotModel, t: Twist) -> None:
    try:
        res = model.ik(t)
    except InfeasibleTwistError:
        return
    try:
        fk = model.fk(list(res.wheel_rad_s), list(res.steer_rad))
    except KinematicsError:
        return  # too few wheels to determine the twist (e.g. one spherical wheel)
    got = fk.twist
    # The IK accepts a twist whose wheels slide by up to the slip tolerance, so the least
    # squares may land elsewhere: by at most twice the twist's own misfit over the smallest
    # singular value of the stacked equations (random layouts can be nearly degenerate), and
    # exactly on the twist when it fits them.
    a, b = FkSolver(model.wheels, model.neutral_steer).system(
        list(res.wheel_rad_s), list(res.steer_rad)
    )
    want = np.array([t.vx_m_s, t.vy_m_s, t.wz_rad_s])
    misfit = float(np.linalg.norm(a @ want - b))
    singular = np.linalg.svd(a, compute_uv=False)
    smallest = float(singular[-1])
    error = float(np.linalg.norm(np.array([got.vx_m_s, got.vy_m_s, got.wz_rad_s]) - want))
    assert error <= (2.0 * misfit + 1e-12) / smallest + 1e-9, (error, misfit, smallest)
    assert misfit <= 2.0 * math.sqrt(len(b)) * model.slip_tolerance_m_s
    # The least squares' residual is at most the twist's own (rms), plus the rounding of a
    # solution through the pseudo-inverse, which grows with the condition number: two wheels
    # of a random layout at one place, their rolling directions 2e-9 rad apart, left a
    # residual of 2.9e-9 m/s where the twist fits exactly (a run of CI, hypothesis's own
    # draw).
    rounding = 8.0 * np.finfo(float).eps * float(singular[0]) / smallest * float(
        np.linalg.norm(b))
    assert fk.residual_m_s <= misfit / math.sqrt(len(b)) + 1e-12 + rounding, (
        fk.residual_m_s, misfit, rounding)


@settings(max_examples=300, deadline=None)
@given(
    st.sampled_from(["differential", "mecanum", "omni", "swerve", "skid_steer"]),
    twists,
    st.floats(0.5, 30.0),
    st.floats(0.05, 2.0),
    st.floats(0.1, 5.0),
)
def test_limited_twists_keep_direction(
    drive: str, t: Twist, cap: float, max_lin: float, max_ang: float
) -> None:
    geometry = {"wheel_radius": 0.05, "track": 0.4, "wheelbase": 0.5, "wheel_distance": 0.2}
    p = PRESETS[drive]
    model = RobotModel(p.wheels(**{k: v for k, v in geometry.items() if k in p.params}))
    if drive in ("differential", "skid_steer"):
        t = Twist(t.vx_m_s, 0.0, t.wz_rad_s)
    res = model.ik(t)
    limits = Limits((cap,) * model.n, max_linear_m_s=max_lin, max_angular_rad_s=max_ang)
    out, report = apply_limits(model, res, limits)
    s = report.speed_scale
    assert 0.0 < s <= 1.0
    assert out.twist.vx_m_s == pytest.approx(s * t.vx_m_s)
    assert out.twist.vy_m_s == pytest.approx(s * t.vy_m_s)
    assert out.twist.wz_rad_s == pytest.approx(s * t.wz_rad_s)
    assert all(abs(v) <= cap * (1 + 1e-9) for v in out.wheel_rad_s)
    assert math.hypot(out.twist.vx_m_s, out.twist.vy_m_s) <= max_lin * (1 + 1e-9)
    assert abs(out.twist.wz_rad_s) <= max_ang * (1 + 1e-9)
    # Wheel speeds are exactly those of the scaled twist.
    assert out.wheel_rad_s == pytest.approx(model.ik(out.twist).wheel_rad_s)


@settings(max_examples=200, deadline=None)
@given(
    st.floats(-3.0, 3.0), st.floats(-3.0, 3.0),
    st.lists(st.floats(0.001, 0.2), min_size=1, max_size=40),
)
def test_exact_integration_reproduces_closed_form_arcs(
    wl: float, wr: float, intervals: list[float]
) -> None:
    r, track = 0.05, 0.3
    model = RobotModel(PRESETS["differential"].wheels(wheel_radius=r, track=track))
    odo = Odometry(model)
    t = 0.0
    odo.update([0.0, 0.0], t)
    for dt in intervals:
        t += dt
        state = odo.update([wl * t, wr * t], t)
    v, w = r * (wl + wr) / 2, r * (wr - wl) / track
    if abs(w) < 1e-9:
        x, y = v * t, 0.0
    else:
        x, y = v / w * math.sin(w * t), v / w * (1 - math.cos(w * t))
    assert state.pose.x_m == pytest.approx(x, abs=1e-9)
    assert state.pose.y_m == pytest.approx(y, abs=1e-9)
    assert state.pose.theta_rad == pytest.approx(
        (w * t + math.pi) % (2 * math.pi) - math.pi, abs=1e-9
    ) or abs(abs(state.pose.theta_rad) - math.pi) < 1e-9
    assert state.distance_m == pytest.approx(abs(v) * t, abs=1e-9)


def test_straight_line_near_zero_yaw_is_exact() -> None:
    # wz -> 0 uses the series; no 0/0 and no loss against the straight line.
    from gateway.core.kinematics.odometry import se2_exp

    for tiny in (0.0, 1e-12, -1e-9, 1e-5):
        p = se2_exp(1.0, 0.0, tiny)
        assert p.x_m == pytest.approx(1.0, abs=1e-9)
        assert p.y_m == pytest.approx(tiny / 2, abs=1e-12)


@settings(max_examples=200, deadline=None)
@given(twists, twists, st.floats(1.0, 50.0), st.floats(0.001, 0.05))
def test_acceleration_limit_moves_every_wheel_together(
    prev_t: Twist, t: Twist, accel: float, dt: float
) -> None:
    model = RobotModel(PRESETS["mecanum"].wheels(wheel_radius=0.05, wheelbase=0.4, track=0.3))
    prev = model.ik(prev_t)
    limits = Limits((math.inf,) * 4, max_wheel_accel_rad_s2=accel)
    out, report = apply_limits(model, model.ik(t), limits, prev, dt)
    for a, b in zip(out.wheel_rad_s, prev.wheel_rad_s, strict=True):
        assert abs(a - b) <= accel * dt * (1 + 1e-9)
    s = report.accel_scale
    expected = Twist(
        prev_t.vx_m_s + s * (t.vx_m_s - prev_t.vx_m_s),
        prev_t.vy_m_s + s * (t.vy_m_s - prev_t.vy_m_s),
        prev_t.wz_rad_s + s * (t.wz_rad_s - prev_t.wz_rad_s),
    )
    assert out.twist.vx_m_s == pytest.approx(expected.vx_m_s, abs=1e-12)
    assert out.twist.wz_rad_s == pytest.approx(expected.wz_rad_s, abs=1e-12)
    assume(s < 1.0)
    assert report.limited
