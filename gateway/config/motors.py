"""The motor blocks of a configuration file and its steering actuators (``steering:``).

Each driven wheel has a motor block (``motors.<wheel>`` of a preset drive, ``wheels[i].motor``
of a generic one) and each steering actuator a block of its own, with ``motor_defaults:`` or
``steering_defaults:`` merged in first.  The keys every driver takes are checked against
:data:`gateway.config.keys.MOTOR_KEYS` and :data:`~gateway.config.keys.STEERING_KEYS`; the rest
are the driver's protocol keys, which the driver validates.  A steering block names a steered
wheel or a steer group, or, with ``linkage: ackermann``, lists the wheels of one axle.
:func:`gateway.config.load.parse_config` calls these in turn.
"""

from __future__ import annotations

import dataclasses
import math
from types import MappingProxyType
from typing import TYPE_CHECKING, Any

from gateway.config.gather import Problems
from gateway.config.keys import (
    GATEWAY_KEYS,
    LINKAGE_KEYS,
    MAX_MULTIPLIER,
    MIN_MULTIPLIER,
    MOTOR_KEYS,
    STEERING_KEYS,
)
from gateway.core.choice import choice
from gateway.core.errors import ConfigError, DriverNotFoundError
from gateway.core.kinematics import WheelType
from gateway.core.linkage import virtual_angle
from gateway.core.options import unknown_key, validate_block
from gateway.core.settings import Linkage
from gateway.core.types import MotorConfig, MotorRole
from gateway.drive.registry import get_driver_class, valid_drivers

if TYPE_CHECKING:
    from collections.abc import Mapping

    from gateway.core.kinematics import Wheel
    from gateway.core.options import OptionSpec
    from gateway.drive.driver import MotorDriver

__all__ = ["STEER_RATE_SHARE", "check_nodes", "limit_steer_rates", "motor_block", "motor_path",
           "preset_motors", "steering_blocks"]


def motor_path(drive: object, index: int, name: str) -> str:
    """Where a wheel's motor block is in the file, for messages."""
    return f"wheels[{index}].motor" if drive == "generic" else f"motors.{name}"


def preset_motors(raw: object, wheels: list[Wheel], source: str) -> list[dict[str, object] | None]:
    """The ``motors:`` block of a preset drive: per wheel, its motor block (``None``: passive).

    :raises ConfigError: for an unknown wheel, a driven wheel without a block, a passive wheel
        with one, or a block that is not a mapping.
    """
    names = [w.name for w in wheels]
    if raw is None:
        driven = ", ".join(w.name for w in wheels if w.driven)
        raise ConfigError(f"{source}: motors: required key is missing (a motor block for each "
                          f"driven wheel: {driven})")
    if not isinstance(raw, dict):
        raise ConfigError(f"{source}: motors: expected a mapping of wheel name to motor block, "
                          f"got {raw!r}")
    for key in raw:
        if key not in names:
            raise ConfigError(f"{source}: motors.{key}: unknown wheel (wheels of this drive: "
                              f"{', '.join(names)})")
    out: list[dict[str, object] | None] = []
    for w in wheels:
        block = raw.get(w.name)
        if w.driven and block is None:
            raise ConfigError(f"{source}: motors.{w.name}: driven wheel needs a motor block")
        if not w.driven and block is not None:
            raise ConfigError(f"{source}: motors.{w.name}: this wheel is passive in this drive")
        if block is not None and not isinstance(block, dict):
            raise ConfigError(f"{source}: motors.{w.name}: expected a mapping, got {block!r}")
        out.append(block)
    return out


def steering_blocks(raw: object, defaults: object, wheels: list[Wheel], source: str,
                    config_dir: str) -> tuple[MotorConfig, ...]:
    """The ``steering:`` blocks: one actuator per steered wheel or steer group."""
    if raw is None:
        if defaults not in (None, {}):
            raise ConfigError(f"{source}: steering_defaults: given without a steering: block")
        return ()
    if not isinstance(raw, dict):
        raise ConfigError(f"{source}: steering: expected a mapping of steered wheel or steer "
                          f"group to actuator block, got {raw!r}")
    if not isinstance(defaults, dict):
        raise ConfigError(f"{source}: steering_defaults: expected a mapping, got {defaults!r}")
    by_name = {w.name: w for w in wheels}
    groups: dict[str, list[str]] = {}
    for w in wheels:
        if w.steered and w.steer_group is not None:
            groups.setdefault(w.steer_group, []).append(w.name)
    choices = [w.name for w in wheels if w.type is WheelType.STEERABLE and w.steer_group is None]
    choices += sorted(groups)
    out: list[MotorConfig] = []
    owner: dict[str, str] = {}
    for key, block in raw.items():
        where = f"{source}: steering.{key}"
        if not isinstance(block, dict):
            raise ConfigError(f"{where}: expected a mapping, got {block!r}")
        link = validate_block({k: block[k] for k in LINKAGE_KEYS if k in block}, LINKAGE_KEYS,
                              where)
        keys = {k: x for k, x in block.items() if k not in LINKAGE_KEYS}
        linkage = choice(Linkage, link["linkage"], f"{where}.linkage")
        listed = link["wheels"]
        if listed:
            members = _linkage_wheels(listed, linkage, by_name, choices, where)
        else:
            if linkage is not Linkage.DIRECT:
                raise ConfigError(f"{where}.wheels: expected the wheels a {linkage} "
                                  f"linkage turns, got none")
            members = _actuated_wheels(str(key), by_name, groups, choices, where)
        for name in members:
            if name in owner:
                raise ConfigError(f"{where}: wheel {name!r} is already turned by "
                                  f"steering.{owner[name]}; expected one actuator per wheel")
            owner[name] = str(key)
        if linkage is Linkage.ACKERMANN:
            axle = by_name[members[0]].x
            lows = [virtual_angle(by_name[n].steer_min, axle, by_name[n].y) for n in members]
            highs = [virtual_angle(by_name[n].steer_max, axle, by_name[n].y) for n in members]
            travel = (max(lows), min(highs))  # where every wheel is within its limits
        else:
            travel = (min(by_name[n].steer_min for n in members),
                      max(by_name[n].steer_max for n in members))
        out.append(motor_block(keys, defaults, f"{key} steering", where, config_dir,
                               tuple(members), travel, linkage,
                               f"{source}: steering_defaults"))
    return tuple(out)


def _actuated_wheels(
    key: str, by_name: Mapping[str, Wheel], groups: Mapping[str, list[str]],
    choices: list[str], where: str,
) -> list[str]:
    """The wheels of a direct actuator named ``key``: a steered wheel, or a steer group."""
    wheel = by_name.get(key)
    if wheel is None and key not in groups:
        raise ConfigError(
            f"{where}: unknown steered wheel or steer group (this robot's: "
            f"{', '.join(choices) or 'none'})"
        )
    if wheel is not None and wheel.steer_group is not None:
        raise ConfigError(
            f"{where}: wheel {key!r} is steered together with its group "
            f"{wheel.steer_group!r}; give the group's actuator as steering.{wheel.steer_group}"
        )
    members = [key] if wheel is not None else groups[key]
    for name in members:
        _check_steerable(by_name[name], choices, where)
    return members


def _linkage_wheels(
    listed: object, linkage: Linkage, by_name: Mapping[str, Wheel], choices: list[str], where: str
) -> list[str]:
    """The wheels a linkage turns: steerable, of one axle off the reference point's line,
    each within a quarter turn of straight ahead."""
    if linkage is not Linkage.ACKERMANN:
        raise ConfigError(f"{where}.wheels: expected linkage: ackermann with a list of wheels "
                          f"(a direct actuator is named after its wheel or steer group)")
    if not (isinstance(listed, list) and len(listed) >= 2
            and all(isinstance(n, str) and n in by_name for n in listed)):
        raise ConfigError(f"{where}.wheels: expected a list of two or more of this robot's "
                          f"steered wheels ({', '.join(choices) or 'none'}), got {listed!r}")
    members = [str(n) for n in listed]
    axle = by_name[members[0]].x
    for name in members:
        w = by_name[name]
        _check_steerable(w, choices, where)
        if w.steer_group is not None:
            raise ConfigError(f"{where}.wheels: wheel {name!r} is steered with its group "
                              f"{w.steer_group!r}; a linkage turns wheels of its own")
    for name in members:
        w = by_name[name]
        if abs(w.x - axle) > 1e-9 or abs(axle) < 1e-9:
            raise ConfigError(
                f"{where}.wheels: expected wheels of one axle ahead of or behind the reference "
                f"point (same x, not 0), got {name!r} at x = {w.x:g} m against "
                f"{members[0]!r} at {axle:g} m"
            )
    for name in members:
        w = by_name[name]
        if max(-w.steer_min, w.steer_max) >= math.pi / 2:
            raise ConfigError(
                f"{where}.wheels: wheel {name!r} steers to {max(-w.steer_min, w.steer_max):g} "
                f"rad; an Ackermann linkage turns its wheels less than pi/2 either way"
            )
    return members


def _check_steerable(wheel: Wheel, choices: list[str], where: str) -> None:
    if wheel.type is WheelType.CASTOR:
        raise ConfigError(f"{where}: wheel {wheel.name!r} is a castor wheel; it swivels by "
                          f"itself and takes no steering actuator")
    if wheel.type is not WheelType.STEERABLE:
        raise ConfigError(f"{where}: wheel {wheel.name!r} is not steered (a {wheel.type.value} "
                          f"wheel); expected one of {', '.join(choices) or 'none'}")


#: The share of a steering actuator's top speed that the commanded steering rate may use, so
#: that its position loop has room to catch up.
STEER_RATE_SHARE = 0.8


def limit_steer_rates(wheels: list[Wheel], steering: tuple[MotorConfig, ...]) -> list[Wheel]:
    """The wheels, each steering rate limit at most :data:`STEER_RATE_SHARE` of the top speed
    (``max_rpm`` through ``gear_ratio``) of the actuator that turns the wheel."""
    limit: dict[str, float] = {}
    for a in steering:
        rate = STEER_RATE_SHARE * a.max_wheel_rad_s  # max_rpm through gear_ratio
        for name in a.steers:
            limit[name] = rate
    return [
        dataclasses.replace(w, max_steer_rate=min(w.max_steer_rate, limit[w.name]))
        if w.name in limit else w
        for w in wheels
    ]


def motor_block(
    raw: Mapping[str, object],
    defaults: Mapping[str, object],
    wheel: str,
    where: str,
    config_dir: str,
    steers: tuple[str, ...] = (),
    travel: tuple[float, float] = (-math.pi, math.pi),
    linkage: Linkage = Linkage.DIRECT,
    defaults_where: str = "",
) -> MotorConfig:
    """A motor block, or with ``steers`` a steering actuator's block.

    :param wheel: the wheel the motor turns (an actuator: the block's name + ``" steering"``).
    :param where: the file and key path of the block, for messages.
    :param config_dir: the directory relative paths of protocol keys start from.
    :param steers: the wheels a steering actuator turns (empty for a drive motor).
    :param travel: the actuator's steering range, rad.
    :param linkage: how the actuator's angle turns its wheels.
    :param defaults_where: the file and key path of ``defaults`` (``motor_defaults``): an
        unknown key or a bad value given there is named there (one line however many blocks
        inherit it).
    :raises ConfigError: naming the key of each problem (the general keys first; the
        protocol's keys when the general ones are right).
    """
    keys = STEERING_KEYS if steers else MOTOR_KEYS
    merged = {**defaults, **raw}
    inherited = {k: x for k, x in defaults.items() if k not in raw}
    # Keys of the defaults are named there (:func:`_name_where_written`): the general keys, and
    # the protocol's when the block takes its driver from them too (else they are its own).
    own = raw.get("driver", defaults.get("driver")) == defaults.get("driver")
    at = defaults_where or where
    common = {k: merged[k] for k in keys if k in merged}
    found = Problems()  # the general keys' problems and the protocol's, together
    v = found.check(lambda: validate_block(common, keys, where,
                                           "steering keys" if steers else "motor keys"))
    driver = merged.get("driver")
    cls = found.check(lambda: _driver_class(driver, steers, at if "driver" in inherited
                                            else where)) if isinstance(driver, str) else None
    if cls is None:
        _name_where_written(found, keys, inherited, where, at)
        found.raise_any()
        raise AssertionError("a motor block without a driver passed validate_block")
    protocol = {k: x for k, x in merged.items() if k not in keys}
    for key in protocol:
        if key not in cls.OPTIONS and key != "config_dir":
            given = ("steering_defaults" if steers else "motor_defaults") if key in inherited \
                else "its block"
            elsewhere = (f" ({key!r}, given in {given}, is a gateway: key)"
                         if key in GATEWAY_KEYS else "")
            named = at if key in inherited and own else where
            if key in inherited and named == where and not elsewhere:
                elsewhere = f" (given in {given}, which the {driver} driver does not take)"
            found.add(str(unknown_key(f"{named}.{key}", key, {
                "steering keys" if steers else "motor keys": keys,
                f"{driver} keys": [k for k in cls.OPTIONS if k != "config_dir"],
            })) + elsewhere)
    protocol = {k: x for k, x in protocol.items() if k in cls.OPTIONS or k == "config_dir"}
    if "config_dir" in cls.OPTIONS and "config_dir" not in protocol:
        # Relative paths in protocol keys (a DBC file) are relative to the config file.
        protocol["config_dir"] = config_dir
    options = found.check(lambda: cls.validate_options(protocol, where))
    node = merged.get("node_id")
    if options is not None and isinstance(node, int) and not isinstance(node, bool):
        # its range may depend on the protocol's keys (ODrive's 29-bit identifiers)
        found.check(lambda: cls.validate_node_id(node, f"{where}.node_id", options))
    _name_where_written(found, {**(cls.OPTIONS if own else {}), **keys}, inherited, where, at)
    found.raise_any()
    assert v is not None and options is not None
    return MotorConfig(
        wheel=wheel, driver=str(driver), node_id=int(v["node_id"]),  # type: ignore[call-overload]
        gear_ratio=float(v["gear_ratio"]), invert=bool(v["invert"]),  # type: ignore[arg-type]
        max_rpm=float(v["max_rpm"]), options=MappingProxyType(options),  # type: ignore[arg-type]
        role=MotorRole.STEER if steers else MotorRole.DRIVE,
        zero_rad=float(v.get("zero_rad", 0.0)),  # type: ignore[arg-type]
        steers=steers, steer_range_rad=travel, linkage=linkage)


def _name_where_written(found: Problems, specs: Mapping[str, OptionSpec],
                        inherited: Mapping[str, object], where: str, at: str) -> None:
    """Name a bad value the block at ``where`` inherits (``gear_ratio: FILL`` in
    ``motor_defaults:``) where it is written, at ``at``, as an unknown key is: once however many
    blocks inherit it.  Only its own spec's problem moves; one across keys stays the block's."""
    moved: dict[str, str] = {}
    for key in specs.keys() & inherited.keys():
        try:
            specs[key].validate(inherited[key], f"{where}.{key}")
        except ConfigError as err:
            moved.update((p, f"{at}.{key}{p[len(where) + len(key) + 1:]}") for p in err.problems)
    found.found = [moved.get(p, p) for p in found.found]


def _driver_class(driver: str, steers: tuple[str, ...], where: str) -> type[MotorDriver[Any]]:
    """The driver class named in a block; a steering actuator's must command steering.

    :raises ConfigError: for an unknown driver, or one that cannot steer in a steering block.
    """
    try:
        cls = get_driver_class(driver)
    except DriverNotFoundError as err:
        raise ConfigError(f"{where}.driver: {err}") from err
    if steers and not cls.STEERING:
        able = sorted(n for n in valid_drivers() if _steers(n))
        raise ConfigError(f"{where}.driver: the {driver} driver does not command steering "
                          f"actuators (drivers that do: {', '.join(able) or 'none'})")
    return cls


def _steers(name: str) -> bool:
    """Whether the driver ``name`` commands steering actuators (``False`` if it cannot load)."""
    try:
        return get_driver_class(name).STEERING
    except DriverNotFoundError:
        return False


def check_nodes(motors: tuple[MotorConfig | None, ...], source: str) -> None:
    """Every controller's node ID must be unique among those of its driver.

    :raises ConfigError: naming both motors and the shared ID.
    """
    seen: dict[tuple[str, int], str] = {}
    for m in motors:
        if m is None:
            continue
        key = (m.driver, m.node_id)
        if key in seen:
            raise ConfigError(
                f"{source}: the motors of {seen[key]!r} and {m.wheel!r} share "
                f"{m.driver} node_id {m.node_id}; expected unique node IDs"
            )
        seen[key] = m.wheel


def radius_multipliers(raw: object, wheels: list[Wheel], where: str) -> dict[str, float]:
    """``kinematics.wheel_radius_multipliers``: wheel name -> factor on its radius, each in
    [:data:`MIN_MULTIPLIER`, :data:`MAX_MULTIPLIER`] (a measured correction, as
    ros2_control's ``left_wheel_radius_multiplier``).

    :raises ConfigError: for an unknown wheel (with the nearest name) or a bad factor.
    """
    where = f"{where}.wheel_radius_multipliers"
    if not isinstance(raw, dict):
        raise ConfigError(f"{where}: expected a mapping of wheel name to factor, got {raw!r}")
    names = [w.name for w in wheels]
    out: dict[str, float] = {}
    problems = []
    for name, value in raw.items():
        if name not in names:
            problems.append(str(unknown_key(f"{where}.{name}", name, {"wheels": names})))
        elif (isinstance(value, bool) or not isinstance(value, int | float)
              or not MIN_MULTIPLIER <= value <= MAX_MULTIPLIER):
            problems.append(f"{where}.{name}: expected a factor from {MIN_MULTIPLIER} to "
                            f"{MAX_MULTIPLIER}, got {value!r}")
        else:
            out[name] = float(value)
    if problems:
        raise ConfigError.of(problems)
    return out
