r"""Wheel odometry by exact SE(2) integration.

Between two encoder samples the wheel-angle increments :math:`\Delta\varphi` give, through the
same least-squares forward kinematics as wheel speeds, a body displacement
:math:`\delta = (\delta_x, \delta_y, \delta_\theta)`.  The pose is then updated on the group,
as in seed 004:

.. math::

    T' = T \exp(\hat\delta), \qquad
    \exp(\hat\delta)_{xy} =
    \begin{pmatrix} A & -B \\ B & A \end{pmatrix}
    \begin{pmatrix} \delta_x \\ \delta_y \end{pmatrix},\quad
    A = \frac{\sin\delta_\theta}{\delta_\theta},\;
    B = \frac{1 - \cos\delta_\theta}{\delta_\theta}

which is exact for motion at constant twist (an arc) and uses Taylor series near
:math:`\delta_\theta = 0`, so straight lines are exact too.  Euler integration is not used.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, cast

from gateway.core.errors import KinematicsError
from gateway.core.types import Twist

if TYPE_CHECKING:
    from collections.abc import Sequence

    from gateway.core.kinematics.model import RobotModel


@dataclass(frozen=True, slots=True)
class Pose:
    """A planar pose in the odometry frame.

    :param x_m: x, m.
    :param y_m: y, m.
    :param theta_rad: heading, rad, wrapped to [-pi, pi).
    """

    x_m: float = 0.0
    y_m: float = 0.0
    theta_rad: float = 0.0


def se2_exp(dx: float, dy: float, dtheta: float) -> Pose:
    """The group exponential of a body displacement (a relative pose).

    >>> p = se2_exp(math.pi / 2, 0.0, math.pi / 2)   # quarter circle of radius 1
    >>> round(p.x_m, 9), round(p.y_m, 9), round(p.theta_rad, 9)
    (1.0, 1.0, 1.570796327)
    """
    a, b = _exp_coefficients(dtheta)
    return Pose(a * dx - b * dy, b * dx + a * dy, dtheta)


_TWO_PI = 2 * math.pi


def _exp_coefficients(dtheta: float) -> tuple[float, float]:
    """``(sin(t)/t, (1 - cos(t))/t)``, by Taylor series near ``t = 0``."""
    t2 = dtheta * dtheta
    if abs(dtheta) < 1e-4:
        return 1.0 - t2 / 6.0 + t2 * t2 / 120.0, dtheta / 2.0 - dtheta * t2 / 24.0
    return math.sin(dtheta) / dtheta, (1.0 - math.cos(dtheta)) / dtheta


def compose(pose: Pose, delta: Pose) -> Pose:
    """``pose`` followed by the relative pose ``delta`` (heading wrapped)."""
    c, s = math.cos(pose.theta_rad), math.sin(pose.theta_rad)
    theta = (pose.theta_rad + delta.theta_rad + math.pi) % (2 * math.pi) - math.pi
    return Pose(
        pose.x_m + c * delta.x_m - s * delta.y_m,
        pose.y_m + s * delta.x_m + c * delta.y_m,
        theta,
    )


@dataclass(frozen=True, slots=True)
class OdometryState:
    """Odometry after one update.

    :param pose: the integrated pose.
    :param twist: body velocity over the last interval.
    :param slip_m_s: RMS residual of the forward kinematics over the last interval, m/s.
    :param distance_m: path length travelled so far, m.
    :param timestamp_s: time of the last sample, s.
    """

    pose: Pose
    twist: Twist
    slip_m_s: float
    distance_m: float
    timestamp_s: float


class Odometry:
    """Integrates wheel angles into a pose.

    Pure: it keeps the previous sample but reads no clock; callers pass sample times.

    The state is kept as plain numbers and :attr:`state` builds its object when read, so a
    loop that takes a sample per cycle and reads the state at its publishing rate builds one
    object per read, not three per sample.

    :param model: the robot.
    :param pose: the starting pose.
    """

    def __init__(self, model: RobotModel, pose: Pose | None = None) -> None:
        self.model = model
        self._last: list[float | None] | None = None
        self._last_steer: Sequence[float | None] | None = None
        #: The least squares with every wheel measured, of a model without steered wheels
        #: (``None`` otherwise): the per-sample path of :meth:`take`.
        self._plan = model.fk_solver.plan([0.0] * model.n)
        # The state as numbers (see the class docstring); _state is its object once built.
        self._x = self._y = self._theta = self._vx = self._vy = self._wz = 0.0
        self._slip = self._distance = self._stamp = 0.0
        self._state: OdometryState | None = None
        self.state = OdometryState(pose or Pose(), Twist(), 0.0, 0.0, 0.0)

    @property
    def state(self) -> OdometryState:
        """The odometry after the last sample (built on the first read after a change)."""
        st = self._state
        if st is None:
            st = self._state = OdometryState(
                Pose(self._x, self._y, self._theta), Twist(self._vx, self._vy, self._wz),
                self._slip, self._distance, self._stamp)
        return st

    @state.setter
    def state(self, value: OdometryState) -> None:
        pose, twist = value.pose, value.twist
        self._x, self._y, self._theta = pose.x_m, pose.y_m, pose.theta_rad
        self._vx, self._vy, self._wz = twist.vx_m_s, twist.vy_m_s, twist.wz_rad_s
        self._slip, self._distance, self._stamp = value.slip_m_s, value.distance_m, \
            value.timestamp_s
        self._state = value

    def reset(self, pose: Pose | None = None) -> None:
        """Set the pose (origin by default) and zero the distance; keeps the last sample."""
        self.state = OdometryState(pose or Pose(), Twist(), 0.0, 0.0, self._stamp)

    def update(
        self,
        positions_rad: Sequence[float | None],
        timestamp_s: float,
        steer_rad: Sequence[float | None] | None = None,
    ) -> OdometryState:
        """:meth:`take` one sample and return the new :attr:`state`.

        :raises KinematicsError: as :meth:`take`.
        """
        self.take(positions_rad, timestamp_s, steer_rad)
        return self.state

    def take(
        self,
        positions_rad: Sequence[float | None],
        timestamp_s: float,
        steer_rad: Sequence[float | None] | None = None,
    ) -> None:
        """Take one sample of every wheel's unwrapped angle.

        :param positions_rad: wheel angles (model order), ``None`` for wheels not measured.
        :param timestamp_s: sample time, s.
        :param steer_rad: steering angles at this sample (steered wheels).
        :raises KinematicsError: for wrong lengths or too few measured wheels.
        """
        n = self.model.n
        if len(positions_rad) != n:
            raise KinematicsError(
                f"Expected {n} wheel positions, but got {len(positions_rad)}"
            )
        steer = steer_rad if steer_rad is not None else self.model.neutral_steer
        last, self._last = self._last, list(positions_rad)
        last_steer, self._last_steer = self._last_steer, steer
        if last is None:
            self._vx = self._vy = self._wz = self._slip = 0.0
            self._stamp, self._state = timestamp_s, None
            return
        plan = self._plan
        if (plan is not None and None not in positions_rad and None not in last
                and len(steer) == n and not any(steer)):
            # Every wheel measured now and before, no steering: the plan's least squares of
            # the changes, as fk_twist would solve them, whose checks a finite result passes
            # (a change that is not finite goes the general way, which names it).
            dx, dy, dtheta, residual = plan.increment(
                cast("Sequence[float]", positions_rad), cast("Sequence[float]", last))
            if math.isfinite(dx + dy + dtheta):
                self._step(dx, dy, dtheta, residual, timestamp_s)
                return
        deltas = [
            None if p is None or q is None else p - q
            for p, q in zip(positions_rad, last, strict=True)
        ]
        mid = steer
        if last_steer is not None and steer != last_steer:
            # Equal angles need no midpoint (0.5 * (a + a) == a exactly).
            mid = [
                None if a is None or b is None else 0.5 * (a + b)
                for a, b in zip(steer, last_steer, strict=True)
            ]
        dx, dy, dtheta, residual = self.model.fk_twist(deltas, mid)
        self._step(dx, dy, dtheta, residual, timestamp_s)

    def _step(
        self, dx: float, dy: float, dtheta: float, residual: float, timestamp_s: float
    ) -> None:
        """Move the pose by the body displacement of one interval ending at ``timestamp_s``:
        ``compose(pose, se2_exp(dx, dy, dtheta))``, the same arithmetic on plain numbers."""
        a, b = _exp_coefficients(dtheta)
        ex, ey = a * dx - b * dy, b * dx + a * dy
        theta0 = self._theta
        c, s = math.cos(theta0), math.sin(theta0)
        self._x = self._x + c * ex - s * ey  # (not +=: the same rounding as compose)
        self._y = self._y + s * ex + c * ey
        self._theta = (theta0 + dtheta + math.pi) % _TWO_PI - math.pi
        dt = timestamp_s - self._stamp
        if dt > 0:
            inv = 1.0 / dt
            self._vx, self._vy, self._wz = dx * inv, dy * inv, dtheta * inv
            self._slip = residual / dt
        else:
            self._vx = self._vy = self._wz = self._slip = 0.0
        # The displacement is the twist times the interval, so the norm of its linear part
        # is the arc length, not the chord.
        self._distance += math.hypot(dx, dy)
        self._stamp, self._state = timestamp_s, None
