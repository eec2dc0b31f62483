r"""The robot as a stack of wheel constraints: inverse and forward kinematics, feasibility.

:class:`RobotModel` stacks the wheels of :mod:`gateway.core.kinematics.wheels` into the matrices of
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
  :class:`~gateway.core.errors.InfeasibleTwistError` with the nearest feasible twist.
* **Forward kinematics** (:meth:`RobotModel.fk`): wheel speeds (and steering angles) -> twist
  by least squares over every rolling and sliding equation, with the residual in m/s as a slip
  indicator for redundant drives.

The result types live in :mod:`gateway.core.kinematics.results` (re-exported here), the wheel check
in :mod:`gateway.core.kinematics.validation`, the constraint checks and the nearest-feasible search
in :mod:`gateway.core.kinematics.feasibility`, and the least-squares machinery of forward kinematics
in :mod:`gateway.core.kinematics.forward`.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from gateway.core.errors import InfeasibleTwistError, KinematicsError
from gateway.core.kinematics.feasibility import (
    LIMIT_SLACK,
    STILL_M_S,
    Violation,
    group_violation,
    limit_excess,
    nearest_feasible,
)
from gateway.core.kinematics.forward import FkSolver
from gateway.core.kinematics.results import FkResult, IkResult, Mobility
from gateway.core.kinematics.validation import validate_wheel
from gateway.core.kinematics.wheels import CONSTRAINING, Wheel, WheelType
from gateway.core.types import Twist

if TYPE_CHECKING:
    from collections.abc import Sequence

    from numpy.typing import NDArray

    from gateway.core.kinematics.lsq import FkPlan

# The result types and the wheel check live in their own modules; they are re-exported here.
__all__ = ["FkResult", "IkResult", "Mobility", "RobotModel", "validate_wheel"]


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
        self.fk_solver = FkSolver(self.wheels, self.neutral_steer)
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

    def change_scale(self, prev: Twist, d: tuple[float, float, float], accel_step: float,
                     decel_step: float) -> float:
        """The largest factor in [0, 1] on the twist change ``d`` from ``prev`` that changes no
        wheel's speed by more than its step (rad/s): ``decel_step`` for a wheel that slows
        down without reversing, the smaller step for one that reverses, ``accel_step`` else;
        with equal steps ``min(1, step / max_wheel_change(*d))``."""
        pvx, pvy, pwz = prev.vx_m_s, prev.vy_m_s, prev.wz_rad_s
        dvx, dvy, dwz = d
        both = min(accel_step, decel_step)
        scale = 1.0
        for _, a, b, c in self._fixed_rows:
            change = abs(a * dvx + b * dvy + c * dwz)
            if change == 0.0:
                continue
            before = a * pvx + b * pvy + c * pwz
            after = before + a * dvx + b * dvy + c * dwz
            if before * after < 0.0:
                step = both
            else:
                step = decel_step if abs(after) <= abs(before) else accel_step
            scale = min(scale, step / change)
        for _, w, x, y, _ in self._steered:
            change = math.hypot(dvx - dwz * y, dvy + dwz * x) / w.radius
            if change == 0.0:
                continue
            bx, by = pvx - pwz * y, pvy + pwz * x
            ax, ay = bx + dvx - dwz * y, by + dvy + dwz * x
            if bx * ax + by * ay < 0.0:
                step = both  # more than a quarter turn of the contact velocity: a reversal
            else:
                step = decel_step if math.hypot(ax, ay) <= math.hypot(bx, by) else accel_step
            scale = min(scale, step / change)
        return scale

    def try_ik(
        self, twist: Twist, steer: Sequence[float | None] | None = None
    ) -> IkResult | None:
        """:meth:`ik`, but ``None`` instead of an error for an infeasible twist (no search for
        the nearest feasible twist; cheap enough for the per-cycle path)."""
        result, violations = self._solve(twist, steer)
        return None if violations else result

    def _solve(
        self, twist: Twist, steer: Sequence[float | None] | None
    ) -> tuple[IkResult, list[Violation]]:
        if not twist.is_finite():
            raise KinematicsError(f"Expected a finite twist, but got {twist}")
        vx, vy, wz = twist.vx_m_s, twist.vy_m_s, twist.wz_rad_s
        prev = self.neutral_steer if steer is None else self._steer_or_neutral(steer)
        violations: list[Violation] = []
        tol = self.slip_tolerance_m_s
        for name, a, b, c in self._slide_rows:
            s = a * vx + b * vy + c * wz
            if abs(s) > tol:
                violations.append(
                    Violation(name, "sliding", abs(s), f"sideways contact speed {s:+.4g} m/s")
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
            if speed <= STILL_M_S:
                angles[i] = sigma0
                continue
            base = math.atan2(py, px) - h0
            kmin = math.ceil((w.steer_min - LIMIT_SLACK - base) / math.pi)
            kmax = math.floor((w.steer_max + LIMIT_SLACK - base) / math.pi)
            if kmin > kmax:
                # Nearest reachable angle and the sliding speed it would cause.
                excess, limit = limit_excess(w, base)
                hx, hy = math.cos(h0 + limit), math.sin(h0 + limit)
                slide = abs(py * hx - px * hy)
                if slide > tol:
                    violations.append(
                        Violation(
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
            v = group_violation(self.wheels, group, members, vx, vy, wz)
            if v is not None and v.residual_m_s > tol:
                violations.append(v)
        return IkResult(twist, tuple(speeds), tuple(angles), tuple(rates)), violations

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
        return nearest_feasible(
            twist,
            self._slide_rows,
            self._steered,
            bool(self._groups),
            self.rho,
            lambda t: self.feasible(t, steer),
        )

    # ----------------------------------------------------------------- forward kinematics

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
        return self.fk_solver.solve(wheel_rad_s, st)

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
        r = self.fk_solver.solve(wheel_rad_s, st)
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
        return st, (None if any(st) else self.fk_solver.plan(wheel_rad_s))

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

