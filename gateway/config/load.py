"""YAML configuration, validated once into frozen dataclasses.

A file names a drive and its geometry, the motors and the limits::

    drive: differential          # a preset, or "generic" for a wheel list as in seed 000
    geometry: {wheel_radius: 0.033, track: 0.160}
    motor_defaults: {driver: odrive, max_rpm: 61}      # merged into every motor block
    motors:
      left:  {node_id: 1}
      right: {node_id: 2, invert: true}
    limits: {max_wheel_accel_rad_s2: 30.0}
    kinematics: {slip_tolerance_m_s: 0.001}
    bus: {interface: virtual, channel: wheelgate, bitrate: 500000}

With ``drive: generic`` the ``wheels:`` list gives each wheel's ``name``, ``type``, ``alpha``,
``l``, ``beta``, ``radius`` (and ``gamma``, ``d``, steering limits, ``steer_group``) and, for a
driven wheel, its ``motor:`` block.  Angles are in radians, lengths in metres.

Unknown keys are errors, and every error names the file, the key path, what was expected and
what came.  Bus settings follow the precedence CLI flag > ``GATEWAY_INTERFACE`` /
``GATEWAY_CHANNEL`` / ``GATEWAY_BITRATE`` environment variables > file > defaults.

The keys of every block are described once in :mod:`gateway.config.keys`; the frozen
dataclasses that come out are defined in :mod:`gateway.core.settings` and exported here, with
the loaders, as this module's public names.
"""

from __future__ import annotations

import dataclasses
import math
import os
import tempfile
from importlib import resources
from pathlib import Path
from types import MappingProxyType
from typing import TYPE_CHECKING

from gateway.config.keys import (
    BUS_KEYS,
    CAN_ID_KEYS,
    GATEWAY_KEYS,
    KINEMATICS_KEYS,
    LIMIT_KEYS,
    LINKAGE_KEYS,
    MOTOR_KEYS,
    STEERING_KEYS,
    TOP_KEYS,
    WHEEL_KEYS,
)
from gateway.config.yaml_text import MAX_BYTES, load_yaml, read_text
from gateway.core.errors import ConfigError, DriverNotFoundError, KinematicsError
from gateway.core.kinematics import PRESETS, Limits, RobotModel, Wheel, WheelType
from gateway.core.kinematics.model import validate_wheel
from gateway.core.linkage import virtual_angle
from gateway.core.options import OptionSpec, validate_block
from gateway.core.protection import Guard, WatchdogPolicy, check_timeout
from gateway.core.settings import BusConfig, GatewayConfig, LoopConfig
from gateway.core.types import MotorConfig, MotorRole
from gateway.drive.filters import own_id_collisions
from gateway.drive.registry import get_driver_class, valid_drivers
from gateway.wire.can import CanIds

if TYPE_CHECKING:
    from collections.abc import Mapping

    from gateway.drive.driveset import DriveSet

__all__ = [
    "DEFAULT_NAME",
    "MAX_WHEELS",
    "BusConfig",
    "GatewayConfig",
    "LoopConfig",
    "client_socket_path",
    "default_socket_path",
    "load_config",
    "parse_config",
]

#: The most wheels a robot may have (a bound on what a config can make the loader build).
MAX_WHEELS = 64
#: Name shown for the configuration embedded in the package.
DEFAULT_NAME = "<embedded default>"


def default_socket_path() -> str:
    """``$WHEELGATE_SOCKET``, else ``/run/wheelgate/wheelgate.sock`` when that directory is
    writable (systemd's RuntimeDirectory), else ``$XDG_RUNTIME_DIR/wheelgate.sock``, else a
    per-user path in the temporary directory."""
    env = os.environ.get("WHEELGATE_SOCKET")
    if env:
        return env
    run = Path("/run/wheelgate")
    if run.is_dir() and os.access(run, os.W_OK):
        return str(run / "wheelgate.sock")
    xdg = os.environ.get("XDG_RUNTIME_DIR")
    if xdg and Path(xdg).is_dir():
        return str(Path(xdg) / "wheelgate.sock")
    return str(Path(tempfile.gettempdir()) / f"wheelgate-{os.getuid()}.sock")


#: Where the systemd unit's daemon listens (``RuntimeDirectory=wheelgate``).
SERVICE_SOCKET = Path("/run/wheelgate/wheelgate.sock")


def client_socket_path() -> str:
    """The socket a client talks to when none is given: ``$WHEELGATE_SOCKET``, else the
    service's ``/run/wheelgate/wheelgate.sock`` when it exists (a member of the group
    ``wheelgate`` can reach it but not write the directory), else
    :func:`default_socket_path`."""
    env = os.environ.get("WHEELGATE_SOCKET")
    if env:
        return env
    if SERVICE_SOCKET.exists():
        return str(SERVICE_SOCKET)
    return default_socket_path()


def load_config(
    path: str | Path | None = None, overrides: Mapping[str, object] | None = None
) -> GatewayConfig:
    """Read and validate a configuration file.

    :param path: the YAML file; the embedded default when ``None``.
    :param overrides: bus keys from the command line (``interface``, ``channel``, ``bitrate``),
        ``None`` values ignored.
    :raises ConfigError: naming the file and key path of the first problem.
    """
    if path is None:
        source = DEFAULT_NAME
        text = resources.files("gateway").joinpath("data/default.yaml").read_text("utf-8")
    else:
        source = str(path)
        try:
            with Path(path).open("rb") as f:
                data = f.read(MAX_BYTES + 1)
        except OSError as err:
            raise ConfigError(f"{source}: cannot read the file: {err.strerror}") from err
        text = read_text(data, source)
    raw = load_yaml(text, source)
    return parse_config(raw, source, overrides)


def parse_config(
    raw: object, source: str, overrides: Mapping[str, object] | None = None
) -> GatewayConfig:
    """Validate an already-loaded YAML document (see :func:`load_config`)."""
    if not isinstance(raw, dict):
        raise ConfigError(f"{source}: expected a mapping at the top level, got {raw!r}")
    for key in raw:
        if key not in TOP_KEYS:
            raise ConfigError(
                f"{source}: {key}: unknown key (known keys: {', '.join(sorted(TOP_KEYS))})"
            )
    drive = raw.get("drive")
    choices = [*sorted(PRESETS), "generic"]
    if drive not in choices:
        raise ConfigError(f"{source}: drive: expected one of {', '.join(choices)}, got {drive!r}")
    config_dir = "" if source == DEFAULT_NAME else str(Path(source).resolve().parent)
    defaults = raw.get("motor_defaults", {})
    if not isinstance(defaults, dict):
        raise ConfigError(f"{source}: motor_defaults: expected a mapping, got {defaults!r}")
    if drive == "generic":
        for key in ("geometry", "motors"):
            if key in raw:
                raise ConfigError(
                    f"{source}: {key}: not used with drive: generic (motors go in wheels[i].motor)"
                )
        geometry: dict[str, object] = {}
        wheels, motor_raw = _generic_wheels(raw.get("wheels"), source)
    else:
        if "wheels" in raw:
            raise ConfigError(
                f"{source}: wheels: only used with drive: generic; a {drive} drive takes "
                f"geometry: and motors:"
            )
        geometry, wheels = _preset_wheels(str(drive), raw.get("geometry"), source)
        motor_raw = _preset_motors(raw.get("motors"), wheels, source)
    motors = tuple(
        None if block is None
        else _motor(
            block, defaults, w.name, f"{source}: {_motor_path(drive, i, w.name)}", config_dir
        )
        for i, (w, block) in enumerate(zip(wheels, motor_raw, strict=True))
    )
    steering = _steering(
        raw.get("steering"), raw.get("steering_defaults", {}), wheels, source, config_dir
    )
    _check_nodes((*motors, *steering), source)
    wheels = _limit_steer_rates(wheels, steering)
    kin = validate_block(raw.get("kinematics", {}), KINEMATICS_KEYS, f"{source}: kinematics")
    try:
        model = RobotModel(wheels, slip_tolerance_m_s=float(kin["slip_tolerance_m_s"]))  # type: ignore[arg-type]
    except KinematicsError as err:
        raise ConfigError(f"{source}: {err}") from err
    lim = validate_block(raw.get("limits", {}), LIMIT_KEYS, f"{source}: limits")
    limits = Limits(
        max_wheel_rad_s=tuple(math.inf if m is None else m.max_wheel_rad_s for m in motors),
        max_wheel_accel_rad_s2=float(lim["max_wheel_accel_rad_s2"]),  # type: ignore[arg-type]
        max_linear_m_s=float(lim["max_linear_m_s"]),  # type: ignore[arg-type]
        max_angular_rad_s=float(lim["max_angular_rad_s"]),  # type: ignore[arg-type]
    )
    bus = _bus(raw.get("bus", {}), source, overrides or {})
    loop = _loop(raw.get("gateway", {}), source)
    name = raw.get("name", Path(source).stem if source != DEFAULT_NAME else "default")
    if not isinstance(name, str):
        raise ConfigError(f"{source}: name: expected str, got {name!r}")
    warnings = []
    if loop.socket_mode & 0o002:
        warnings.append(
            f"{source}: gateway.socket_mode: {loop.socket_mode:#o} makes the control socket "
            f"writable by every local user, who could then drive the robot; expected 0o660 "
            f"(the owner and the group wheelgate), with socket_uids for finer control"
        )
    config = GatewayConfig(
        source, name, str(drive), MappingProxyType(geometry), model, motors, limits, bus, loop,
        steering, tuple(warnings),
    )
    from gateway.drive.driveset import DriveSet  # noqa: PLC0415 - the drivers load after the config

    drives = DriveSet(config)
    _check_own_ids(config, drives)
    more = _check_protection(config, drives)
    return dataclasses.replace(config, warnings=(*config.warnings, *more)) if more else config


def _check_protection(config: GatewayConfig, drives: DriveSet) -> list[str]:
    """Every motor's controller-side protection (:mod:`gateway.core.protection`) against the policy.

    :return: warnings: a motor with no known protection, a timeout too short for the loop.
    :raises ConfigError: with ``controller_watchdog: required``, for a motor whose protocol
        could set its watchdog over CAN but whose configuration does not say how.
    """
    warnings = []
    period = 1.0 / config.loop.rate_hz
    for label, prot in drives.protections():
        where = f"{config.source}: {label}"
        if prot.guard is Guard.UNSTATED:
            if prot.configurable and config.loop.controller_watchdog is WatchdogPolicy.REQUIRED:
                raise ConfigError(
                    f"{where}: controller watchdog {prot.how}, and gateway.controller_watchdog "
                    f"is required; fix: {prot.fix} (or controller_watchdog: warn, to arm "
                    f"without it)"
                )
            warnings.append(f"{where}: controller watchdog {prot.how}; fix: {prot.fix}")
        elif prot.guard is Guard.NONE:
            fix = f"; fix: {prot.fix}" if prot.fix else ""
            warnings.append(f"{where}: controller watchdog {prot.describe()}{fix}")
        problem = check_timeout(prot, period, where)
        if problem:
            warnings.append(problem)
    return warnings


def _check_own_ids(config: GatewayConfig, drives: DriveSet) -> None:
    """The gateway's own CAN IDs must not be any controller's (:func:`own_id_collisions`).

    :raises ConfigError: naming every collision and the fix.
    """
    collisions = own_id_collisions(config, drives)
    if collisions:
        raise ConfigError(
            f"{config.source}: " + "; ".join(collisions)
            + ". Expected the gateway's own identifiers (gateway.can_ids, defaults 0x100 to "
            "0x104) apart from every controller's: choose other can_ids or other node IDs"
        )


def _motor_path(drive: object, index: int, name: str) -> str:
    return f"wheels[{index}].motor" if drive == "generic" else f"motors.{name}"


def _preset_wheels(drive: str, raw: object, source: str) -> tuple[dict[str, object], list[Wheel]]:
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
    return params, preset.build(params)  # type: ignore[arg-type]


def _preset_motors(
    raw: object, wheels: list[Wheel], source: str
) -> list[dict[str, object] | None]:
    if not isinstance(raw, dict):
        raise ConfigError(f"{source}: motors: expected a mapping of wheel name to motor block, "
                          f"got {raw!r}")
    names = [w.name for w in wheels]
    for key in raw:
        if key not in names:
            raise ConfigError(
                f"{source}: motors.{key}: unknown wheel (wheels of this drive: {', '.join(names)})"
            )
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


def _generic_wheels(
    raw: object, source: str
) -> tuple[list[Wheel], list[dict[str, object] | None]]:
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


def _steering(
    raw: object, defaults: object, wheels: list[Wheel], source: str, config_dir: str
) -> tuple[MotorConfig, ...]:
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
        listed = link["wheels"]
        if listed:
            members = _linkage_wheels(listed, str(link["linkage"]), by_name, choices, where)
        else:
            if link["linkage"] != "direct":
                raise ConfigError(f"{where}.wheels: expected the wheels a {link['linkage']} "
                                  f"linkage turns, got none")
            members = _actuated_wheels(str(key), by_name, groups, choices, where)
        for name in members:
            if name in owner:
                raise ConfigError(f"{where}: wheel {name!r} is already turned by "
                                  f"steering.{owner[name]}; expected one actuator per wheel")
            owner[name] = str(key)
        if link["linkage"] == "ackermann":
            axle = by_name[members[0]].x
            lows = [virtual_angle(by_name[n].steer_min, axle, by_name[n].y) for n in members]
            highs = [virtual_angle(by_name[n].steer_max, axle, by_name[n].y) for n in members]
            travel = (max(lows), min(highs))  # where every wheel is within its limits
        else:
            travel = (min(by_name[n].steer_min for n in members),
                      max(by_name[n].steer_max for n in members))
        out.append(_motor(keys, defaults, f"{key} steering", where, config_dir, tuple(members),
                          travel, str(link["linkage"])))
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
    listed: object, linkage: str, by_name: Mapping[str, Wheel], choices: list[str], where: str
) -> list[str]:
    """The wheels a linkage turns: steerable, of one axle off the reference point's line,
    each within a quarter turn of straight ahead."""
    if linkage != "ackermann":
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


def _limit_steer_rates(wheels: list[Wheel], steering: tuple[MotorConfig, ...]) -> list[Wheel]:
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


def _motor(
    raw: Mapping[str, object],
    defaults: Mapping[str, object],
    wheel: str,
    where: str,
    config_dir: str,
    steers: tuple[str, ...] = (),
    travel: tuple[float, float] = (-math.pi, math.pi),
    linkage: str = "direct",
) -> MotorConfig:
    """A motor block, or with ``steers`` a steering actuator's block."""
    keys = STEERING_KEYS if steers else MOTOR_KEYS
    merged = {**defaults, **raw}
    common = {k: merged[k] for k in keys if k in merged}
    v = validate_block(common, keys, where, "steering keys" if steers else "motor keys")
    driver = str(v["driver"])
    try:
        cls = get_driver_class(driver)
    except DriverNotFoundError as err:
        raise ConfigError(f"{where}.driver: {err}") from err
    if steers and not cls.STEERING:
        able = sorted(n for n in valid_drivers() if _steers(n))
        raise ConfigError(
            f"{where}.driver: the {driver} driver does not command steering actuators "
            f"(drivers that do: {', '.join(able) or 'none'})"
        )
    node_id = int(v["node_id"])  # type: ignore[call-overload]
    protocol = {k: x for k, x in merged.items() if k not in keys}
    if "config_dir" in cls.OPTIONS and "config_dir" not in protocol:
        # Relative paths in protocol keys (a DBC file) are relative to the config file.
        protocol["config_dir"] = config_dir
    options = cls.validate_options(protocol, where)
    cls.validate_node_id(node_id, f"{where}.node_id", options)
    return MotorConfig(
        wheel=wheel,
        driver=driver,
        node_id=node_id,
        gear_ratio=float(v["gear_ratio"]),  # type: ignore[arg-type]
        invert=bool(v["invert"]),
        max_rpm=float(v["max_rpm"]),  # type: ignore[arg-type]
        options=MappingProxyType(options),
        role=MotorRole.STEER if steers else MotorRole.DRIVE,
        zero_rad=float(v.get("zero_rad", 0.0)),  # type: ignore[arg-type]
        steers=steers,
        steer_range_rad=travel,
        linkage=linkage,
    )


def _steers(name: str) -> bool:
    """Whether the driver ``name`` commands steering actuators (``False`` if it cannot load)."""
    try:
        return get_driver_class(name).STEERING
    except DriverNotFoundError:
        return False


def _check_nodes(motors: tuple[MotorConfig | None, ...], source: str) -> None:
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


def _bus(raw: object, source: str, overrides: Mapping[str, object]) -> BusConfig:
    v = validate_block(raw, BUS_KEYS, f"{source}: bus", "bus keys")
    for key, spec in BUS_KEYS.items():
        env = os.environ.get(f"GATEWAY_{key.upper()}")
        if env is not None:
            value: object = env
            if key == "bitrate":
                try:
                    value = int(env)
                except ValueError:
                    raise ConfigError(
                        f"GATEWAY_BITRATE: expected an integer bit rate, got {env!r}"
                    ) from None
            v[key] = spec.validate(value, f"GATEWAY_{key.upper()}")
        if overrides.get(key) is not None:
            v[key] = spec.validate(overrides[key], f"--{key}")
    return BusConfig(str(v["interface"]), str(v["channel"]), int(v["bitrate"]))  # type: ignore[call-overload]


def _loop(raw: object, source: str) -> LoopConfig:
    v = validate_block(raw, GATEWAY_KEYS, f"{source}: gateway", "gateway keys")
    ids = validate_block(v["can_ids"], CAN_ID_KEYS, f"{source}: gateway.can_ids", "CAN ID keys")
    try:
        can_ids = CanIds.from_mapping(ids)
    except ConfigError as err:
        raise ConfigError(f"{source}: {err}") from err
    uids = v["socket_uids"]
    if not isinstance(uids, list) or not all(
        isinstance(u, int) and not isinstance(u, bool) and u >= 0 for u in uids
    ):
        raise ConfigError(
            f"{source}: gateway.socket_uids: expected a list of user IDs, got {uids!r}"
        )
    if float(v["odom_rate_hz"]) > float(v["rate_hz"]):  # type: ignore[arg-type]
        raise ConfigError(
            f"{source}: gateway.odom_rate_hz: expected at most rate_hz ({v['rate_hz']}), "
            f"got {v['odom_rate_hz']}"
        )
    skip = ("can_ids", "socket_uids", "controller_watchdog")
    fields = {k: x for k, x in v.items() if k not in skip}
    return LoopConfig(
        **fields,  # type: ignore[arg-type]
        socket_uids=tuple(uids),
        can_ids=can_ids,
        controller_watchdog=WatchdogPolicy(v["controller_watchdog"]),
    )
