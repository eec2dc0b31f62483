r"""Least-squares machinery of forward kinematics behind :meth:`RobotModel.fk
<gateway.core.kinematics.model.RobotModel.fk>`.

:class:`FkSolver` stacks every rolling equation of a measured wheel and every sliding equation
of a fixed or steerable wheel into :math:`A\,\xi = b` and solves it by least squares.  For a
robot without steered wheels it precomputes the pseudo-inverse and, per pattern of unmeasured
wheels, the pure-Python :class:`~gateway.core.kinematics.lsq.FkPlan` of the per-sample path.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from gateway.core.errors import KinematicsError
from gateway.core.kinematics.lsq import FkPlan
from gateway.core.kinematics.results import FkResult
from gateway.core.kinematics.wheels import CONSTRAINING
from gateway.core.types import Twist

if TYPE_CHECKING:
    from collections.abc import Sequence

    from numpy.typing import NDArray

    from gateway.core.kinematics.wheels import Wheel

__all__ = ["FkSolver", "system"]


def system(
    wheels: Sequence[Wheel], speeds: Sequence[float | None], steer: Sequence[float | None]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``(A, b)``: the rolling rows of the measured wheels (speed not ``None``), then the
    sliding rows of the fixed and steerable wheels, at the steering angles ``steer``."""
    rows: list[tuple[float, float, float]] = []
    rhs: list[float] = []
    for i, w in enumerate(wheels):
        sigma = steer[i] or 0.0
        if speeds[i] is not None:
            rows.append(w.rolling_row(sigma))
            rhs.append(w.radius * float(speeds[i] or 0.0))
    for i, w in enumerate(wheels):
        if w.type in CONSTRAINING:
            rows.append(w.sliding_row(steer[i] or 0.0))
            rhs.append(0.0)
    return np.array(rows, dtype=float).reshape(len(rows), 3), np.array(rhs)


class FkSolver:
    """Forward kinematics of a wheel set by least squares.

    :param wheels: the wheels, in model order.
    :param neutral_steer: their neutral steering angles (``None`` for wheels not steered).
    """

    def __init__(self, wheels: Sequence[Wheel], neutral_steer: Sequence[float | None]) -> None:
        self.wheels: tuple[Wheel, ...] = tuple(wheels)
        self.n = len(self.wheels)
        self.neutral_steer = neutral_steer
        self._steered = any(w.steered for w in self.wheels)
        self._static = self._build_static()
        #: Pure-Python least-squares plans of a model without steered wheels, by the pattern
        #: of unmeasured wheels (``None`` when that pattern leaves the twist undetermined).
        self._plans: dict[tuple[bool, ...], FkPlan | None] = {}

    def _build_static(self) -> NDArray[np.float64] | None:
        if self._steered:
            return None
        a, _ = self.system([1.0] * self.n, self.neutral_steer)
        if int(np.linalg.matrix_rank(a)) < 3:
            return None
        pinv: NDArray[np.float64] = np.asarray(np.linalg.pinv(a), dtype=np.float64)
        return pinv

    def plan(self, wheel_rad_s: Sequence[float | None]) -> FkPlan | None:
        """The precomputed least squares for the neutral angles and these measured wheels
        (built on first use of each pattern); ``None`` if the model has steered wheels or
        the pattern leaves the twist undetermined."""
        if self._steered:
            return None
        key = tuple(v is None for v in wheel_rad_s)
        try:
            return self._plans[key]
        except KeyError:
            pass
        speeds = [None if missing else 1.0 for missing in key]
        a, _ = self.system(speeds, self.neutral_steer)
        plan = None
        if int(np.linalg.matrix_rank(a)) >= 3:
            pinv = np.asarray(np.linalg.pinv(a), dtype=np.float64)
            measured = tuple((i, w.radius) for i, w in enumerate(self.wheels)
                             if not key[i])
            m = len(measured)
            rows = [(float(r[0]), float(r[1]), float(r[2])) for r in a]
            plan = FkPlan(
                measured=measured,
                pinv_x=tuple(float(v) for v in pinv[0, :m]),
                pinv_y=tuple(float(v) for v in pinv[1, :m]),
                pinv_w=tuple(float(v) for v in pinv[2, :m]),
                rolling=tuple(rows[:m]),
                sliding=tuple(rows[m:]),
            )
        self._plans[key] = plan
        return plan

    def system(
        self, speeds: Sequence[float | None], steer: Sequence[float | None]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """:func:`system` of these wheels."""
        return system(self.wheels, speeds, steer)

    def solve(
        self, wheel_rad_s: Sequence[float | None], st: Sequence[float | None]
    ) -> FkResult:
        """The general (numpy) solution for validated speeds and steering angles.

        :raises KinematicsError: if the measured wheels leave the twist undetermined.
        """
        a, b = self.system(wheel_rad_s, st)
        if self._static is not None and all(v is not None for v in wheel_rad_s):
            xi = self._static @ b
        else:
            if int(np.linalg.matrix_rank(a)) < 3:
                raise KinematicsError(
                    f"Expected enough wheel speeds to fix the twist (rank 3), but the "
                    f"{sum(v is not None for v in wheel_rad_s)} given leave it undetermined"
                )
            xi = np.asarray(np.linalg.lstsq(a, b, rcond=None)[0], dtype=np.float64)
        res = a @ xi - b
        per_wheel = [0.0] * self.n
        k = 0
        for i in range(self.n):
            if wheel_rad_s[i] is not None:
                per_wheel[i] = float(-res[k])
                k += 1
        rms = float(math.sqrt(float(np.mean(res**2)))) if res.size else 0.0
        return FkResult(
            Twist(float(xi[0]), float(xi[1]), float(xi[2])), tuple(per_wheel), rms
        )
