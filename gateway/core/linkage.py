r"""Ackermann steering linkages: one actuator turns two wheels of an axle to different angles.

A car-like robot usually steers its front wheels with one motor through a linkage that keeps
both wheels tangent to circles about one centre on the line of the other axle.  The
actuator's angle :math:`\delta` is then that of a virtual wheel in the middle of the steered
axle, at :math:`(L, 0)` in the body frame (the reference point is on the other axle, as in the
``ackermann`` and ``tricycle`` presets).  The turning centre is at :math:`(0, R)` with
:math:`\tan\delta = L / R`; a wheel at :math:`(L, y)` then stands at :math:`\tan\sigma = L /
(R - y)`:

.. math::

    \sigma = \operatorname{atan2}(L \sin\delta,\; L\cos\delta - y\sin\delta), \qquad
    \delta = \operatorname{atan2}(L \sin\sigma,\; L\cos\sigma + y\sin\sigma)

Both are smooth through straight ahead (:math:`R \to \infty`) and exact for any wheel of the
axle, so the virtual angle taken from either steered wheel of an inverse-kinematics solve is
the same.  Pure functions, no state.
"""

from __future__ import annotations

import math

__all__ = ["virtual_angle", "wheel_angle"]


def wheel_angle(delta: float, axle_x: float, wheel_y: float) -> float:
    """The steering angle of the wheel at ``(axle_x, wheel_y)`` for the virtual angle ``delta``.

    >>> round(wheel_angle(0.3, 0.65, 0.25), 6)  # the inner (left) wheel turns further
    0.337663
    >>> round(wheel_angle(0.3, 0.65, -0.25), 6)
    0.26971
    """
    s = math.sin(delta)
    return math.atan2(axle_x * s, axle_x * math.cos(delta) - wheel_y * s)


def virtual_angle(sigma: float, axle_x: float, wheel_y: float) -> float:
    """The virtual (actuator) angle for the wheel at ``(axle_x, wheel_y)`` at ``sigma``.

    >>> round(virtual_angle(wheel_angle(0.3, 0.65, 0.25), 0.65, 0.25), 12)
    0.3
    """
    s = math.sin(sigma)
    return math.atan2(axle_x * s, axle_x * math.cos(sigma) + wheel_y * s)
