"""The one motor factory of the tests: motor blocks as the configuration loader makes them.

Every test that needs a :class:`~gateway.core.types.MotorConfig` without a configuration file
builds it here, so a motor block means the same thing in every test: the protocol keys are
validated by the driver, as :func:`gateway.config.load_config` does, and a steering actuator
has the fields the loader gives it.

A protocol's test module may keep a helper of its own for the keys its motors share (a VESC's
pole pairs, a DBC file's message names); the helper builds on :func:`motor` or
:func:`steer_motor`.
"""

from __future__ import annotations

import math
from types import MappingProxyType
from typing import TYPE_CHECKING, Any

from gateway.core.types import MotorConfig, MotorRole
from gateway.drive.registry import get_driver_class

if TYPE_CHECKING:
    from collections.abc import Mapping, Sequence

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
    driver_class: type[MotorDriver[Any]] | None = None,
    options: Mapping[str, object] | None = None,
    **keys: object,
) -> MotorConfig:
    """A drive motor of ``driver`` at ``node_id`` turning ``wheel``.

    :param validate: check and complete the protocol keys with the driver's defaults (as the
        loader does); ``False`` keeps them as given, for tests of the validation itself (the
        driver's constructor checks them again, as it does after the loader).
    :param driver_class: the class that validates the keys, for a protocol that is not in the
        registry (a test's own); by default the registry's class of ``driver``.
    :param options: protocol keys of the motor block, as a mapping (e.g. a helper's shared keys).
    :param keys: protocol keys as keywords; a key given both ways takes its value from here.
    """
    return MotorConfig(
        wheel, driver, node_id, gear_ratio=gear_ratio, invert=invert, max_rpm=max_rpm,
        options=_options(driver_class or driver, wheel, {**(options or {}), **keys}, validate),
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
    wheel: str | None = None,
    validate: bool = True,
    options: Mapping[str, object] | None = None,
    **keys: object,
) -> MotorConfig:
    """A steering actuator of ``driver`` at ``node_id`` turning the wheels ``steers``.

    :param wheel: the block's name; by default ``"<first wheel> steering"``, as the loader
        names it.
    :param validate: as for :func:`motor`.
    :param options: as for :func:`motor`.
    :param keys: as for :func:`motor`.
    """
    wheel = wheel or f"{steers[0]} steering"
    return MotorConfig(
        wheel, driver, node_id, gear_ratio=gear_ratio, invert=invert, max_rpm=max_rpm,
        options=_options(driver, wheel, {**(options or {}), **keys}, validate),
        role=MotorRole.STEER,
        zero_rad=zero_rad, steers=tuple(steers), steer_range_rad=steer_range_rad,
        linkage=linkage,
    )


def driver_of(motors: Sequence[MotorConfig]) -> MotorDriver[Any]:
    """The driver of these motors (one protocol), from the registry."""
    return get_driver_class(motors[0].driver)(motors)


def _options(
    driver: str | type[MotorDriver[Any]], wheel: str, options: dict[str, object], validate: bool
) -> MappingProxyType[str, object]:
    if validate:
        cls = get_driver_class(driver) if isinstance(driver, str) else driver
        options = cls.validate_options(options, f"motor {wheel!r}")
    return MappingProxyType(dict(options))
