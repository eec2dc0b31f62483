"""Shared fixtures and helpers of the daemon's safety tests (test_safety_*): a rig on simulated
time with its socket pilot, and reading its state and speeds."""

from __future__ import annotations

from typing import TYPE_CHECKING

import pytest

from tests.conftest import CONFIG_DIR
from tests.e2e_helpers import Rig, SocketPilot, virtual_config

if TYPE_CHECKING:
    from collections.abc import Iterator

    from gateway.core.types import GatewayState

TB3 = CONFIG_DIR / "turtlebot3_burger.yaml"


@pytest.fixture
def rig(channel: str, sock_path: str, request: pytest.FixtureRequest) -> Iterator[Rig]:
    loop = getattr(request, "param", {})
    cfg = virtual_config(TB3, channel, rate_hz=100.0, **loop)
    with Rig(cfg, sock_path) as r:
        r.enable()
        yield r


@pytest.fixture
def pilot(rig: Rig, sock_path: str) -> Iterator[SocketPilot]:
    p = SocketPilot(sock_path)
    yield p
    p.close()


def state(rig: Rig) -> GatewayState:
    """The gateway state, read through a call so mypy does not narrow it across cycles."""
    return rig.gw.state


def speeds(rig: Rig) -> tuple[float, ...]:
    return rig.gw.prev.wheel_rad_s


def commanded(rig: Rig) -> tuple[float, ...]:
    """The wheel speeds the simulated controllers were last commanded: what reached them."""
    return tuple(s.motor.motor_to_wheel_rad_s(s.model.target_rad_s) for s in rig.drive_sims)
