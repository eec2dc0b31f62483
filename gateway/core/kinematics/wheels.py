r"""Wheels of the general wheel-constraint model (Siegwart, Nourbakhsh and Scaramuzza).

A wheel is placed in the REP-103 body frame (x forward, y left, yaw counter-clockwise) by its
polar angle :math:`\alpha` and distance :math:`l` from the body origin, its plane angle
:math:`\beta` and radius :math:`r`.  Swedish wheels add the roller angle :math:`\gamma`, castor
wheels the offset :math:`d`.  With the body twist :math:`\xi = (v_x, v_y, \omega_z)`:

.. math::

    \text{rolling:}\quad
    (\sin(\alpha+\beta+\gamma),\; -\cos(\alpha+\beta+\gamma),\; -l\cos(\beta+\gamma))\,\xi
    = r\dot\varphi\cos\gamma

    \text{sliding:}\quad
    (\cos(\alpha+\beta),\; \sin(\alpha+\beta),\; d + l\sin\beta)\,\xi + d\dot\beta = 0

(:math:`\gamma = 0` and :math:`d = 0` where the type has none.)  The rolling direction of a
wheel is the unit vector :math:`(\sin(\alpha+\beta), -\cos(\alpha+\beta))`; a wheel that rolls
forward along +x has :math:`\alpha + \beta = \pi/2`, so the left wheel of a differential drive
is :math:`\alpha = \pi/2, \beta = 0` and the right one :math:`\alpha = -\pi/2, \beta = \pi`.

For steered wheels (``steerable`` and ``castor``) the configured :math:`\beta` is the neutral
plane angle and the steering angle :math:`\sigma` is measured from it: the wheel's plane is at
:math:`\beta + \sigma`.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass


class WheelType(enum.Enum):
    """The five wheel types of the general model."""

    FIXED = "fixed"
    STEERABLE = "steerable"
    CASTOR = "castor"
    SWEDISH = "swedish"
    SPHERICAL = "spherical"


#: Wheel types whose plane angle changes (and that report a steering angle).
STEERED = frozenset({WheelType.STEERABLE, WheelType.CASTOR})
#: Wheel types with a no-slip (sliding) constraint that limits the body twist.
CONSTRAINING = frozenset({WheelType.FIXED, WheelType.STEERABLE})


@dataclass(frozen=True, slots=True)
class Wheel:
    """One wheel of the general model.

    :param name: unique name, e.g. ``"front_left"``.
    :param type: the wheel type.
    :param alpha: polar angle of the wheel's mounting point, rad.
    :param l: distance of the mounting point from the body origin, m (>= 0).
    :param beta: plane angle (neutral angle for steered wheels), rad.
    :param radius: wheel radius, m (> 0).
    :param gamma: roller angle of a Swedish wheel, rad, with ``|gamma| < pi/2``.
    :param d: castor offset, m (> 0 for a castor wheel).
    :param steer_min: smallest steering angle, rad (steered wheels).
    :param steer_max: largest steering angle, rad (steered wheels).
    :param max_steer_rate: steering rate limit, rad/s (``inf`` for none).
    :param driven: whether a motor turns the wheel.
    :param steer_group: wheels with the same group name are steered together (synchro drive).
    """

    name: str
    type: WheelType
    alpha: float
    l: float  # noqa: E741 - the seed's symbol
    beta: float
    radius: float
    gamma: float = 0.0
    d: float = 0.0
    steer_min: float = -math.pi
    steer_max: float = math.pi
    max_steer_rate: float = math.inf
    driven: bool = True
    steer_group: str | None = None

    @property
    def steered(self) -> bool:
        """Whether the plane angle of this wheel changes."""
        return self.type in STEERED

    @property
    def x(self) -> float:
        """x of the mounting point in the body frame, m."""
        return self.l * math.cos(self.alpha)

    @property
    def y(self) -> float:
        """y of the mounting point in the body frame, m."""
        return self.l * math.sin(self.alpha)

    def rolling_row(self, sigma: float = 0.0) -> tuple[float, float, float]:
        """Coefficients of :math:`\\xi` in the rolling constraint, divided by :math:`\\cos\\gamma`.

        The wheel's angular speed is ``row . xi / radius``.

        :param sigma: steering angle of a steered wheel, rad.
        """
        b = self.beta + sigma
        g = self.gamma
        c = math.cos(g)
        return (
            math.sin(self.alpha + b + g) / c,
            -math.cos(self.alpha + b + g) / c,
            -self.l * math.cos(b + g) / c,
        )

    def sliding_row(self, sigma: float = 0.0) -> tuple[float, float, float]:
        """Coefficients of :math:`\\xi` in the sliding constraint (without the castor's
        :math:`d\\dot\\beta` term).

        :param sigma: steering angle of a steered wheel, rad.
        """
        b = self.beta + sigma
        return (math.cos(self.alpha + b), math.sin(self.alpha + b), self.d + self.l * math.sin(b))

    def heading(self, sigma: float = 0.0) -> float:
        """Direction of positive rolling in the body frame, rad (``alpha + beta - pi/2``)."""
        return self.alpha + self.beta + sigma - math.pi / 2


def wrap_angle(angle: float) -> float:
    """``angle`` wrapped into [-pi, pi).

    >>> round(wrap_angle(3 * math.pi / 2), 6)
    -1.570796
    """
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


def forward_beta(alpha: float) -> float:
    """The plane angle, in (-pi, pi], that makes a wheel at polar angle ``alpha`` roll forward
    along +x (``alpha + beta = pi/2``).

    >>> forward_beta(math.pi / 2), round(forward_beta(-math.pi / 2), 6)
    (0.0, 3.141593)
    """
    beta = wrap_angle(math.pi / 2 - alpha)
    return beta + 2.0 * math.pi if beta <= -math.pi else beta
