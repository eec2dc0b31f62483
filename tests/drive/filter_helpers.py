"""Shared helpers of the receive-filter tests (test_filters_*): the configurations and their
drivers."""

from __future__ import annotations

import functools
from typing import TYPE_CHECKING, Any

from gateway.config import load_config, parse_config
from gateway.config.yaml_text import load_yaml
from gateway.drive.driveset import DriveSet
from tests.conftest import CONFIG_DIR, REPO

if TYPE_CHECKING:

    from gateway.core.settings import GatewayConfig
    from gateway.drive.driver import MotorDriver
    from gateway.drive.filters import CanFilter

#: The embedded default robot (``None``), the shipped configurations, and robots made from
#: them for declarations no shipped file exercises.
ODRIVE_EXTENDED = "default, odrive extended_id"
#: An identifier and its type.
Ident = tuple[int, bool]


@functools.cache
def config(name: str | None) -> GatewayConfig:
    """A configuration of :data:`CONFIGS` (validated once)."""
    if name == ODRIVE_EXTENDED:
        text = (REPO / "gateway" / "data" / "default.yaml").read_text()
        raw = load_yaml(text, name)
        assert isinstance(raw, dict)
        raw["motor_defaults"]["extended_id"] = True
        raw["motors"]["front_left"]["node_id"] = 0x10203  # identifiers above 16 bits
        return parse_config(raw, name)
    return load_config(None if name is None else CONFIG_DIR / name)


def drivers(name: str | None) -> list[MotorDriver[Any]]:
    """Fresh drivers of every protocol of configuration ``name``."""
    return [drv for drv, _ in DriveSet(config(name)).groups]


def declared(drv: MotorDriver[Any]) -> tuple[CanFilter, ...]:
    filters = drv.receive_filters()
    assert filters is not None, f"{type(drv).__name__} declares no receive filters"
    return filters
