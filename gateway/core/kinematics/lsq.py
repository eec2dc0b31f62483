r"""Precomputed least squares for forward kinematics with a constant system matrix.

For a robot without steered wheels, the rows of the forward-kinematics system
:math:`A\,\xi = b` (one rolling row per measured wheel, one sliding row per fixed wheel) do not
change between calls; only :math:`b = (r_i\,\dot\varphi_i, \ldots, 0, \ldots)` does.  So
:math:`\xi = A^{+} b` needs only the columns of the pseudo-inverse that belong to the measured
wheels, and the residual :math:`A\xi - b` the rows of :math:`A`.  :class:`FkPlan` keeps both as
plain Python floats: per call that is a few dozen multiplications, where numpy's ``@``,
``mean`` and the array conversions of a 7x3 system cost ten times as much.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from collections.abc import Sequence

Row = tuple[float, float, float]


@dataclass(frozen=True, slots=True)
class FkPlan:
    """The least-squares solution of one system for one set of measured wheels.

    :param measured: ``(wheel index, radius)`` of every measured wheel, in row order.
    :param pinv_x: row of :math:`A^{+}` giving ``vx``, restricted to the measured wheels.
    :param pinv_y: the same for ``vy``.
    :param pinv_w: the same for ``wz``.
    :param rolling: the rolling rows of the measured wheels (same order as ``measured``).
    :param sliding: the sliding rows (right-hand side zero).
    """

    measured: tuple[tuple[int, float], ...]
    pinv_x: tuple[float, ...]
    pinv_y: tuple[float, ...]
    pinv_w: tuple[float, ...]
    rolling: tuple[Row, ...]
    sliding: tuple[Row, ...]

    def solve(
        self, n: int, wheel_rad_s: Sequence[float | None], per_wheel: bool
    ) -> tuple[float, float, float, float, list[float] | None]:
        """``(vx, vy, wz, RMS residual, per-wheel residual)`` for these wheel speeds.

        :param n: the number of wheels (length of the per-wheel residual list).
        :param wheel_rad_s: every wheel's speed; those in :attr:`measured` must not be None.
        :param per_wheel: whether to return the per-wheel residuals (measured minus
            predicted rim speed; ``None`` when not asked for).
        """
        rhs = [radius * float(wheel_rad_s[i] or 0.0) for i, radius in self.measured]
        return self._fit(n, rhs, per_wheel)

    def increment(
        self, now: Sequence[float], before: Sequence[float]
    ) -> tuple[float, float, float, float]:
        """:meth:`solve` of the changes ``now - before`` of every wheel's angle, as
        ``(dx, dy, dtheta, RMS residual)``, for the plan with every wheel measured: the same
        arithmetic without the list of changes (odometry's per-sample path).

        A change that is not finite makes all three displacements non-finite (the caller's
        check).
        """
        rhs = [radius * ((now[i] - before[i]) or 0.0) for i, radius in self.measured]
        vx, vy, wz, rms, _ = self._fit(0, rhs, False)
        return vx, vy, wz, rms

    def _fit(
        self, n: int, rhs: list[float], per_wheel: bool
    ) -> tuple[float, float, float, float, list[float] | None]:
        """The least squares of the right-hand sides ``rhs`` of the measured wheels' rows."""
        vx = vy = wz = 0.0
        for px, py, pw, b in zip(self.pinv_x, self.pinv_y, self.pinv_w, rhs, strict=True):
            vx += px * b
            vy += py * b
            wz += pw * b
        residuals = [0.0] * n if per_wheel else None
        squares = 0.0
        for (i, _), (a0, a1, a2), b in zip(self.measured, self.rolling, rhs, strict=True):
            r = a0 * vx + a1 * vy + a2 * wz - b
            if residuals is not None:
                residuals[i] = -r
            squares += r * r
        for a0, a1, a2 in self.sliding:
            r = a0 * vx + a1 * vy + a2 * wz
            squares += r * r
        rms = math.sqrt(squares / (len(self.rolling) + len(self.sliding)))
        return vx, vy, wz, rms, residuals
