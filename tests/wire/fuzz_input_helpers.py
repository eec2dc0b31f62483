"""Shared helpers of the fuzzing of the gateway's own inputs (test_fuzz_inputs_*): a running
gateway with its simulators on simulated time, and the hypothesis settings."""

from __future__ import annotations

import contextlib
import itertools
from typing import TYPE_CHECKING

from hypothesis import HealthCheck, settings

from gateway.core.types import GatewayState
from tests.e2e_helpers import Rig, virtual_config

if TYPE_CHECKING:
    from collections.abc import Iterator
    from pathlib import Path

FUZZ = settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])
_channels = itertools.count()


@contextlib.contextmanager
def running(path: Path, socket_path: str | None = None) -> Iterator[Rig]:
    """A rig of ``path`` on its own virtual channel, enabled, RUNNING and stopped."""
    cfg = virtual_config(path, f"wg-fuzz-{next(_channels)}", rate_hz=100.0)
    with Rig(cfg, socket_path) as rig:
        rig.enable()
        rig.advance(0.05)
        assert rig.gw.state is GatewayState.RUNNING
        assert all(w == 0.0 for w in rig.gw.prev.wheel_rad_s)
        yield rig
