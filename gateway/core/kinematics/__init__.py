"""The general wheel-constraint model, its presets and limits (pure numpy); the odometry that
integrates the wheels' feedback is :mod:`gateway.core.kinematics.odometry`."""

from __future__ import annotations

from gateway.core.kinematics.limits import LimitReport, Limits, apply_limits
from gateway.core.kinematics.model import FkResult, IkResult, Mobility, RobotModel
from gateway.core.kinematics.presets import PRESETS, Preset
from gateway.core.kinematics.wheels import Wheel, WheelType, forward_beta, wrap_angle

__all__ = [
    "PRESETS",
    "FkResult",
    "IkResult",
    "LimitReport",
    "Limits",
    "Mobility",
    "Preset",
    "RobotModel",
    "Wheel",
    "WheelType",
    "apply_limits",
    "forward_beta",
    "wrap_angle",
]
