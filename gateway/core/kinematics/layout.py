r"""How well a robot's driven wheels tell its motions apart.

Forward kinematics (odometry, :class:`~gateway.core.kinematics.forward.FkSolver`) solves
:math:`A\,\xi = b`: one rolling equation per driven wheel (its rim speed) and one sliding
equation per fixed or steerable wheel (no sideways speed).  A motion :math:`\xi` that changes
none of these equations turns no driven wheel and is resisted by no wheel: the gateway can
neither drive it nor measure it.  One that changes them very little is measured with a large
error, a wheel-speed error of 1 mm/s reading as metres a second.  Neither happens on a real
robot; both happen on a layout written wrong: two wheels written at one place (the right wheel
of a differential drive written as a copy of the left wheel's line, its ``alpha`` and ``beta``:
``wheelgate ik --wz 1`` then turns both wheels alike, which drives the robot backwards instead
of turning it).

:func:`weakest_motion` finds the motion the equations notice least (the right singular vector
of the smallest singular value, [Golub & Van Loan, *Matrix Computations*, 4th ed., sec. 2.4]).
It is computed at the neutral steering angles, about the centroid of the wheels' mounting
points, with the yaw rate weighted by the wheels' RMS distance from it, so the figure does not
depend on where the body frame's origin is, how it is turned, or the robot's size.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from gateway.core.kinematics.forward import system
from gateway.core.types import Twist

if TYPE_CHECKING:
    from collections.abc import Sequence

    from numpy.typing import NDArray

    from gateway.core.kinematics.wheels import Wheel

__all__ = [
    "MIN_EXTENT_M", "NOTICED_LITTLE_M_S", "NOTICED_NONE_M_S", "closest_pair", "equations",
    "weakest_motion",
]

#: Below this (m/s of the equations per 1 m/s of the fastest mounting point) a motion is not
#: noticed at all: the layout is singular (rounding leaves about 1e-16).
NOTICED_NONE_M_S = 1e-9
#: Below this a motion is noticed too little to measure: odometry would read a wheel-speed
#: error as more than 100 times larger.  Every sound layout is at about 0.5 to 1 (each
#: shipped robot and preset: 0.49, a differential drive with a castor, to 1).
NOTICED_LITTLE_M_S = 0.01
#: The smallest extent a robot is taken to have, m: wheels closer than this to each other are
#: at one place (a robot smaller than a millimetre is a layout written wrong).
MIN_EXTENT_M = 1e-3


def weakest_motion(wheels: Sequence[Wheel], driven: Sequence[bool]) -> tuple[Twist, float]:
    """The motion the no-slip equations notice least, and how much they notice it.

    :param wheels: the robot's wheels (steered ones at their neutral angle).
    :param driven: per wheel, whether its speed is commanded and measured (it has a motor).
    :return: ``(twist, noticed)``: the motion, scaled so that the fastest wheel's mounting
        point moves at 1 m/s, and the largest speed (m/s) it gives any equation: a driven
        wheel's rim speed or a fixed or steerable wheel's sideways speed.  ``0`` (up to
        rounding): not noticed at all.  Where several motions are noticed equally little
        (a plane of them: a symmetric layout), any one of them.
    """
    a, to_origin = equations(wheels, driven)
    _, _, vt = np.linalg.svd(a)
    vx, vy, wz = (float(c) for c in to_origin @ vt[-1])
    points = [(w.x, w.y) for w in wheels]
    # (at least a point MIN_EXTENT_M from the centre of a turn: every wheel at one place)
    fastest = max(*(math.hypot(vx - wz * y, vy + wz * x) for x, y in points),
                  MIN_EXTENT_M * abs(wz))
    sign = -1.0 if (wz, vx, vy) < (0.0, 0.0, 0.0) else 1.0  # one sign, whatever LAPACK gives
    twist = Twist(vx, vy, wz).scaled(sign / fastest)
    rows = _rows(wheels, driven)
    xi = np.array([twist.vx_m_s, twist.vy_m_s, twist.wz_rad_s])
    return twist, float(np.max(np.abs(rows @ xi))) if rows.size else 0.0


def equations(
    wheels: Sequence[Wheel], driven: Sequence[bool]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``(A, T)``: the equations of forward kinematics with the driven wheels measured
    (:func:`~gateway.core.kinematics.forward.system`, at least three rows: zeros added), for
    a twist ``(u, v, s w)`` about the centroid of the mounting points, ``s`` their RMS
    distance from it; ``T`` turns such a twist into ``(vx, vy, wz)`` about the body frame's
    origin."""
    rows = _rows(wheels, driven)
    rows = np.vstack([rows, np.zeros((max(0, 3 - len(rows)), 3))])  # fewer than unknowns
    n = len(wheels)
    cx, cy = sum(w.x for w in wheels) / n, sum(w.y for w in wheels) / n
    size = max(math.sqrt(sum((w.x - cx) ** 2 + (w.y - cy) ** 2 for w in wheels) / n),
               MIN_EXTENT_M)
    # A twist (u, v, size * w) about the centroid is (u + w * cy, v - w * cx, w) at the origin.
    to_origin = np.array([[1.0, 0.0, cy / size], [0.0, 1.0, -cx / size], [0.0, 0.0, 1.0 / size]])
    return rows @ to_origin, to_origin


def _rows(wheels: Sequence[Wheel], driven: Sequence[bool]) -> NDArray[np.float64]:
    """The system forward kinematics solves, the driven wheels measured, at the neutral
    steering angles."""
    return system(wheels, [1.0 if d else None for d in driven], [None] * len(wheels))[0]


def closest_pair(wheels: Sequence[Wheel]) -> tuple[str, str, float] | None:
    """The two wheels whose mounting points are closest, and their distance (m); ``None``
    for a robot with one wheel."""
    best: tuple[str, str, float] | None = None
    for i, a in enumerate(wheels):
        for b in wheels[i + 1:]:
            dist = math.hypot(a.x - b.x, a.y - b.y)
            if best is None or dist < best[2]:
                best = (a.name, b.name, dist)
    return best
