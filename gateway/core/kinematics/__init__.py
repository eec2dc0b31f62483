"""The general wheel-constraint model, its presets, limits and odometry (pure numpy)."""

from __future__ import annotations

from gateway.core.kinematics.limits import LimitReport, Limits, apply_limits
from gateway.core.kinematics.model import FkResult, IkResult, Mobility, RobotModel
from gateway.core.kinematics.odometry import Odometry, OdometryState, Pose, compose, se2_exp
from gateway.core.kinematics.presets import PRESETS, Preset
from gateway.core.kinematics.wheels import Wheel, WheelType, forward_beta, wrap_angle

__all__ = [
    "PRESETS",
    "FkResult",
    "IkResult",
    "LimitReport",
    "Limits",
    "Mobility",
    "Odometry",
    "OdometryState",
    "Pose",
    "Preset",
    "RobotModel",
    "Wheel",
    "WheelType",
    "apply_limits",
    "compose",
    "forward_beta",
    "se2_exp",
    "wrap_angle",
]
