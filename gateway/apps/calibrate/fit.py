r"""Least squares for ``wheelgate calibrate``: the factors that make the odometry end where
the robot was measured to end.

The odometry's end poses are smooth in the factors but not linear, so the fit is Gauss-Newton
[Nocedal & Wright, *Numerical Optimization*, 2nd ed., sec. 10.3] on a numerical Jacobian,
each step halved until it lowers the cost.  The step is the truncated-SVD least-squares
solution: a combination of factors that moves the end poses by less than the measurements'
accuracy for a 1 % change is left where it is and reported, not guessed (two squares, for
instance, hardly tell the overall wheel size: both wheels and the track 1 % larger move the
ends by a few millimetres).  Each fitted factor's uncertainty is that accuracy carried
through the fit (one standard deviation, the measurements' errors taken as independent).
Pure: the caller's function integrates the odometry.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from collections.abc import Callable, Sequence

    from numpy.typing import NDArray

__all__ = ["ACCURACY_M", "Fit", "fit"]

#: How well an end pose is measured on the floor by default, m (a tape and a square: about
#: 5 mm; the heading weighted by the robot's size, as the residual has it).
ACCURACY_M = 5e-3
#: The most Gauss-Newton steps, and the factor change below which the fit has converged.
MAX_STEPS, CONVERGED = 50, 1e-10
#: The step of the numerical derivative (the factors are near 1).
DERIVATIVE_STEP = 1e-6


@dataclass(frozen=True, slots=True)
class Fit:
    """What :func:`fit` found.

    :param factors: the fitted factors (1.0: unchanged).
    :param before: the residual at factors 1.0.
    :param after: the residual at ``factors``.
    :param undetermined: unit combinations of factors the runs do not determine (each left
        as it was), largest component positive.
    :param steps: Gauss-Newton steps taken.
    :param uncertainty: per factor, its standard deviation from the measurements' accuracy
        (the determined combinations only).
    """

    factors: tuple[float, ...]
    before: tuple[float, ...]
    after: tuple[float, ...]
    undetermined: tuple[tuple[float, ...], ...]
    steps: int
    uncertainty: tuple[float, ...]


def _cost(r: NDArray[np.float64]) -> float:
    return float(r @ r)


def fit(residual: Callable[[Sequence[float]], Sequence[float]], n: int,
        accuracy_m: float = ACCURACY_M) -> Fit:
    """Factors from 1.0 that minimise ``|residual(factors)|``.

    :param residual: the residual vector (m) for factors.
    :param n: the number of factors.
    :param accuracy_m: how well each residual component is measured, m.
    """
    def at(q: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.array(residual([float(x) for x in q]), dtype=np.float64)

    p = np.ones(n)
    r0 = at(p)
    r, undetermined, steps, sigma = r0, np.zeros((0, n)), 0, np.zeros(n)
    for steps in range(1, MAX_STEPS + 1):  # noqa: B007 - the count is reported
        jac = np.empty((r.size, n))
        for k in range(n):
            dp = p.copy()
            dp[k] += DERIVATIVE_STEP
            jac[:, k] = (at(dp) - r) / DERIVATIVE_STEP
        u, s, vt = np.linalg.svd(jac)  # vt: n x n; with fewer rows than n, those no row
        s = np.concatenate([s, np.zeros(n - s.size)])  # touches come last, at 0
        keep = np.flatnonzero(s * 0.01 >= accuracy_m)
        undetermined = np.delete(vt, keep, axis=0)
        sigma = accuracy_m * np.sqrt(((vt[keep] / s[keep, None]) ** 2).sum(axis=0))
        step = -(vt[keep].T @ ((u[:, keep].T @ r) / s[keep]))
        for _ in range(30):
            candidate = at(p + step)
            if _cost(candidate) < _cost(r):
                break
            step /= 2
        else:
            break  # no step lowers the cost: at the minimum (up to rounding)
        p, r = p + step, candidate
        if float(np.max(np.abs(step))) < CONVERGED:
            break
    signs = [1.0 if v[int(np.argmax(np.abs(v)))] > 0 else -1.0 for v in undetermined]
    return Fit(tuple(float(x) for x in p), tuple(float(x) for x in r0),
               tuple(float(x) for x in r),
               tuple(tuple(float(c * sign) for c in v) for v, sign in zip(undetermined, signs,
                                                                          strict=True)),
               steps, tuple(float(x) for x in sigma))

