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

The keys of every block are described once in :mod:`gateway.config.keys`; the motor and
steering blocks are read by :mod:`gateway.config.motors`; the frozen dataclasses that come out
are defined in :mod:`gateway.core.settings` and exported here, with the loaders, as this
module's public names.
"""

from __future__ import annotations

import dataclasses
import math
import os
import pkgutil
from pathlib import Path
from types import MappingProxyType
from typing import TYPE_CHECKING

from gateway.config.keys import (
    BUS_KEYS,
    CAN_ID_KEYS,
    GATEWAY_KEYS,
    KINEMATICS_KEYS,
    LIMIT_KEYS,
    TOP_KEYS,
    WHEEL_KEYS,
)
from gateway.config.motors import (
    check_nodes,
    limit_steer_rates,
    motor_block,
    motor_path,
    preset_motors,
    steering_blocks,
)
from gateway.config.yaml_text import MAX_BYTES, load_yaml, read_text
from gateway.core.can_ids import CanIds
from gateway.core.choice import choice
from gateway.core.errors import ConfigError, KinematicsError
from gateway.core.kinematics import PRESETS, Limits, RobotModel, Wheel, WheelType
from gateway.core.kinematics.model import validate_wheel
from gateway.core.options import OptionSpec, unknown_key, validate_block
from gateway.core.protection import Guard, WatchdogPolicy, check_timeout
from gateway.core.settings import LOOP_CHOICES, BusConfig, GatewayConfig, LoopConfig
from gateway.drive.ownership import own_id_collisions

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
    import tempfile  # noqa: PLC0415 - the last resort; importing it costs start-up time

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
        # pkgutil reads through the package's loader, zipped or not, as importlib.resources
        # does, without importing zipfile, tempfile and the compression modules (about a
        # twentieth of the CLI's start-up in instructions).
        data = pkgutil.get_data("gateway", "data/default.yaml")
        if data is None:  # a loader without get_data: not one of Python's own
            raise ConfigError(f"{source}: the package's loader cannot read data/default.yaml")
        text = data.decode("utf-8")
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
            raise unknown_key(f"{source}: {key}", key, {"top-level keys": TOP_KEYS})
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
        motor_raw = preset_motors(raw.get("motors"), wheels, source)
    motors = tuple(
        None if block is None
        else motor_block(
            block, defaults, w.name, f"{source}: {motor_path(drive, i, w.name)}", config_dir
        )
        for i, (w, block) in enumerate(zip(wheels, motor_raw, strict=True))
    )
    steering = steering_blocks(
        raw.get("steering"), raw.get("steering_defaults", {}), wheels, source, config_dir
    )
    check_nodes((*motors, *steering), source)
    wheels = limit_steer_rates(wheels, steering)
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
    if "bus" not in raw and bus.interface == "virtual" and source != DEFAULT_NAME:
        warnings.append(
            f"{source}: no bus: block: the robot is driven on python-can's virtual bus "
            f"{bus.channel!r}, where only simulated controllers answer (`wheelgate run --sim`); "
            f"a robot needs e.g. bus: {{interface: socketcan, channel: can0}}"
        )
    if loop.socket_mode & 0o002:
        warnings.append(
            f"{source}: gateway.socket_mode: {loop.socket_mode:#o} makes the control socket "
            f"writable by every local user, who could then drive the robot; expected 0o660 "
            f"(the owner and the group wheelgate), with socket_uids for finer control"
        )
    bridge = foxglove = None
    if "bridge" in raw or "foxglove" in raw:
        # Loaded only for these blocks: their settings classes cost start-up time otherwise.
        from gateway.config.bridge import parse_bridge, parse_foxglove  # noqa: PLC0415

        if "bridge" in raw:
            bridge, said = parse_bridge(raw["bridge"], source, name)
            warnings += said
        if "foxglove" in raw:
            foxglove = parse_foxglove(raw["foxglove"], source)
    config = GatewayConfig(
        source, name, str(drive), MappingProxyType(geometry), model, motors, limits, bus, loop,
        steering, tuple(warnings), bridge, foxglove,
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
    for key, kind in LOOP_CHOICES.items():
        v[key] = choice(kind, v[key], f"{source}: gateway.{key}")
    fields = {k: x for k, x in v.items() if k not in ("can_ids", "socket_uids")}
    return LoopConfig(
        **fields,  # type: ignore[arg-type]
        socket_uids=tuple(uids),
        can_ids=can_ids,
    )
