"""Loading a robot's configuration: YAML text, checked key by key, into the frozen settings of
:mod:`gateway.core.settings`.

This layer sits above the driver contract: a motor block's protocol keys are validated by the
driver that serves it (:mod:`gateway.drive.registry`).
"""

from __future__ import annotations

from gateway.config.load import (
    DEFAULT_NAME,
    MAX_WHEELS,
    client_socket_path,
    default_socket_path,
    load_config,
    parse_config,
)
from gateway.core.settings import BusConfig, GatewayConfig, LoopConfig

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
