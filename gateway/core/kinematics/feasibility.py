"""Feasibility of a twist: the constraint violations inverse kinematics reports, the coupling
check of wheels steered together, and the search for the nearest feasible twist (weighted
projections onto the no-slip subspaces)."""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from gateway.core.kinematics.wheels import WheelType
from gateway.core.types import Twist

if TYPE_CHECKING:
    from collections.abc import Callable, Iterable, Sequence

    from numpy.typing import NDArray

    from gateway.core.kinematics.wheels import Wheel

__all__ = [
    "LIMIT_SLACK",
    "STILL_M_S",
    "Violation",
    "group_violation",
    "limit_excess",
    "nearest_feasible",
    "project",
]

#: Below this contact-point speed (m/s) a steered wheel keeps its angle.
STILL_M_S = 1e-9
#: Slack on steering limits (rad) so that boundary projections count as feasible.
LIMIT_SLACK = 1e-9


@dataclass(frozen=True, slots=True)
class Violation:
    """One constraint a twist breaks: the wheel, which constraint, by how much (m/s), and a
    human-readable detail."""

    wheel: str
    constraint: str
    residual_m_s: float
    detail: str


def group_violation(
    wheels: Sequence[Wheel], group: str, members: Sequence[int], vx: float, vy: float,
    wz: float,
) -> Violation | None:
    """How far the wheels ``members`` of steer group ``group`` would need different angles:
    the largest sideways contact speed relative to the fastest member's direction (``None``
    when the group stands still)."""
    vel = [(vx - wz * wheels[i].y, vy + wz * wheels[i].x) for i in members]
    ref = max(range(len(members)), key=lambda j: math.hypot(*vel[j]))
    rx, ry = vel[ref]
    norm = math.hypot(rx, ry)
    if norm <= STILL_M_S:
        return None
    ux, uy = rx / norm, ry / norm
    worst, who = 0.0, members[ref]
    for j, (px, py) in enumerate(vel):
        side = abs(px * uy - py * ux)
        if side > worst:
            worst, who = side, members[j]
    return Violation(
        wheels[who].name,
        "steering coupling",
        worst,
        f"wheels of steer group {group!r} would need different angles",
    )


def limit_excess(w: Wheel, base: float) -> tuple[float, float]:
    """For an angle ``base`` (mod pi) out of ``w``'s limits: (signed excess, nearest limit)."""
    best: tuple[float, float] = (math.inf, 0.0)
    for lim in (w.steer_min, w.steer_max):
        diff = (base - lim + math.pi / 2) % math.pi - math.pi / 2
        if abs(diff) < abs(best[0]):
            best = (diff, lim)
    return best


def project(
    xi: NDArray[np.float64], rows: Iterable[NDArray[np.float64]], weight: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Weighted least-squares projection of ``xi`` onto ``{t : row . t = 0 for every row}``."""
    m = np.array(list(rows), dtype=float).reshape(-1, 3)
    if m.size == 0:
        return xi
    mw = m / weight
    z = xi * weight
    projected: NDArray[np.float64] = np.asarray(
        (z - np.linalg.pinv(mw) @ (mw @ z)) / weight, dtype=np.float64
    )
    return projected


def nearest_feasible(
    twist: Twist,
    slide_rows: Iterable[tuple[str, float, float, float]],
    steered: Iterable[tuple[int, Wheel, float, float, float]],
    coupled: bool,
    rho: float,
    accept: Callable[[Twist], bool],
) -> Twist:
    """The twist nearest to ``twist`` (least squares, yaw weighted by ``rho``) that ``accept``
    takes; see :meth:`~gateway.core.kinematics.model.RobotModel.nearest_feasible`.

    :param slide_rows: ``(name, sliding row...)`` of the fixed wheels.
    :param steered: ``(index, wheel, x, y, heading)`` of the steered wheels.
    :param coupled: whether some wheels are steered together (zero yaw is a candidate).
    :param accept: whether inverse kinematics accepts a candidate; zero must pass.
    """
    xi = np.array([twist.vx_m_s, twist.vy_m_s, twist.wz_rad_s])
    base = [np.array(row[1:]) for row in slide_rows]
    extra: list[list[NDArray[np.float64]]] = [[]]
    if coupled:
        extra.append([np.array([0.0, 0.0, 1.0])])
    single: list[list[NDArray[np.float64]]] = []
    for _, w, x, y, h0 in steered:
        if w.type is WheelType.CASTOR:
            continue
        single.append([np.array([1.0, 0.0, -y]), np.array([0.0, 1.0, x])])
        for lim in (w.steer_min, w.steer_max):
            h = h0 + lim
            n = np.array([-math.sin(h), math.cos(h)])
            single.append([np.array([n[0], n[1], -n[0] * y + n[1] * x])])
    extra.extend(single)
    extra.extend(a + b for a, b in itertools.combinations(single, 2))
    best, best_cost = Twist(), math.inf
    weight = np.array([1.0, 1.0, rho])
    for rows in extra:
        cand = project(xi, base + rows, weight)
        t = Twist(float(cand[0]), float(cand[1]), float(cand[2]))
        cost = float(np.sum(((cand - xi) * weight) ** 2))
        if cost < best_cost - 1e-15 and accept(t):
            best, best_cost = t, cost
    return best
