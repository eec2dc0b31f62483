"""The kinematics fast paths give the same results as the general code they shortcut.

Issue 6: precomputed pure-Python forward kinematics (against numpy's least squares),
odometry's one-allocation SE(2) step, the loop's inverse-kinematics memo and the limits it
skips while nothing changes.  Issue 15: the supervisor's solve of an accepted twist reused by
the loop (one solve per new twist).
"""

from __future__ import annotations

import copy
import dataclasses
import math
import random
import re
from typing import TYPE_CHECKING, Any

import pytest

import gateway.runtime.loop
from gateway.config import load_config
from gateway.core.control import Accepted, Source
from gateway.core.errors import KinematicsError
from gateway.core.kinematics import apply_limits
from gateway.core.kinematics.odometry import Odometry, OdometryState, Pose, compose, se2_exp
from gateway.core.types import (
    GatewayState,
    Twist,
)
from gateway.runtime.loop import Gateway
from tests.conftest import CONFIG_DIR
from tests.e2e_helpers import Rig, virtual_config

if TYPE_CHECKING:
    from pathlib import Path

    from gateway.core.kinematics import IkResult, RobotModel

CONFIGS = [None, *sorted(CONFIG_DIR.glob("*.yaml"))]


def _close(a: float, b: float) -> bool:
    return abs(a - b) <= 1e-12 * max(1.0, abs(a), abs(b))


@pytest.mark.parametrize("path", CONFIGS, ids=lambda p: "default" if p is None else p.stem)
def test_fk_fast_path_matches_numpy(path: Path | None) -> None:
    model = load_config(path).model
    rng = random.Random(1)
    fast = 0
    for trial in range(60):
        speeds: list[float | None] = [rng.uniform(-30.0, 30.0) for _ in range(model.n)]
        if trial % 3 == 0:
            speeds[rng.randrange(model.n)] = None
        steer = model.neutral_steer
        try:
            ref = model.fk_solver.solve(speeds, steer)
        except KinematicsError:  # too few wheels measured: both paths refuse
            with pytest.raises(KinematicsError):
                model.fk(speeds, steer)
            continue
        got = model.fk(speeds, steer)
        fast += model.fk_solver.plan(speeds) is not None
        assert _close(got.twist.vx_m_s, ref.twist.vx_m_s)
        assert _close(got.twist.vy_m_s, ref.twist.vy_m_s)
        assert _close(got.twist.wz_rad_s, ref.twist.wz_rad_s)
        assert _close(got.residual_m_s, ref.residual_m_s)
        assert all(_close(a, b) for a, b in zip(got.wheel_residual_m_s,
                                                ref.wheel_residual_m_s, strict=True))
        vx, vy, wz, rms = model.fk_twist(speeds, steer)
        assert (vx, vy, wz, rms) == (got.twist.vx_m_s, got.twist.vy_m_s, got.twist.wz_rad_s,
                                     got.residual_m_s)
    steered = any(w.steered for w in model.wheels)
    assert (fast == 0) == steered  # the fast path is taken exactly for unsteered robots


def test_odometry_step_is_compose_of_exp() -> None:
    """The odometry's step on plain numbers is ``compose(pose, se2_exp(...))`` to the bit
    (the Taylor branch, the exact one and a zero turn), and its twist, slip and distance are
    the interval's."""
    rng = random.Random(2)
    odo = Odometry(load_config(None).model)
    for k in range(500):
        pose = Pose(rng.uniform(-5, 5), rng.uniform(-5, 5), rng.uniform(-math.pi, math.pi))
        d = (rng.uniform(-0.1, 0.1), rng.uniform(-0.1, 0.1),
             rng.choice([0.0, 1e-6, rng.uniform(-0.5, 0.5)]))
        odo.state = OdometryState(pose, Twist(), 0.0, 1.0, 2.0)
        dt = (2.0 + rng.choice([0.0, 0.001 * (k % 7 + 1)])) - 2.0  # the interval as stamped
        odo._step(*d, 0.25, 2.0 + dt)
        inv = 1.0 / dt if dt else 0.0
        got = odo.state
        assert got.pose == compose(pose, se2_exp(*d))
        assert got.twist == Twist(d[0] * inv, d[1] * inv, d[2] * inv)
        assert got.slip_m_s == (0.25 / dt if dt else 0.0)
        assert got.distance_m == 1.0 + math.hypot(d[0], d[1])
        assert got.timestamp_s == 2.0 + dt


def test_ik_memo_follows_the_target_object(channel: str) -> None:
    cfg = load_config(None, {"interface": "virtual", "channel": channel})
    gw = Gateway(cfg)
    try:
        target = Twist(0.3, 0.1, 0.2)
        first = gw._solve(target)
        assert first == cfg.model.try_ik(target, gw.prev.steer_rad)
        assert gw._solve(target) is first  # same object: no second solve
        other = gw._solve(Twist(0.3, 0.1, 0.2))  # equal but new: solved again
        assert other == first and other is not first
    finally:
        gw.close()
    cfg = load_config(CONFIG_DIR / "differential_tub.yaml",
                      {"interface": "virtual", "channel": channel})
    gw = Gateway(cfg)
    try:
        assert gw._solve(Twist(0.0, 0.5, 0.0)) == cfg.model.ik(Twist())  # infeasible -> zero
    finally:
        gw.close()


class _AlwaysLimited(Gateway):
    """A gateway that runs the limits every cycle (the general path): its solves are new
    objects, never the command of the cycle before."""

    def _solve(self, twist: Twist) -> IkResult:
        return copy.copy(super()._solve(twist))


@pytest.mark.parametrize("robot", ["mecanum.yaml", "swerve.yaml", "ackermann.yaml"])
def test_limits_skipped_only_when_they_would_change_nothing(
        channel: str, robot: str, monkeypatch: pytest.MonkeyPatch) -> None:
    configs = [virtual_config(CONFIG_DIR / robot, f"{channel}-{k}") for k in range(2)]
    if robot == "swerve.yaml":  # its ramps come from the steering-rate limit alone
        configs = [dataclasses.replace(c, limits=dataclasses.replace(
            c.limits, max_wheel_accel_rad_s2=math.inf)) for c in configs]
    rigs = [Rig(c) for c in configs]
    rigs[1].gw.__class__ = _AlwaysLimited
    fast_model = rigs[0].gw.model
    calls = {"fast": 0}
    real = apply_limits

    def counting(model: RobotModel, *args: Any) -> Any:
        calls["fast"] += model is fast_model
        return real(model, *args)

    monkeypatch.setattr(gateway.runtime.loop, "apply_limits", counting)
    rng = random.Random(3)
    try:
        for rig in rigs:
            rig.enable()
        cycles = calls["fast"] = 0
        for k in range(20):
            if k % 7 == 6:  # an e-stop, which jumps to zero past the limits, and back
                for rig in rigs:
                    rig.gw.supervisor.estop()
                for _ in range(3):
                    lockstep(rigs)
                for rig in rigs:
                    rig.gw.supervisor.enable(rig.t)
                while rigs[0].gw.state is not GatewayState.RUNNING:
                    lockstep(rigs)
            twist = Twist(rng.uniform(-0.6, 0.6), 0.0, rng.uniform(-0.8, 0.8))
            hold = rng.choice((1, 3, 25, 80))  # ramps that finish, and ones cut short
            for rig in rigs:
                rig.gw.twist(twist, rig.t, Source.INTERNAL)
            for _ in range(hold):
                lockstep(rigs)
                cycles += 1
        assert all(rig.gw.state is GatewayState.RUNNING for rig in rigs)
        assert calls["fast"] <= 0.75 * cycles  # the shortcut was taken (runs are deterministic)
    finally:
        for rig in rigs:
            rig.close()


def lockstep(rigs: list[Rig]) -> None:
    """One cycle of both rigs; the same commands and limit reports come out."""
    for rig in rigs:
        rig.advance(rig.period)
    fast, slow = (rig.gw for rig in rigs)
    assert fast.state is slow.state
    assert fast.prev == slow.prev
    assert fast.limit_report == slow.limit_report


@pytest.mark.parametrize("robot", ["mecanum.yaml", "swerve.yaml"])
def test_one_inverse_kinematics_solve_per_new_twist(
        channel: str, robot: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """The supervisor's feasibility check of an accepted twist is the solve the loop uses: a
    new twist costs one solve, the cycle that follows it none; on a robot without steered
    wheels no cycle after it solves again (steered wheels turning through the steering-rate
    limit start each cycle from new angles, a new solve each)."""
    cfg = virtual_config(CONFIG_DIR / robot, channel)
    # No acceleration limit: the limits then solve nothing themselves.
    cfg = dataclasses.replace(cfg, limits=dataclasses.replace(
        cfg.limits, max_wheel_accel_rad_s2=math.inf))
    with Rig(cfg) as rig:
        rig.enable()
        model = rig.gw.model
        calls = [0]
        real = type(model)._solve

        def counting(self: RobotModel, *args: Any) -> Any:
            calls[0] += self is model
            return real(self, *args)

        monkeypatch.setattr(type(model), "_solve", counting)
        for twist in (Twist(0.3, 0.0, 0.0), Twist(0.3, 0.2, 0.1), Twist(0.0, 0.0, 0.4)):
            calls[0] = 0
            result = rig.gw.twist(twist, rig.t, Source.INTERNAL)
            assert isinstance(result, Accepted) and result.ik is not None
            assert calls[0] == 1
            rig.advance(rig.period)
            assert calls[0] == 1
            assert rig.gw.prev.twist == twist
            rig.advance(30 * rig.period)
            if robot == "mecanum.yaml":
                assert calls[0] == 1
        assert rig.gw.state is GatewayState.RUNNING


def test_ik_of_an_accepted_twist_is_the_loops_own_solve(channel: str) -> None:
    """The solve the supervisor hands over equals the loop's own for that twist."""
    for robot in ("mecanum.yaml", "swerve.yaml", "ackermann.yaml"):
        with Rig(virtual_config(CONFIG_DIR / robot, f"{channel}-{robot}")) as rig:
            rig.enable()
            rng = random.Random(4)
            for _ in range(15):
                twist = Twist(rng.uniform(-0.5, 0.5), rng.uniform(-0.3, 0.3),
                              rng.uniform(-0.6, 0.6))
                steer = rig.gw.prev.steer_rad
                result = rig.gw.twist(twist, rig.t, Source.INTERNAL)
                if isinstance(result, Accepted) and result.ik is not None:
                    assert rig.gw._solve(twist) is result.ik
                    assert result.ik == rig.gw.model.try_ik(twist, steer)
                rig.advance(rng.choice((1, 5)) * rig.period)


@pytest.mark.parametrize("path", CONFIGS, ids=lambda p: "default" if p is None else p.stem)
def test_odometry_per_sample_path_is_the_general_one(path: Path | None) -> None:
    """Issue 15: odometry's per-sample path (every wheel measured, no steering: the plan's
    least squares of the changes) gives exactly the states of the general path, and leaves
    every other sample (a wheel unmeasured, steering angles, a value that is not finite) to
    it, error messages included."""
    model = load_config(path).model
    fast, general = Odometry(model), Odometry(model)
    general._plan = None
    steered = any(w.steered for w in model.wheels)
    assert (fast._plan is None) == steered
    rng = random.Random(4)
    positions = [0.0] * model.n
    taken = 0
    for k in range(300):
        positions = [p + rng.uniform(-0.05, 0.05) for p in positions]
        sample: list[float | None] = list(positions)
        if k % 17 == 5:
            sample[rng.randrange(model.n)] = None
        if k % 29 == 7:
            sample[rng.randrange(model.n)] = rng.choice([math.nan, math.inf])
        steer = None if k % 3 else [0.0 if w.steered else None for w in model.wheels]
        if steered and k % 5 == 0:
            steer = [rng.uniform(-0.3, 0.3) if w.steered else None for w in model.wheels]
        t = 0.001 * k
        try:
            want = general.update(sample, t, steer)
        except KinematicsError as err:
            with pytest.raises(KinematicsError, match=re.escape(str(err))):
                fast.update(sample, t, steer)
            continue
        before = fast._last
        got = fast.update(sample, t, steer)
        taken += fast._plan is not None and before is not None and None not in sample \
            and None not in before
        assert got == want
    assert (taken > 150) == (not steered)
