"""Parameter checks of a single wheel, shared by the robot model and the config loader."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from gateway.core.errors import KinematicsError
from gateway.core.kinematics.wheels import WheelType

if TYPE_CHECKING:
    from gateway.core.kinematics.wheels import Wheel

__all__ = ["validate_wheel"]


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
