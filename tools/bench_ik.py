"""Benchmark: inverse kinematics plus limits for a 4-wheel robot, per call.

Method: for each robot, time batches of N calls of ``model.ik`` followed by ``apply_limits``
(speed, acceleration and steering-rate limits from the previous command) with
``time.perf_counter_ns``; repeat the batch R times and report the median and best per-call
cost.  Beside it, the same-run cost of two references on the same machine gives a
machine-independent ratio: a hand-written four-line mecanum IK in plain Python (the floor for
any Python IK) and one numpy ``4x3 @ 3`` product (what a naive numpy IK costs at least).

Run: ``python tools/bench_ik.py`` (target: IK + limits at most 20 us median per call).
"""

from __future__ import annotations

import gc
import math
import statistics
import time
from typing import TYPE_CHECKING

import numpy as np

from gateway.core.kinematics import PRESETS, Limits, RobotModel, apply_limits
from gateway.core.types import Twist

if TYPE_CHECKING:
    from collections.abc import Callable

N = 2000
R = 15


def per_call_us(fn: Callable[[int], None]) -> tuple[float, float]:
    """(median, best) per-call cost in microseconds over R batches of N calls."""
    samples = []
    for _ in range(R):
        t0 = time.perf_counter_ns()
        fn(N)
        samples.append((time.perf_counter_ns() - t0) / N / 1000.0)
    return statistics.median(samples), min(samples)


def robot(name: str, **params: float) -> RobotModel:
    return RobotModel(PRESETS[name].wheels(**params))


def bench_robot(model: RobotModel) -> Callable[[int], None]:
    limits = Limits((40.0,) * model.n, max_wheel_accel_rad_s2=200.0,
                    max_linear_m_s=2.0, max_angular_rad_s=3.0)
    twists = [Twist(0.5 * math.cos(k / 7), 0.3 * math.sin(k / 5), 0.4 * math.sin(k / 3))
              for k in range(64)]
    twists = [model.nearest_feasible(t) for t in twists]

    def run(n: int) -> None:
        prev = model.ik(Twist())
        for k in range(n):
            res = model.ik(twists[k & 63], prev.steer_rad)
            prev, _ = apply_limits(model, res, limits, prev, 0.001)

    return run


def reference_python(n: int) -> None:
    k_, r = 0.35, 0.05
    for k in range(n):
        vx, vy, wz = 0.5, 0.1 * (k & 3), 0.2
        _ = ((vx - vy - k_ * wz) / r, (vx + vy + k_ * wz) / r,
             (vx + vy - k_ * wz) / r, (vx - vy + k_ * wz) / r)


_H = np.ones((4, 3))
_X = np.ones(3)


def reference_numpy(n: int) -> None:
    for _ in range(n):
        _H @ _X


def main() -> None:
    gc.collect()
    gc.freeze()
    print(__doc__.split("\n\n")[1].replace("\n", " "))
    print(f"N = {N} calls per batch, R = {R} batches\n")
    py_med, _ = per_call_us(reference_python)
    np_med, _ = per_call_us(reference_numpy)
    print(f"reference: plain-Python mecanum IK  {py_med:7.3f} us")
    print(f"reference: numpy 4x3 @ 3            {np_med:7.3f} us\n")
    print(f"{'robot':<24} {'median us':>10} {'best us':>9} {'x python ref':>13} "
          f"{'x numpy ref':>12}")
    for name, model in (
        ("mecanum (4 swedish)", robot("mecanum", wheel_radius=0.05, wheelbase=0.4, track=0.3)),
        ("skid_steer (4 fixed)", robot("skid_steer", wheel_radius=0.1, track=0.5,
                                       wheelbase=0.45)),
        ("swerve (4 steerable)", robot("swerve", wheel_radius=0.05, wheelbase=0.5, track=0.5,
                                       max_steer_rate=8.0)),
        ("ackermann (2+2)", robot("ackermann", wheel_radius=0.1, wheelbase=0.5, track=0.4,
                                  max_steer=0.9)),
    ):
        med, best = per_call_us(bench_robot(model))
        print(f"{name:<24} {med:10.2f} {best:9.2f} {med / py_med:13.1f} {med / np_med:12.1f}")
    print("\ntarget: <= 20 us median per IK + limits call for a 4-wheel robot")


if __name__ == "__main__":
    main()
