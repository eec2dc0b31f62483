"""What :class:`~gateway.core.kinematics.model.RobotModel` returns: the results of inverse and
forward kinematics and the robot's degrees of freedom (frozen dataclasses)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from gateway.core.types import Twist

__all__ = ["FkResult", "IkResult", "Mobility"]


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
