"""The wheels of a configuration: a preset drive's from its ``geometry:``, or ``drive:
generic``'s ``wheels:`` list (read by :func:`gateway.config.load.parse_config`)."""

from __future__ import annotations

from gateway.config.keys import WHEEL_KEYS
from gateway.core.errors import ConfigError, KinematicsError
from gateway.core.kinematics import PRESETS, Wheel, WheelType
from gateway.core.kinematics.model import validate_wheel
from gateway.core.options import OptionSpec, validate_block

#: The most wheels a robot may have (a bound on what a config can make the loader build).
MAX_WHEELS = 64


def preset_wheels(
    drive: str, raw: object, source: str, separation: float = 1.0
) -> tuple[dict[str, object], list[Wheel]]:
    """The preset's geometry as written, and its wheels built with the track times
    ``separation`` (kinematics.wheel_separation_multiplier)."""
    preset = PRESETS[drive]
    specs = {
        key: OptionSpec(
            str if key in preset.choices else type(default) if default is not None else float,
            default,
            choices=tuple(preset.choices.get(key, ())),
            minimum=None if key in preset.choices or key == "first_wheel_angle" else 0.0,
        )
        for key, default in preset.params.items()
    }
    for key in ("wheel_count",):
        if key in specs:
            specs[key] = OptionSpec(int, specs[key].default, minimum=3 if drive == "omni" else 2,
                                    maximum=MAX_WHEELS)
    params = validate_block(
        raw if raw is not None else {}, specs, f"{source}: geometry", f"{drive} geometry keys"
    )
    for key, value in params.items():
        if key in ("wheel_radius", "track", "wheelbase", "wheel_distance") and value == 0.0:
            raise ConfigError(f"{source}: geometry.{key}: expected a length > 0 m, got 0")
    if separation == 1.0:
        return params, preset.build(params)  # type: ignore[arg-type]
    if "track" not in params:
        raise ConfigError(
            f"{source}: kinematics.wheel_separation_multiplier: expected a drive with a track "
            f"({', '.join(sorted(k for k, p in PRESETS.items() if 'track' in p.params))}); a "
            f"{drive} drive has none: correct its geometry instead")
    scaled = {k: v * separation if k in ("track", "effective_track") else v  # type: ignore[operator]
              for k, v in params.items()}
    return params, preset.build(scaled)  # type: ignore[arg-type]


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
