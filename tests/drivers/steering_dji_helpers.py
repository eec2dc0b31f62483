"""Shared builders of the DJI steering tests (test_steering_dji_*): steering and drive motors and
feedback frames."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from drivers.dji import (
    M2006_GEAR_RATIO,
    M3508_GEAR_RATIO,
)
from drivers.dji.codec import COUNTS_PER_REV
from tests import factories

if TYPE_CHECKING:
    from gateway.core.types import MotorConfig

TWO_PI = 2.0 * math.pi
COUNT_RAD = TWO_PI / COUNTS_PER_REV
#: Every DJI motor block acknowledges that the ESC has no stop of its own.
ACK = {"no_controller_stop": "acknowledged"}


def steer(
    node_id: int = 5,
    esc: str = "c620",
    gear: float | None = None,
    zero_rad: float = 1.0,
    invert: bool = False,
    max_rpm: float = 3000.0,
    **options: object,
) -> MotorConfig:
    """A DJI steering actuator ``"fl steering"`` of the factory
    (:func:`tests.factories.steer_motor`), the gearbox of the ESC's motor unless ``gear``."""
    ratio = gear if gear is not None else (M3508_GEAR_RATIO if esc == "c620" else M2006_GEAR_RATIO)
    return factories.steer_motor(
        "dji", node_id, ("front_left",), wheel="fl steering", zero_rad=zero_rad,
        gear_ratio=ratio, invert=invert, max_rpm=max_rpm, options={"esc": esc, **ACK, **options},
    )


def drive(node_id: int = 1, **options: object) -> MotorConfig:
    """A DJI drive motor ``w<node>`` of the factory (:func:`tests.factories.motor`)."""
    return factories.motor("dji", node_id, f"w{node_id}", gear_ratio=M3508_GEAR_RATIO,
                           max_rpm=9000.0, options={"esc": "c620", **ACK, **options})
