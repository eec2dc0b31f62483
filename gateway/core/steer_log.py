"""Steering angles for a replayed log: where they come from and how.

When every steered wheel has a steering actuator (``steering:`` blocks), the log holds their
feedback and the replay takes the measured angles (:attr:`SteeringSource.ACTUATORS`), as the
gateway does.  Otherwise the wheels are steered outside the gateway and a candump log has wheel
speeds and positions but no steering angles.  :class:`~gateway.apps.replay.replay.Replay` then
replays a
robot with steered wheels with the first of these that applies:

* :attr:`SteeringSource.FIXED_WHEELS`: the wheels that are not steered determine the twist on
  their own (Ackermann with driven rear wheels, the differential drive with a castor): the
  steered wheels are left out of the odometry, which is then exact again; their angles are
  reconstructed from that twist by inverse kinematics, for the plot.
* :attr:`SteeringSource.GATEWAY_TWIST`: the log holds the gateway's own ``WG_Odom_Velocity``
  frames (a ``--record`` log does): each steered wheel is turned parallel to its contact
  point's velocity under the last twist the gateway reported, the half turn chosen by the sign
  of the wheel's measured speed (:func:`reconstruct_steer`).  It lags by up to one odometry
  period (1/``odom_rate_hz``), carries that frame's resolution (1 mm/s) and is only as right
  as the gateway's own estimate; while wheels are being turned it can be off by their turn.
* :attr:`SteeringSource.NEUTRAL`: neither: steered wheels are taken at their neutral angle,
  which is wrong whenever they were turned.  The replay's summary says so
  (:attr:`gateway.apps.replay.replay.ReplaySummary.steering`).

Both functions are pure: :func:`fixed_subset` decides whether the first source applies to a
configuration; :func:`reconstruct_steer` turns a twist (that of the wheels that are not
steered, or the gateway's) into angles.
"""

from __future__ import annotations

import enum
import math
from typing import TYPE_CHECKING

from gateway.core.errors import KinematicsError
from gateway.core.kinematics import RobotModel, WheelType, wrap_angle

if TYPE_CHECKING:
    from collections.abc import Sequence

    from gateway.core.settings import GatewayConfig
    from gateway.core.types import Twist

#: Contact-point speed (m/s) below which a steered wheel keeps its angle.
_STILL_M_S = 1e-6
#: Rim speed (m/s) above which a wheel's measured direction decides its half turn.
_STILL_M_S_MEASURED = 1e-3
#: Slack on steering limits, rad.
_SLACK = 1e-9


class SteeringSource(enum.Enum):
    """Where a replay takes the steering angles from (see the module docstring)."""

    NONE = "none (no steered wheels)"
    ACTUATORS = "measured by the steering actuators"
    FIXED_WHEELS = "left out: the wheels that are not steered fix the twist"
    GATEWAY_TWIST = "inverse kinematics of the gateway's WG_Odom_Velocity frames"
    NEUTRAL = "neutral angles (the log has no steering information)"


def fixed_subset(config: GatewayConfig) -> tuple[tuple[int, ...], RobotModel] | None:
    """The wheels that are not steered, as a model of their own, if the model has steered
    wheels and the others (with their motors' feedback) determine the twist on their own.

    :return: their indices (model order) and their model, or ``None``.
    """
    model = config.model
    idx = tuple(i for i, w in enumerate(model.wheels) if not w.steered)
    if len(idx) == model.n:
        return None
    probe = [1.0 if config.motors[i] is not None else None for i in idx]
    if all(p is None for p in probe):
        return None
    try:
        sub = RobotModel([model.wheels[i] for i in idx], model.slip_tolerance_m_s)
        sub.fk(probe)
    except KinematicsError:
        return None
    return idx, sub


def reconstruct_steer(
    model: RobotModel,
    twist: Twist,
    previous: Sequence[float | None],
    wheel_rad_s: Sequence[float | None],
) -> tuple[float | None, ...]:
    """Steering angles of the steerable wheels that realise ``twist``.

    A steerable wheel's plane must be parallel to its contact point's velocity, which fixes
    its angle up to a half turn; the half turn decides the sign of the wheel's rolling speed.
    Of the angles within the wheel's limits, the one whose rolling direction agrees with the
    sign of the wheel's measured speed is taken (when it turns by more than 1 mm/s at the rim),
    then the one nearest ``previous``.  A wheel whose contact point stands still, or that no
    angle within its limits fits, keeps its previous angle; castor wheels keep theirs too.

    :param model: the robot.
    :param twist: the body twist.
    :param previous: the current angles (model order, ``None`` for wheels not steered).
    :param wheel_rad_s: the wheels' measured speeds (model order), ``None`` where unknown.
    :return: the angles, model order (``None`` for wheels not steered).
    """
    vx, vy, wz = twist.vx_m_s, twist.vy_m_s, twist.wz_rad_s
    out = list(previous)
    for i, w in enumerate(model.wheels):
        if w.type is not WheelType.STEERABLE:
            continue
        px, py = vx - wz * w.y, vy + wz * w.x
        if math.hypot(px, py) <= _STILL_M_S:
            continue
        base = math.atan2(py, px) - w.heading()
        kmin = math.ceil((w.steer_min - _SLACK - base) / math.pi)
        kmax = math.floor((w.steer_max + _SLACK - base) / math.pi)
        if kmin > kmax:
            continue
        measured = wheel_rad_s[i]
        sign = 0
        if measured is not None and abs(measured) * w.radius > _STILL_M_S_MEASURED:
            sign = 1 if measured > 0 else -1
        prev = previous[i] or 0.0
        best: tuple[bool, float, float] | None = None
        for k in range(kmin, kmax + 1):
            sigma = base + k * math.pi
            mismatch = sign != 0 and (1 if k % 2 == 0 else -1) != sign
            key = (mismatch, abs(wrap_angle(sigma - prev)), sigma)
            if best is None or key < best:
                best = key
        if best is not None:
            out[i] = best[2]
    return tuple(out)
