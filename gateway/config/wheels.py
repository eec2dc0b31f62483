"""The wheels of a configuration: a preset drive's from its ``geometry:``, or ``drive:
generic``'s ``wheels:`` list (read by :func:`gateway.config.load.parse_config`)."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from gateway.config.keys import MAX_LENGTH_M, MIN_LENGTH_M, WHEEL_KEYS
from gateway.core.errors import ConfigError, KinematicsError
from gateway.core.kinematics import PRESETS, Wheel, WheelType
from gateway.core.kinematics.layout import (
    NOTICED_LITTLE_M_S,
    NOTICED_NONE_M_S,
    closest_pair,
    weakest_motion,
)
from gateway.core.kinematics.model import validate_wheel
from gateway.core.numfmt import short
from gateway.core.options import OptionSpec, validate_block

if TYPE_CHECKING:
    from collections.abc import Sequence

    from gateway.core.kinematics import RobotModel
    from gateway.core.types import Twist

#: The most wheels a robot may have (a bound on what a config can make the loader build).
MAX_WHEELS = 64


#: The geometry keys that are lengths a robot cannot have as 0 (or less): from
#: :data:`~gateway.config.keys.MIN_LENGTH_M` to :data:`~gateway.config.keys.MAX_LENGTH_M`.
LENGTHS = frozenset(("wheel_radius", "track", "wheelbase", "wheel_distance"))
_ANGLES = frozenset(("first_wheel_angle",))
#: Lengths that may be 0 (bounded above only).
_EXTRA_LENGTHS = frozenset(("effective_track",))
#: Steering limits: at most half a turn either way.
_STEER_ANGLES = frozenset(("max_steer",))


def _geometry_specs(drive: str) -> dict[str, OptionSpec]:
    """The ``geometry:`` keys of a preset drive, with their specs."""
    preset = PRESETS[drive]
    specs = {
        key: OptionSpec(
            str if key in preset.choices else type(default) if default is not None else float,
            default,
            choices=tuple(preset.choices.get(key, ())),
            minimum=(MIN_LENGTH_M if key in LENGTHS
                     else None if key in preset.choices or key in _ANGLES else 0.0),
            maximum=(MAX_LENGTH_M if key in LENGTHS or key in _EXTRA_LENGTHS
                     else math.pi if key in _STEER_ANGLES else None),
            unit=" m" if key in LENGTHS or key in _EXTRA_LENGTHS else "",
        )
        for key, default in preset.params.items()
    }
    if "wheel_count" in specs:
        specs["wheel_count"] = OptionSpec(int, specs["wheel_count"].default,
                                          minimum=3 if drive == "omni" else 2,
                                          maximum=MAX_WHEELS)
    return specs


def preset_wheels(
    drive: str, raw: object, source: str, separation: float = 1.0
) -> tuple[dict[str, object], list[Wheel]]:
    """The preset's geometry as written, and its wheels built with the track times
    ``separation`` (kinematics.wheel_separation_multiplier)."""
    preset = PRESETS[drive]
    specs = _geometry_specs(drive)
    given = {} if raw is None else raw
    theirs: dict[object, ConfigError] = {}  # another drive's keys: said as such, first
    if isinstance(given, dict):
        theirs = {key: err for key in given if key not in specs
                  if (err := _other_drives_key(f"{source}: geometry.{key}", key, drive, specs))}
        given = {k: x for k, x in given.items() if k not in theirs}
    said = [str(err) for err in theirs.values()]
    try:
        params = validate_block(given, specs, f"{source}: geometry", f"{drive} geometry keys")
    except ConfigError as err:
        raise ConfigError.of([*said, *err.problems]) from err
    if said:
        raise ConfigError.of(said)
    if separation == 1.0:
        return params, preset.build(params)  # type: ignore[arg-type]
    if "track" not in params:
        raise ConfigError(
            f"{source}: kinematics.wheel_separation_multiplier: expected a drive with a track "
            f"({', '.join(sorted(k for k, p in PRESETS.items() if 'track' in p.params))}); "
            f"{a_drive(drive)} has none: correct its geometry instead")
    scaled = {k: v * separation if k in ("track", "effective_track") else v  # type: ignore[operator]
              for k, v in params.items()}
    return params, preset.build(scaled)  # type: ignore[arg-type]


def _other_drives_key(
    where: str, key: object, drive: str, specs: dict[str, OptionSpec]
) -> ConfigError | None:
    """The error for a ``geometry:`` key that is (nearly) another preset drive's key and not
    this one's (``wheelbase`` on a differential drive); ``None`` for any other unknown key."""
    theirs = sorted({k for p in PRESETS.values() for k in p.params} - set(specs))
    import difflib  # noqa: PLC0415 - only where a suggestion is made (start-up)

    close = difflib.get_close_matches(str(key), [*theirs, *specs], n=1, cutoff=0.7)
    if not close or close[0] not in theirs:
        return None
    users = sorted(name for name, p in PRESETS.items() if close[0] in p.params)
    said = "" if close[0] == key else f" ({key!r}: did you mean {close[0]!r}?)"
    return ConfigError(
        f"{where}: {a_drive(drive)} has no {close[0]!r}{said}; it is a key of "
        f"{', '.join(users)} drives (known {drive} geometry keys: {', '.join(sorted(specs))})")


def stand_in_wheels(drive: str, raw: object) -> list[Wheel] | None:
    """The wheels of a preset drive whose ``geometry:`` has problems, for checking the blocks
    that name its wheels (motors, steering, radius multipliers) in the same run: every key
    written with a valid value is taken, a missing or bad one is its default or 1.0 m.  The
    wheels' names, roles and count are right whenever the keys that decide them
    (``wheel_count``, ``drive``) are; their positions are not measurements.  ``None`` when
    even that cannot be built.
    """
    given = raw if isinstance(raw, dict) else {}
    params: dict[str, object] = {}
    for key, spec in _geometry_specs(drive).items():
        try:
            value = spec.validate(given[key], key)
        except (KeyError, ConfigError):
            value = None
        params[key] = value if value not in (None, 0.0) else (
            1.0 if spec.default is None else spec.default)
    try:
        return PRESETS[drive].build(params)  # type: ignore[arg-type]
    except (KinematicsError, ValueError, TypeError):
        return None


def a_drive(drive: str) -> str:
    """``"a mecanum drive"``, ``"an omni drive"``: for messages."""
    return f"{'an' if drive[:1] in 'aeiou' else 'a'} {drive} drive"


def generic_wheels(
    raw: object, source: str
) -> tuple[list[Wheel], list[dict[str, object] | None]]:
    """The ``wheels:`` list of ``drive: generic``: each wheel and its ``motor:`` block (or
    ``None`` for a passive wheel)."""
    if not isinstance(raw, list) or not raw or len(raw) > MAX_WHEELS:
        shown = f"a list of {len(raw)}" if isinstance(raw, list) and raw else repr(raw)[:80]
        raise ConfigError(
            f"{source}: wheels: expected a list of 1 to {MAX_WHEELS} wheels, got {shown}"
        )
    wheels: list[Wheel] = []
    motors: list[dict[str, object] | None] = []
    for i, item in enumerate(raw):
        v = validate_block(item, WHEEL_KEYS, f"{source}: wheels[{i}]", "wheel keys")
        motor = v.pop("motor")
        group = v.pop("steer_group")
        try:
            wheel = Wheel(
                name=str(v["name"]),
                type=WheelType(v["type"]),
                steer_group=str(group) or None,
                driven=bool(motor),
                **{k: float(x) for k, x in v.items() if k not in ("name", "type")},  # type: ignore[arg-type]
            )
            validate_wheel(wheel)
        except (KinematicsError, ValueError) as err:
            raise ConfigError(f"{source}: wheels[{i}]: {err}") from err
        wheels.append(wheel)
        motors.append(motor or None)  # type: ignore[arg-type]
    return wheels, motors


def wheel_layout(model: RobotModel, motors: Sequence[object | None], source: str) -> list[str]:
    """Whether the driven wheels tell every motion apart (:mod:`gateway.core.kinematics.layout`).

    :return: a warning when one motion is noticed too little to measure.
    :raises ConfigError: when one is not noticed at all: the gateway could neither drive
        nor measure it.
    """
    twist, noticed = weakest_motion(model.wheels, [m is not None for m in motors])
    if noticed >= NOTICED_LITTLE_M_S:
        return []
    pair = closest_pair(model.wheels)
    where = ("" if pair is None or pair[2] >= 0.01 * model.rho
             else f"; wheels {pair[0]!r} and {pair[1]!r} are mounted {pair[2] * 1e3:.2g} mm apart")
    check = ("check each wheel's position and angles (REP-103: x forward, y left, angles "
             f"counter-clockwise; `wheelgate check` lists them){where}")
    motion = f"{_motion(twist)} (the twist {twist}, its fastest wheel at 1 m/s)"
    if noticed < NOTICED_NONE_M_S:
        raise ConfigError(
            f"{source}: wheels: {motion} turns no driven wheel and no fixed or steerable wheel "
            f"resists it, so wheelgate could neither drive nor measure it; expected driven "
            f"wheels that tell every motion apart: {check}")
    return [f"{source}: wheels: {motion} turns the driven wheels, or pushes the fixed or "
            f"steerable ones sideways, by at most {noticed * 1e3:.2g} mm/s, so odometry would "
            f"read a wheel-speed error of 1 mm/s as up to {1 / noticed:,.0f} mm/s of motion "
            f"(a sound layout: 1 to 2 mm/s); {check}"]


def _motion(twist: Twist) -> str:
    """``turning about the point x 0 m, y 0.2 m`` or ``moving straight at 90 deg`` (from x,
    counter-clockwise): a motion as a robot builder pictures it."""
    vx, vy, wz = twist.vx_m_s, twist.vy_m_s, twist.wz_rad_s
    if abs(wz) * MAX_LENGTH_M > math.hypot(vx, vy):  # a centre within the largest robot
        return (f"turning about the point x {short(-vy / wz, 4)} m, y {short(vx / wz, 4)} m "
                f"of the body frame")
    return f"moving straight at {math.degrees(math.atan2(vy, vx)):.0f} deg"
