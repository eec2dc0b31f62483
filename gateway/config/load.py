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

import binascii
import dataclasses
import math
import os
import pkgutil
from pathlib import Path
from types import MappingProxyType
from typing import TYPE_CHECKING

from gateway.config.daemon_blocks import parse_bus, parse_loop
from gateway.config.gather import Problems
from gateway.config.keys import KINEMATICS_KEYS, LIMIT_KEYS, TOP_KEYS
from gateway.config.motors import (
    check_nodes,
    limit_steer_rates,
    motor_block,
    motor_path,
    preset_motors,
    radius_multipliers,
    steering_blocks,
)
from gateway.config.wheels import (
    MAX_WHEELS,
    a_drive,
    generic_wheels,
    preset_wheels,
    stand_in_wheels,
    wheel_layout,
)
from gateway.config.yaml_text import MAX_BYTES, load_yaml, not_a_mapping, read_text
from gateway.core.errors import ConfigError, KinematicsError
from gateway.core.kinematics import PRESETS, Limits, RobotModel
from gateway.core.options import unknown_key, validate_block
from gateway.core.protection import Guard, WatchdogPolicy, check_timeout
from gateway.core.settings import BusConfig, GatewayConfig, LoopConfig
from gateway.core.types import MotorConfig
from gateway.drive.ownership import driver_collisions, own_id_collisions

if TYPE_CHECKING:
    from collections.abc import Collection, Mapping

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

#: The longest robot name (it names the e-stop latch file and the status).
MAX_NAME = 64
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
    path: str | Path | None = None, overrides: Mapping[str, object] | None = None,
    interfaces: Collection[str] | None = None,
) -> GatewayConfig:
    """Read and validate a configuration file.

    :param path: the YAML file; the embedded default when ``None``.
    :param overrides: bus keys from the command line (``interface``, ``channel``, ``bitrate``),
        ``None`` values ignored.
    :param interfaces: python-can's interfaces, to check ``bus.interface`` against with the
        file's other problems (``None``: not checked here).
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
    # (binascii: already imported by the libraries, so free at start-up, unlike hashlib)
    config = parse_config(raw, source, overrides, interfaces, f"{binascii.crc32(data):08x}")
    return config if path is None else dataclasses.replace(config, path=os.path.abspath(path))


def parse_config(
    raw: object, source: str, overrides: Mapping[str, object] | None = None,
    interfaces: Collection[str] | None = None, fingerprint: str = "",
) -> GatewayConfig:
    """Validate an already-loaded YAML document (see :func:`load_config`).

    :param fingerprint: :attr:`GatewayConfig.fingerprint` (the file's bytes' CRC-32).

    :raises ConfigError: with every problem of the file, one line each (block by block; a
        block that needs a broken one is not checked).
    """
    if raw is None:
        raise ConfigError(f"{source}: the file is empty; expected a robot's configuration "
                          f"(wheelgate init writes a commented one)")
    if not isinstance(raw, dict):
        raise not_a_mapping(raw, source)
    found = Problems()
    for key in raw:
        if key not in TOP_KEYS:
            found.add(str(unknown_key(f"{source}: {key}", key, {"top-level keys": TOP_KEYS})))
    robot = _robot(raw, source, found)
    lim = found.check(lambda: validate_block(raw.get("limits", {}), LIMIT_KEYS,
                                             f"{source}: limits"))
    bus = found.check(lambda: parse_bus(raw.get("bus", {}), source, overrides or {},
                                        interfaces))
    loop = found.check(lambda: parse_loop(raw.get("gateway", {}), source))
    name = raw.get("name", Path(source).stem if source != DEFAULT_NAME else "default")
    if not isinstance(name, str):
        found.add(f"{source}: name: expected str, got {name!r}")
    elif not 0 < len(name) <= MAX_NAME or not name.isprintable():
        found.add(f"{source}: name{'' if 'name' in raw else ' (the file name: state name:)'}: "
                  f"expected 1 to {MAX_NAME} printable characters, got {name!r}")
    bridge = foxglove = None
    bridge_said: list[str] = []
    if "bridge" in raw or "foxglove" in raw:
        # Loaded only for these blocks: their settings classes cost start-up time otherwise.
        from gateway.config.bridge import check_joints, parse_bridge, parse_foxglove  # noqa: PLC0415

        if "bridge" in raw and isinstance(name, str):
            parsed = found.check(lambda: parse_bridge(raw["bridge"], source, name))
            if parsed is not None:
                bridge, bridge_said = parsed
        if "foxglove" in raw:
            foxglove = found.check(lambda: parse_foxglove(raw["foxglove"], source))
    found.raise_any()
    assert robot is not None and lim is not None and bus is not None and loop is not None
    drive, geometry, model, motors, steering, calibration = robot
    if bridge is not None:  # (the joints it names must be the robot's)
        check_joints(bridge, [m.wheel for m in (*motors, *steering) if m is not None], source)
    limits = Limits(
        max_wheel_rad_s=tuple(math.inf if m is None else m.max_wheel_rad_s for m in motors),
        max_wheel_accel_rad_s2=float(lim["max_wheel_accel_rad_s2"]),  # type: ignore[arg-type]
        max_linear_m_s=float(lim["max_linear_m_s"]),  # type: ignore[arg-type]
        max_angular_rad_s=float(lim["max_angular_rad_s"]),  # type: ignore[arg-type]
        max_wheel_decel_rad_s2=float(lim["max_wheel_decel_rad_s2"]) or None,  # type: ignore[arg-type]
    )
    warnings = [*_warnings(raw, source, bus, loop), *bridge_said,
                *wheel_layout(model, motors, source)]
    config = GatewayConfig(
        source, str(name), drive, MappingProxyType(geometry), model, motors, limits, bus, loop,
        steering, tuple(warnings), bridge, foxglove, MappingProxyType(calibration), fingerprint,
    )
    from gateway.drive.driveset import DriveSet  # noqa: PLC0415 - the drivers load after the config

    try:  # (what only a driver can check: a DBC file, an endpoints file; after the rest)
        drives = DriveSet(config)
    except ConfigError as err:
        raise ConfigError(f"{source}: {err}") from err
    _check_own_ids(config, drives)
    more = _check_protection(config, drives) + [f"{source}: {d}" for d in drives.doubts()]
    return dataclasses.replace(config, warnings=(*config.warnings, *more)) if more else config


_Robot = tuple[str, dict[str, object], RobotModel, tuple[MotorConfig | None, ...],
               tuple[MotorConfig, ...], dict[str, float]]


def _robot(raw: dict[str, object], source: str, found: Problems) -> _Robot | None:
    """The drive, its geometry, the model, the motors and the steering actuators; ``None``
    with the problems in ``found`` (each motor block checked on its own)."""
    drive = raw.get("drive")
    choices = [*sorted(PRESETS), "generic"]
    if drive not in choices:
        found.add(f"{source}: drive: expected one of {', '.join(choices)}, got {drive!r}")
        return None
    config_dir = "" if source == DEFAULT_NAME else str(Path(source).resolve().parent)
    defaults = raw.get("motor_defaults", {})
    if not isinstance(defaults, dict):
        found.add(f"{source}: motor_defaults: expected a mapping, got {defaults!r}")
        return None
    kin = found.check(lambda: validate_block(raw.get("kinematics", {}), KINEMATICS_KEYS,
                                             f"{source}: kinematics", "kinematics keys"))
    geometry: dict[str, object] = {}
    stand_in = False  # the wheels are stand-ins for a broken geometry: no model
    if drive == "generic":
        for key in ("geometry", "motors"):
            if key in raw:
                found.add(f"{source}: {key}: not used with drive: generic (motors go in "
                          f"wheels[i].motor)")
        parsed = found.check(lambda: generic_wheels(raw.get("wheels"), source))
        if parsed is None:
            return None
        wheels, motor_raw = parsed
    else:
        if "wheels" in raw:
            found.add(f"{source}: wheels: only used with drive: generic; "
                      f"{a_drive(str(drive))} takes geometry: and motors:")
        separation = 1.0 if kin is None else float(kin["wheel_separation_multiplier"])  # type: ignore[arg-type]
        preset = found.check(lambda: preset_wheels(str(drive), raw.get("geometry"), source,
                                                    separation))
        if preset is None:  # the blocks that name wheels are still checked, on stand-ins
            stand_ins = stand_in_wheels(str(drive), raw.get("geometry"))
            if stand_ins is None:
                return None
            wheels, stand_in = stand_ins, True
        else:
            geometry, wheels = preset
        blocks = found.check(lambda: preset_motors(raw.get("motors"), wheels, source))
        if blocks is None:
            return None
        motor_raw = blocks
    motors = tuple(
        None if block is None
        else found.check(lambda w=w, i=i, block=block: motor_block(  # type: ignore[misc]
            block, defaults, w.name, f"{source}: {motor_path(drive, i, w.name)}", config_dir,
            defaults_where=f"{source}: motor_defaults"))
        for i, (w, block) in enumerate(zip(wheels, motor_raw, strict=True))
    )
    steering = found.check(lambda: steering_blocks(
        raw.get("steering"), raw.get("steering_defaults", {}), wheels, source, config_dir))
    calibration: dict[str, float] = {}
    if kin is not None:
        if drive == "generic" and kin["wheel_separation_multiplier"] != 1.0:
            found.add(f"{source}: kinematics.wheel_separation_multiplier: expected a preset "
                      f"drive with a track; with drive: generic, give the measured positions "
                      f"in wheels:")
        radii = found.check(lambda: radius_multipliers(kin["wheel_radius_multipliers"], wheels,
                                                       f"{source}: kinematics"))
        wheels = wheels if radii is None else [
            dataclasses.replace(w, radius=w.radius * radii.get(w.name, 1.0)) for w in wheels]
        calibration.update((f"radius {name}", f) for name, f in (radii or {}).items() if f != 1.0)
        if kin["wheel_separation_multiplier"] != 1.0:
            calibration["wheel_separation_multiplier"] = float(kin["wheel_separation_multiplier"])  # type: ignore[arg-type]
    if steering is None or kin is None or any(
        m is None for m, block in zip(motors, motor_raw, strict=True) if block is not None
    ):
        return None
    found.check(lambda: check_nodes((*motors, *steering), source))
    if stand_in:
        return None
    wheels = limit_steer_rates(wheels, steering)
    try:
        model = RobotModel(wheels, slip_tolerance_m_s=float(kin["slip_tolerance_m_s"]))  # type: ignore[arg-type]
    except KinematicsError as err:
        found.add(f"{source}: {err}")
        return None
    return str(drive), geometry, model, motors, steering, calibration


def _warnings(raw: dict[str, object], source: str, bus: BusConfig, loop: LoopConfig) -> list[str]:
    """What a valid file may still get wrong: no bus: block, no acceleration limit, a socket
    every user may write."""
    warnings = []
    if "bus" not in raw and bus.interface == "virtual" and source != DEFAULT_NAME:
        warnings.append(
            f"{source}: no bus: block: the robot is driven on python-can's virtual bus "
            f"{bus.channel!r}, where only simulated controllers answer (`wheelgate run --sim`); "
            f"a robot needs e.g. bus: {{interface: socketcan, channel: can0}}"
        )
    limits = raw.get("limits")
    if not isinstance(limits, dict) or "max_wheel_accel_rad_s2" not in limits:
        what = "no limits: block" if limits is None else "limits: no max_wheel_accel_rad_s2"
        steps = ("speeds every wheel up in one cycle (max_wheel_decel_rad_s2 bounds only "
                 "slowing down)" if isinstance(limits, dict) and "max_wheel_decel_rad_s2" in limits
                 else "steps every wheel to its new speed in one cycle")
        warnings.append(
            f"{source}: {what}: a twist {steps} "
            f"(wheel slip, a jolt, a tipping robot) and only each motor's max_rpm bounds the "
            f"speed; set e.g. limits: {{max_wheel_accel_rad_s2: 30.0}} (rad/s^2 at the wheel), "
            f"and max_linear_m_s, max_angular_rad_s for the body"
        )
    if loop.socket_mode & 0o002:
        warnings.append(
            f"{source}: gateway.socket_mode: {loop.socket_mode:#o} makes the control socket "
            f"writable by every local user, who could then drive the robot; expected 0o660 "
            f"(the owner and the group wheelgate), with socket_uids for finer control"
        )
    return warnings


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
    """The gateway's own CAN IDs must not be any controller's (:func:`own_id_collisions`), nor
    one protocol's identifiers another's (:func:`driver_collisions`).

    :raises ConfigError: naming every collision and the fix.
    """
    collisions = own_id_collisions(config, drives)
    if collisions:
        raise ConfigError(
            f"{config.source}: " + "; ".join(collisions)
            + ". Expected the gateway's own identifiers (gateway.can_ids, defaults 0x100 to "
            "0x104) apart from every controller's: choose other can_ids or other node IDs"
        )
    shared = driver_collisions(drives)
    if shared:
        raise ConfigError(f"{config.source}: " + "; ".join(shared) + ". Expected every "
                          "protocol's identifiers apart from the others': choose other node IDs")


