"""Speed, acceleration and steering-rate limits that keep the path.

* **Speed**: twist caps (linear and angular) and every motor's ``max_rpm`` (through its gear
  ratio) are met by scaling the *whole* twist by one factor, so direction and curvature stay.
* **Acceleration**: the change from the previous command is scaled by one factor so that no
  wheel's speed changes faster than ``max_wheel_accel_rad_s2``; all wheels reach the new command
  together, and from rest the direction and curvature are kept.  Where the interpolated twist
  would be infeasible (steering cones), the robot decelerates along its previous path instead.
* **Steering rate**: a steered wheel turns at most ``max_steer_rate * dt`` per cycle, and while
  it lags behind its target it only drives the part of its target speed that lies along its
  actual heading (cosine of the error), so it does not push sideways.  It never turns past the
  angle of the twist asked for on its way to an interpolated twist's: where the acceleration
  limit interpolates across the end of the steering range (a synchro drive from driving
  backwards to driving right: the interpolated wheel direction starts on the far side and
  sweeps back), the wheel stops turning at the requested angle and waits there for the
  interpolation, instead of swinging past it and back (a reversal an actuator with momentum
  overshoots).

Nothing is silent: every call returns a :class:`LimitReport` with the factors applied.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

from gateway.core.errors import KinematicsError
from gateway.core.kinematics.model import IkResult
from gateway.core.types import Twist

if TYPE_CHECKING:

    from gateway.core.kinematics.model import RobotModel


@dataclass(frozen=True, slots=True)
class Limits:
    """Limits applied after inverse kinematics.

    :param max_wheel_rad_s: per wheel (model order), the largest wheel speed, rad/s.
    :param max_wheel_accel_rad_s2: the largest change of any wheel's speed, rad/s^2.
    :param max_linear_m_s: cap on ``hypot(vx, vy)``, m/s.
    :param max_angular_rad_s: cap on ``|wz|``, rad/s.
    :param max_wheel_decel_rad_s2: the largest change of a wheel's speed that slows it down,
        rad/s^2; ``None``: ``max_wheel_accel_rad_s2``.  (A wheel that reverses takes the
        smaller of the two.)
    """

    max_wheel_rad_s: tuple[float, ...]
    max_wheel_accel_rad_s2: float = math.inf
    max_linear_m_s: float = math.inf
    max_angular_rad_s: float = math.inf
    max_wheel_decel_rad_s2: float | None = None

    @property
    def decel_rad_s2(self) -> float:
        """The deceleration limit in force (rad/s^2)."""
        decel = self.max_wheel_decel_rad_s2
        return self.max_wheel_accel_rad_s2 if decel is None else decel


@dataclass(frozen=True, slots=True)
class LimitReport:
    """What the limits did to one command.

    :param speed_scale: factor on the twist from speed limits (1.0: untouched).
    :param accel_scale: factor on the change from the previous command (1.0: untouched).
    :param steer_limited: names of wheels whose steering was rate limited.
    :param requested: the twist asked for.
    """

    speed_scale: float
    accel_scale: float
    steer_limited: tuple[str, ...]
    requested: Twist

    @property
    def limited(self) -> bool:
        """Whether any limit changed the command."""
        return self.speed_scale < 1.0 or self.accel_scale < 1.0 or bool(self.steer_limited)


def speed_scale(model: RobotModel, result: IkResult, limits: Limits) -> float:
    """The largest factor in (0, 1] that keeps ``result`` within the speed limits."""
    t = result.twist
    scale = 1.0
    lin = math.hypot(t.vx_m_s, t.vy_m_s)
    if lin > limits.max_linear_m_s:
        scale = limits.max_linear_m_s / lin
    if abs(t.wz_rad_s) > limits.max_angular_rad_s:
        scale = min(scale, limits.max_angular_rad_s / abs(t.wz_rad_s))
    for speed, cap in zip(result.wheel_rad_s, limits.max_wheel_rad_s, strict=True):
        if abs(speed) > cap:
            scale = min(scale, cap / abs(speed))
    return scale


def binding_limit(model: RobotModel, result: IkResult, limits: Limits) -> tuple[float, str]:
    """:func:`speed_scale` and, when it is below 1, the limit that sets it, for people
    (``"max_linear_m_s 1.5 m/s"``, ``"the wheel front_left's max_rpm (31.4 rad/s)"``);
    ``""`` when nothing limits the twist."""
    t = result.twist
    best, why = 1.0, ""
    lin = math.hypot(t.vx_m_s, t.vy_m_s)
    if lin > limits.max_linear_m_s:
        best, why = limits.max_linear_m_s / lin, f"max_linear_m_s {limits.max_linear_m_s:g} m/s"
    if abs(t.wz_rad_s) > limits.max_angular_rad_s:
        factor = limits.max_angular_rad_s / abs(t.wz_rad_s)
        if factor < best:
            best, why = factor, f"max_angular_rad_s {limits.max_angular_rad_s:g} rad/s"
    for wheel, speed, cap in zip(model.wheels, result.wheel_rad_s, limits.max_wheel_rad_s,
                                 strict=True):
        if abs(speed) > cap and cap / abs(speed) < best:
            best, why = cap / abs(speed), f"the wheel {wheel.name}'s max_rpm ({cap:.4g} rad/s)"
    return best, why


def _scaled(result: IkResult, factor: float) -> IkResult:
    return IkResult(
        result.twist.scaled(factor),
        tuple(s * factor for s in result.wheel_rad_s),
        result.steer_rad,
        tuple(None if r is None else r * factor for r in result.steer_rate_rad_s),
    )


def apply_limits(
    model: RobotModel,
    result: IkResult,
    limits: Limits,
    prev: IkResult | None = None,
    dt_s: float = 0.0,
) -> tuple[IkResult, LimitReport]:
    """Limit one inverse-kinematics result.

    :param model: the robot.
    :param result: the unlimited result (from :meth:`RobotModel.ik`).
    :param limits: the limits.
    :param prev: the previous limited command; acceleration and steering-rate limits need it.
    :param dt_s: time since ``prev``, s.
    :return: the limited result and what was done.
    :raises KinematicsError: if ``limits`` does not match the model.
    """
    if len(limits.max_wheel_rad_s) != model.n:
        raise KinematicsError(
            f"Expected {model.n} wheel speed limits, but got {len(limits.max_wheel_rad_s)}"
        )
    requested = result.twist
    s_speed = speed_scale(model, result, limits)
    if s_speed < 1.0:
        result = _scaled(result, s_speed)
    goal = result.steer_rad  # where the steering ends for the twist asked for
    s_accel = 1.0
    steer_limited: list[str] = []
    if prev is not None and dt_s > 0.0:
        max_step = limits.max_wheel_accel_rad_s2 * dt_s
        brake_step = limits.decel_rad_s2 * dt_s
        p, c = prev.twist, result.twist
        d = (c.vx_m_s - p.vx_m_s, c.vy_m_s - p.vy_m_s, c.wz_rad_s - p.wz_rad_s)
        if brake_step == max_step:
            need = model.max_wheel_change(*d)
            factor = max_step / need if need > max_step else 1.0
        else:
            factor = model.change_scale(p, d, max_step, brake_step)
        if factor < 1.0:
            s_accel = factor
            t = Twist(p.vx_m_s + s_accel * d[0], p.vy_m_s + s_accel * d[1],
                      p.wz_rad_s + s_accel * d[2])
            interpolated = model.try_ik(t, prev.steer_rad)
            if interpolated is not None:
                result = interpolated
            else:
                # The straight change passes through twists the steering cannot follow:
                # slow down along the previous path instead.
                stop = model.max_wheel_change(p.vx_m_s, p.vy_m_s, p.wz_rad_s)
                result = model.ik(p.scaled(max(0.0, 1.0 - brake_step / stop)), prev.steer_rad)
                s_accel = 0.0
        result, steer_limited = _limit_steering(model, result, prev, dt_s, goal)
    report = LimitReport(s_speed, s_accel, tuple(steer_limited), requested)
    return result, report


def _limit_steering(
    model: RobotModel, result: IkResult, prev: IkResult, dt_s: float,
    goal: tuple[float | None, ...],
) -> tuple[IkResult, list[str]]:
    """Turn each rate-limited wheel from ``prev`` toward ``result``'s angle, but not past its
    ``goal`` angle (the requested twist's) where that lies on the way (see the module)."""
    names: list[str] = []
    limited = model.rate_limited_wheels
    if not limited:
        return result, names
    speeds = list(result.wheel_rad_s)
    angles = list(result.steer_rad)
    for i, w in limited:
        target, before, end = result.steer_rad[i], prev.steer_rad[i], goal[i]
        if target is None or before is None:
            continue
        aim = target
        if end is not None and end != target and min(before, target) <= end <= max(before, target):
            aim = end
        step = w.max_steer_rate * dt_s
        actual = aim if abs(aim - before) <= step else before + math.copysign(step, aim - before)
        if actual != target:
            speeds[i] *= max(0.0, math.cos(target - actual))
            angles[i] = actual
            names.append(w.name)
    if not names:
        return result, names
    return IkResult(result.twist, tuple(speeds), tuple(angles), result.steer_rate_rad_s), names
