"""The one motor factory of the tests: motor blocks as the configuration loader makes them.

Every test that needs a :class:`~gateway.core.types.MotorConfig` without a configuration file
builds it here, so a motor block means the same thing in every test: the protocol keys are
validated by the driver, as :func:`gateway.config.load_config` does, and a steering actuator
has the fields the loader gives it.
"""

from __future__ import annotations

import math
from types import MappingProxyType
from typing import TYPE_CHECKING, Any

from gateway.core.types import MotorConfig, MotorRole
from gateway.drive.registry import get_driver_class

if TYPE_CHECKING:
    from collections.abc import Sequence

    from gateway.drive.driver import MotorDriver


def motor(
    driver: str,
    node_id: int,
    wheel: str = "left",
    *,
    gear_ratio: float = 1.0,
    invert: bool = False,
    max_rpm: float = 3000.0,
    validate: bool = True,
    **options: object,
) -> MotorConfig:
    """A drive motor of ``driver`` at ``node_id`` turning ``wheel``.

    :param validate: check and complete the protocol keys with the driver's defaults (as the
        loader does); ``False`` keeps them as given, for tests of the validation itself.
    :param options: the motor block's protocol keys.
    """
    return MotorConfig(
        wheel, driver, node_id, gear_ratio=gear_ratio, invert=invert, max_rpm=max_rpm,
        options=_options(driver, wheel, options, validate),
    )


def steer_motor(
    driver: str,
    node_id: int,
    steers: Sequence[str] = ("front_left",),
    *,
    zero_rad: float = 0.0,
    gear_ratio: float = 1.0,
    invert: bool = False,
    max_rpm: float = 3000.0,
    steer_range_rad: tuple[float, float] = (-math.pi, math.pi),
    linkage: str = "direct",
    **options: object,
) -> MotorConfig:
    """A steering actuator of ``driver`` at ``node_id`` turning the wheels ``steers`` (named
    ``"<first wheel> steering"``, as the loader names it)."""
    wheel = f"{steers[0]} steering"
    return MotorConfig(
        wheel, driver, node_id, gear_ratio=gear_ratio, invert=invert, max_rpm=max_rpm,
        options=_options(driver, wheel, options, True), role=MotorRole.STEER,
        zero_rad=zero_rad, steers=tuple(steers), steer_range_rad=steer_range_rad,
        linkage=linkage,
    )


def driver_of(motors: Sequence[MotorConfig]) -> MotorDriver[Any]:
    """The driver of these motors (one protocol), from the registry."""
    return get_driver_class(motors[0].driver)(motors)


def _options(
    driver: str, wheel: str, options: dict[str, object], validate: bool
) -> MappingProxyType[str, object]:
    if validate:
        options = get_driver_class(driver).validate_options(options, f"motor {wheel!r}")
    return MappingProxyType(dict(options))
