"""The blocks of a configuration that set up the daemon rather than the robot: ``bus:`` and
``gateway:`` (read by :func:`gateway.config.load.parse_config`)."""

from __future__ import annotations

import os
from typing import TYPE_CHECKING

from gateway.config.keys import BUS_KEYS, CAN_ID_KEYS, GATEWAY_KEYS
from gateway.core.can_ids import CanIds
from gateway.core.choice import choice
from gateway.core.errors import ConfigError
from gateway.core.options import validate_block
from gateway.core.settings import LOOP_CHOICES, BusConfig, LoopConfig

if TYPE_CHECKING:
    from collections.abc import Collection, Mapping


def parse_bus(raw: object, source: str, overrides: Mapping[str, object],
              interfaces: Collection[str] | None = None) -> BusConfig:
    """The ``bus:`` block, then the environment's ``GATEWAY_*`` variables, then the command
    line's ``overrides`` (that precedence).

    :param interfaces: python-can's interfaces, to check the one given against (``None``: not
        checked; the loader does not import python-can, a command that opens a bus does).
    """
    v = validate_block(raw, BUS_KEYS, f"{source}: bus", "bus keys")
    said = f"{source}: bus.interface"
    if os.environ.get("GATEWAY_INTERFACE") is not None:
        said = "GATEWAY_INTERFACE"
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
    if overrides.get("interface") is not None:
        said = "--interface"
    if interfaces is not None and v["interface"] not in interfaces:
        raise ConfigError(f"{said}: expected a python-can interface, one of "
                          f"{', '.join(sorted(interfaces))}; got {v['interface']!r}")
    return BusConfig(str(v["interface"]), str(v["channel"]), int(v["bitrate"]))  # type: ignore[call-overload]


def parse_loop(raw: object, source: str) -> LoopConfig:
    """The ``gateway:`` block: the loop, the socket, the gateway's own CAN IDs, the policies."""
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
    state_file = str(v["state_file"])
    if state_file and os.path.isdir(state_file):
        raise ConfigError(
            f"{source}: gateway.state_file: expected the path of the e-stop latch file, got "
            f"{state_file!r}, a directory (the e-stop would not survive a restart)"
        )
    for key, kind in LOOP_CHOICES.items():
        v[key] = choice(kind, v[key], f"{source}: gateway.{key}")
    fields = {k: x for k, x in v.items() if k not in ("can_ids", "socket_uids")}
    return LoopConfig(
        **fields,  # type: ignore[arg-type]
        socket_uids=tuple(uids),
        can_ids=can_ids,
    )
