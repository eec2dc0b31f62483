r"""The robot as a stack of wheel constraints: inverse and forward kinematics, feasibility.

:class:`RobotModel` stacks the wheels of :mod:`gateway.kinematics.wheels` into the matrices of
the general model,

.. math::

    J_1(\beta_s, \beta_c)\,\xi - J_2\,\dot\varphi = 0, \qquad C_1(\beta_s)\,\xi = 0,

and precomputes what the per-cycle path needs as plain Python floats (numpy calls on 4x3
arrays cost more than the arithmetic).  numpy is used at build time and on the error path.

* **Inverse kinematics** (:meth:`RobotModel.ik`): twist -> wheel angular speeds, steering
  angles of steered wheels (nearest to their current angle, reversing the drive rather than
  turning past 90 degrees, within limits) and the swivel rate of castor wheels.
* **Feasibility**: fixed and steerable wheels may not slide; a twist whose sliding residual
  exceeds ``slip_tolerance_m_s``, that needs a steering angle out of limits, or that needs
  different angles from wheels steered together raises
  :class:`~gateway.errors.InfeasibleTwistError` with the nearest feasible twist.
* **Forward kinematics** (:meth:`RobotModel.fk`): wheel speeds (and steering angles) -> twist
  by least squares over every rolling and sliding equation, with the residual in m/s as a slip
  indicator for redundant drives.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from gateway.errors import InfeasibleTwistError, KinematicsError
from gateway.kinematics.lsq import FkPlan
from gateway.kinematics.wheels import CONSTRAINING, Wheel, WheelType
from gateway.types import Twist

if TYPE_CHECKING:
    from collections.abc import Iterable, Sequence

    from numpy.typing import NDArray

#: Below this contact-point speed (m/s) a steered wheel keeps its angle.
_STILL_M_S = 1e-9
#: Slack on steering limits (rad) so that boundary projections count as feasible.
_LIMIT_SLACK = 1e-9


@dataclass(frozen=True, slots=True)
class IkResult:
    """Inverse kinematics of one twist.

    :param twist: the twist the wheels realise.
    :param wheel_rad_s: angular speed of every wheel (model order), rad/s.
    :param steer_rad: steering angle of every steered wheel, ``None`` for the others.
    :param steer_rate_rad_s: swivel rate of castor wheels, ``None`` for the others.
    """

    twist: Twist
    wheel_rad_s: tuple[float, ...]
    steer_rad: tuple[float | None, ...]
    steer_rate_rad_s: tuple[float | None, ...]


@dataclass(frozen=True, slots=True)
class FkResult:
    """Forward kinematics of measured wheel speeds.

    :param twist: the least-squares body twist.
    :param wheel_residual_m_s: per wheel, measured minus predicted rim speed, m/s (0 for
        wheels without a measurement).
    :param residual_m_s: RMS of every equation's residual (rolling and sliding), m/s: zero for
        consistent measurements, grows with slip on redundant drives.
    """

    twist: Twist
    wheel_residual_m_s: tuple[float, ...]
    residual_m_s: float


@dataclass(frozen=True, slots=True)
class Mobility:
    """Degrees of freedom in Siegwart's sense, at the neutral steering angles.

    :param mobility: ``3 - rank C1`` (fixed and steerable sliding rows).
    :param steerability: rank of the steerable wheels' sliding rows, at most the number of
        independent steering actuators.
    :param maneuverability: their sum.
    """

    mobility: int
    steerability: int
    maneuverability: int


@dataclass(frozen=True, slots=True)
class _Violation:
    wheel: str
    constraint: str
    residual_m_s: float
    detail: str


class RobotModel:
    """A robot described by its wheels.

    :param wheels: the wheels; names must be unique.
    :param slip_tolerance_m_s: largest sliding speed (m/s) a twist may ask of a wheel.
    :raises KinematicsError: for a geometry the model cannot use.
    """

    def __init__(self, wheels: Sequence[Wheel], slip_tolerance_m_s: float = 1e-3) -> None:
        if not wheels:
            raise KinematicsError("A robot needs at least one wheel, but got none")
        names = [w.name for w in wheels]
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise KinematicsError(f"Wheel names must be unique, but {dup} appear twice")
        for w in wheels:
            validate_wheel(w)
        if not (slip_tolerance_m_s >= 0.0 and math.isfinite(slip_tolerance_m_s)):
            raise KinematicsError(
                f"Expected slip tolerance >= 0 m/s, but got {slip_tolerance_m_s!r}"
            )
        self.wheels: tuple[Wheel, ...] = tuple(wheels)
        self.slip_tolerance_m_s = slip_tolerance_m_s
        self.names: tuple[str, ...] = tuple(names)
        self.n = len(wheels)
        #: Characteristic length (m) that weighs yaw rate against speed in "nearest twist".
        self.rho = max((w.l for w in wheels), default=0.0) or 1.0
        # Per-wheel hot-path data: (index, kind, coefficients...).
        self._fixed_rows: tuple[tuple[int, float, float, float], ...] = tuple(
            (i, row[0] / w.radius, row[1] / w.radius, row[2] / w.radius)
            for i, w in enumerate(wheels)
            if not w.steered
            for row in (w.rolling_row(),)
        )
        self._slide_rows = tuple(
            (w.name, *w.sliding_row()) for w in wheels if w.type is WheelType.FIXED
        )
        self._steered = tuple(
            (i, w, w.x, w.y, w.heading()) for i, w in enumerate(wheels) if w.steered
        )
        groups: dict[str, list[int]] = {}
        for i, w in enumerate(wheels):
            if w.steered and w.steer_group is not None:
                groups.setdefault(w.steer_group, []).append(i)
        self._groups = {g: tuple(ix) for g, ix in groups.items() if len(ix) > 1}
        #: ``(index, wheel)`` of the wheels with a finite steering rate limit.
        self.rate_limited_wheels: tuple[tuple[int, Wheel], ...] = tuple(
            (i, w) for i, w in enumerate(wheels) if not math.isinf(w.max_steer_rate)
        )
        self.neutral_steer: tuple[float | None, ...] = tuple(
            0.0 if w.steered else None for w in wheels
        )
        self._fk_static = self._build_static_fk()
        #: Pure-Python least-squares plans of a model without steered wheels, by the pattern
        #: of unmeasured wheels (``None`` when that pattern leaves the twist undetermined).
        self._fk_plans: dict[tuple[bool, ...], FkPlan | None] = {}
        self.mobility = self._mobility()

    # ----------------------------------------------------------------- matrices

    def j1(self, steer: Sequence[float | None] | None = None) -> NDArray[np.float64]:
        """The stacked rolling matrix :math:`J_1` (N x 3), as in the seed (not divided by
        :math:`\\cos\\gamma`)."""
        s = self._steer_or_neutral(steer)
        return np.array(
            [
                [c * math.cos(w.gamma) for c in w.rolling_row(s[i] or 0.0)]
                for i, w in enumerate(self.wheels)
            ]
        )

    def j2(self) -> NDArray[np.float64]:
        """The diagonal :math:`J_2` (N x N): radii, times :math:`\\cos\\gamma` for Swedish
        wheels."""
        return np.diag([w.radius * math.cos(w.gamma) for w in self.wheels])

    def c1(self, steer: Sequence[float | None] | None = None) -> NDArray[np.float64]:
        """The sliding matrix :math:`C_1` of the fixed and steerable wheels, in model order."""
        s = self._steer_or_neutral(steer)
        rows = [
            w.sliding_row(s[i] or 0.0)
            for i, w in enumerate(self.wheels)
            if w.type in CONSTRAINING
        ]
        return np.array(rows, dtype=float).reshape(len(rows), 3)

    def _steer_or_neutral(self, steer: Sequence[float | None] | None) -> Sequence[float | None]:
        if steer is None:
            return self.neutral_steer
        if len(steer) != self.n:
            raise KinematicsError(f"Expected {self.n} steering angles, but got {len(steer)}")
        return steer

    def _mobility(self) -> Mobility:
        c1 = self.c1()
        rank_c1 = int(np.linalg.matrix_rank(c1)) if c1.size else 0
        steer_rows = [w.sliding_row() for w in self.wheels if w.type is WheelType.STEERABLE]
        rank_s = int(np.linalg.matrix_rank(np.array(steer_rows))) if steer_rows else 0
        grouped = {w.steer_group for w in self.wheels if w.steer_group is not None}
        independent = len(grouped) + sum(
            1 for w in self.wheels if w.type is WheelType.STEERABLE and w.steer_group is None
        )
        ds = min(rank_s, independent)
        dm = 3 - rank_c1
        return Mobility(dm, ds, dm + ds)

    # ----------------------------------------------------------------- inverse kinematics

    def ik(self, twist: Twist, steer: Sequence[float | None] | None = None) -> IkResult:
        """Wheel speeds and steering angles for ``twist``.

        :param twist: the body twist.
        :param steer: current steering angle of every wheel (``None`` or any value for wheels
            that are not steered); the neutral angles when omitted.
        :raises InfeasibleTwistError: if a wheel would have to slide, a steering limit would be
            passed, or coupled wheels would need different angles.
        :raises KinematicsError: if the twist is not finite.
        """
        result, violations = self._solve(twist, steer)
        if violations:
            worst = max(violations, key=lambda v: v.residual_m_s)
            raise InfeasibleTwistError(
                worst.wheel,
                worst.constraint,
                worst.residual_m_s,
                self.nearest_feasible(twist, steer),
                twist,
                worst.detail,
            )
        return result

    def feasible(self, twist: Twist, steer: Sequence[float | None] | None = None) -> bool:
        """Whether :meth:`ik` would accept ``twist``."""
        return not self._solve(twist, steer)[1]

    def max_wheel_change(self, dvx: float, dvy: float, dwz: float) -> float:
        """The largest wheel speed change (rad/s) that a twist change causes.

        Linear for wheels that are not steered; for steered wheels, the change of the contact
        point's velocity vector over the radius, which bounds their speed change and is linear
        in the twist too.  So ``limit / max_wheel_change(d)`` is the exact factor on ``d``.
        """
        worst = 0.0
        for _, a, b, c in self._fixed_rows:
            worst = max(worst, abs(a * dvx + b * dvy + c * dwz))
        for _, w, x, y, _ in self._steered:
            worst = max(worst, math.hypot(dvx - dwz * y, dvy + dwz * x) / w.radius)
        return worst

    def try_ik(
        self, twist: Twist, steer: Sequence[float | None] | None = None
    ) -> IkResult | None:
        """:meth:`ik`, but ``None`` instead of an error for an infeasible twist (no search for
        the nearest feasible twist; cheap enough for the per-cycle path)."""
        result, violations = self._solve(twist, steer)
        return None if violations else result

    def _solve(
        self, twist: Twist, steer: Sequence[float | None] | None
    ) -> tuple[IkResult, list[_Violation]]:
        if not twist.is_finite():
            raise KinematicsError(f"Expected a finite twist, but got {twist}")
        vx, vy, wz = twist.vx_m_s, twist.vy_m_s, twist.wz_rad_s
        prev = self.neutral_steer if steer is None else self._steer_or_neutral(steer)
        violations: list[_Violation] = []
        tol = self.slip_tolerance_m_s
        for name, a, b, c in self._slide_rows:
            s = a * vx + b * vy + c * wz
            if abs(s) > tol:
                violations.append(
                    _Violation(name, "sliding", abs(s), f"sideways contact speed {s:+.4g} m/s")
                )
        speeds = [0.0] * self.n
        angles: list[float | None] = [None] * self.n
        rates: list[float | None] = [None] * self.n
        for i, a, b, c in self._fixed_rows:
            speeds[i] = a * vx + b * vy + c * wz
        for i, w, x, y, h0 in self._steered:
            px, py = vx - wz * y, vy + wz * x
            sigma0 = prev[i] or 0.0
            if w.type is WheelType.CASTOR:
                row = w.rolling_row(sigma0)
                sl = w.sliding_row(sigma0)
                speeds[i] = (row[0] * vx + row[1] * vy + row[2] * wz) / w.radius
                angles[i] = sigma0
                rates[i] = -(sl[0] * vx + sl[1] * vy + sl[2] * wz) / w.d
                continue
            speed = math.hypot(px, py)
            if speed <= _STILL_M_S:
                angles[i] = sigma0
                continue
            base = math.atan2(py, px) - h0
            kmin = math.ceil((w.steer_min - _LIMIT_SLACK - base) / math.pi)
            kmax = math.floor((w.steer_max + _LIMIT_SLACK - base) / math.pi)
            if kmin > kmax:
                # Nearest reachable angle and the sliding speed it would cause.
                excess, limit = _limit_excess(w, base)
                hx, hy = math.cos(h0 + limit), math.sin(h0 + limit)
                slide = abs(py * hx - px * hy)
                if slide > tol:
                    violations.append(
                        _Violation(
                            w.name,
                            "steering limit",
                            slide,
                            f"needs {math.degrees(limit + excess):.1f} deg, limit "
                            f"{math.degrees(limit):.1f} deg",
                        )
                    )
                sigma = limit
                speeds[i] = (px * hx + py * hy) / w.radius
            else:
                k = min(max(round((sigma0 - base) / math.pi), kmin), kmax)
                sigma = base + k * math.pi
                speeds[i] = (speed if k % 2 == 0 else -speed) / w.radius
            angles[i] = sigma
        for group, members in self._groups.items():
            v = self._group_violation(group, members, vx, vy, wz)
            if v is not None and v.residual_m_s > tol:
                violations.append(v)
        return IkResult(twist, tuple(speeds), tuple(angles), tuple(rates)), violations

    def _group_violation(
        self, group: str, members: Sequence[int], vx: float, vy: float, wz: float
    ) -> _Violation | None:
        vel = [(vx - wz * self.wheels[i].y, vy + wz * self.wheels[i].x) for i in members]
        ref = max(range(len(members)), key=lambda j: math.hypot(*vel[j]))
        rx, ry = vel[ref]
        norm = math.hypot(rx, ry)
        if norm <= _STILL_M_S:
            return None
        ux, uy = rx / norm, ry / norm
        worst, who = 0.0, members[ref]
        for j, (px, py) in enumerate(vel):
            side = abs(px * uy - py * ux)
            if side > worst:
                worst, who = side, members[j]
        return _Violation(
            self.wheels[who].name,
            "steering coupling",
            worst,
            f"wheels of steer group {group!r} would need different angles",
        )

    # ----------------------------------------------------------------- nearest feasible twist

    def nearest_feasible(
        self, twist: Twist, steer: Sequence[float | None] | None = None
    ) -> Twist:
        """The feasible twist nearest to ``twist`` (least squares, yaw weighted by ``rho``).

        Candidates are projections onto the no-slip subspace of the fixed wheels, combined
        with steering at a limit, zero yaw (coupled steering) or a wheel at the instantaneous
        centre of rotation; the nearest candidate that :meth:`ik` accepts wins (zero always
        does).
        """
        xi = np.array([twist.vx_m_s, twist.vy_m_s, twist.wz_rad_s])
        base = [np.array(row[1:]) for row in self._slide_rows]
        extra: list[list[NDArray[np.float64]]] = [[]]
        if self._groups:
            extra.append([np.array([0.0, 0.0, 1.0])])
        single: list[list[NDArray[np.float64]]] = []
        for _, w, x, y, h0 in self._steered:
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
        weight = np.array([1.0, 1.0, self.rho])
        for rows in extra:
            cand = _project(xi, base + rows, weight)
            t = Twist(float(cand[0]), float(cand[1]), float(cand[2]))
            cost = float(np.sum(((cand - xi) * weight) ** 2))
            if cost < best_cost - 1e-15 and self.feasible(t, steer):
                best, best_cost = t, cost
        return best

    # ----------------------------------------------------------------- forward kinematics

    def _build_static_fk(self) -> NDArray[np.float64] | None:
        if self._steered:
            return None
        a, _ = self._fk_system([1.0] * self.n, self.neutral_steer)
        if int(np.linalg.matrix_rank(a)) < 3:
            return None
        pinv: NDArray[np.float64] = np.asarray(np.linalg.pinv(a), dtype=np.float64)
        return pinv

    def _fk_plan(self, wheel_rad_s: Sequence[float | None]) -> FkPlan | None:
        """The precomputed least squares for the neutral angles and these measured wheels
        (built on first use of each pattern); ``None`` if the model has steered wheels or
        the pattern leaves the twist undetermined."""
        if self._steered:
            return None
        key = tuple(v is None for v in wheel_rad_s)
        try:
            return self._fk_plans[key]
        except KeyError:
            pass
        speeds = [None if missing else 1.0 for missing in key]
        a, _ = self._fk_system(speeds, self.neutral_steer)
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
        self._fk_plans[key] = plan
        return plan

    def _fk_system(
        self, speeds: Sequence[float | None], steer: Sequence[float | None]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        rows: list[tuple[float, float, float]] = []
        rhs: list[float] = []
        for i, w in enumerate(self.wheels):
            sigma = steer[i] or 0.0
            if speeds[i] is not None:
                rows.append(w.rolling_row(sigma))
                rhs.append(w.radius * float(speeds[i] or 0.0))
        for i, w in enumerate(self.wheels):
            if w.type in CONSTRAINING:
                rows.append(w.sliding_row(steer[i] or 0.0))
                rhs.append(0.0)
        return np.array(rows, dtype=float).reshape(len(rows), 3), np.array(rhs)

    def fk(
        self,
        wheel_rad_s: Sequence[float | None],
        steer: Sequence[float | None] | None = None,
    ) -> FkResult:
        """Body twist from wheel speeds by least squares.

        :param wheel_rad_s: angular speed of every wheel (model order), ``None`` where unknown.
        :param steer: steering angle of every wheel (``None`` for wheels not steered).
        :raises KinematicsError: for wrong lengths, non-finite values, or too few measurements.
        """
        st, plan = self._fk_checked(wheel_rad_s, steer)
        if plan is not None:
            vx, vy, wz, rms, per_wheel = plan.solve(self.n, wheel_rad_s, per_wheel=True)
            return FkResult(Twist(vx, vy, wz), tuple(per_wheel or ()), rms)
        return self._fk_numpy(wheel_rad_s, st)

    def fk_twist(
        self,
        wheel_rad_s: Sequence[float | None],
        steer: Sequence[float | None] | None = None,
    ) -> tuple[float, float, float, float]:
        """:meth:`fk` as plain numbers ``(vx, vy, wz, residual_m_s)``, without the result
        objects and the per-wheel residuals (odometry's per-sample path).

        :raises KinematicsError: as :meth:`fk`.
        """
        st, plan = self._fk_checked(wheel_rad_s, steer)
        if plan is not None:
            vx, vy, wz, rms, _ = plan.solve(self.n, wheel_rad_s, per_wheel=False)
            return vx, vy, wz, rms
        r = self._fk_numpy(wheel_rad_s, st)
        return r.twist.vx_m_s, r.twist.vy_m_s, r.twist.wz_rad_s, r.residual_m_s

    def _fk_checked(
        self, wheel_rad_s: Sequence[float | None], steer: Sequence[float | None] | None
    ) -> tuple[Sequence[float | None], FkPlan | None]:
        """Validate fk's arguments; the steering angles and, at the neutral angles of a
        model without steered wheels, the precomputed plan."""
        if len(wheel_rad_s) != self.n:
            raise KinematicsError(f"Expected {self.n} wheel speeds, but got {len(wheel_rad_s)}")
        for v in wheel_rad_s:
            if v is not None and not math.isfinite(v):
                raise KinematicsError(
                    f"Expected finite wheel speeds, but got {list(wheel_rad_s)}"
                )
        st = self._steer_or_neutral(steer)
        # Neutral angles (None or 0 everywhere): the rows are the precomputed ones.
        return st, (None if any(st) else self._fk_plan(wheel_rad_s))

    def _fk_numpy(
        self, wheel_rad_s: Sequence[float | None], st: Sequence[float | None]
    ) -> FkResult:
        a, b = self._fk_system(wheel_rad_s, st)
        if self._fk_static is not None and all(v is not None for v in wheel_rad_s):
            xi = self._fk_static @ b
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

    def index(self, name: str) -> int:
        """Position of the wheel ``name``.

        :raises KinematicsError: naming the known wheels if there is none.
        """
        try:
            return self.names.index(name)
        except ValueError:
            raise KinematicsError(
                f"Unknown wheel {name!r}; expected one of: {', '.join(self.names)}"
            ) from None


def _limit_excess(w: Wheel, base: float) -> tuple[float, float]:
    """For an angle ``base`` (mod pi) out of ``w``'s limits: (signed excess, nearest limit)."""
    best: tuple[float, float] = (math.inf, 0.0)
    for lim in (w.steer_min, w.steer_max):
        diff = (base - lim + math.pi / 2) % math.pi - math.pi / 2
        if abs(diff) < abs(best[0]):
            best = (diff, lim)
    return best


def _project(
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


def validate_wheel(w: Wheel) -> None:
    """Check one wheel's parameters.

    :raises KinematicsError: naming the wheel, what was expected and what came.
    """
    what = f"wheel {w.name!r}"
    for key in ("alpha", "l", "beta", "radius", "gamma", "d"):
        value = getattr(w, key)
        if not math.isfinite(value):
            raise KinematicsError(f"{what}: expected a finite {key}, but got {value!r}")
    if w.radius <= 0.0:
        raise KinematicsError(f"{what}: expected radius > 0 m, but got {w.radius!r}")
    if w.l < 0.0:
        raise KinematicsError(f"{what}: expected l >= 0 m, but got {w.l!r}")
    if w.type is WheelType.SWEDISH and not abs(w.gamma) < math.pi / 2 - 1e-6:
        raise KinematicsError(
            f"{what}: expected |gamma| < pi/2 (rollers parallel to the axle cannot roll), "
            f"but got {w.gamma!r}"
        )
    if w.type is not WheelType.SWEDISH and w.gamma != 0.0:
        raise KinematicsError(f"{what}: gamma applies to Swedish wheels only, got {w.gamma!r}")
    if w.type is WheelType.CASTOR and w.d <= 0.0:
        raise KinematicsError(f"{what}: expected castor offset d > 0 m, but got {w.d!r}")
    if w.type is not WheelType.CASTOR and w.d != 0.0:
        raise KinematicsError(f"{what}: offset d applies to castor wheels only, got {w.d!r}")
    if w.steered and not w.steer_min <= 0.0 <= w.steer_max:
        raise KinematicsError(
            f"{what}: expected steer_min <= 0 <= steer_max, but got "
            f"[{w.steer_min!r}, {w.steer_max!r}]"
        )
    if not w.max_steer_rate > 0.0:
        raise KinematicsError(
            f"{what}: expected max_steer_rate > 0 rad/s, but got {w.max_steer_rate!r}"
        )
