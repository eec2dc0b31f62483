"""End to end on the virtual bus: every shipped config, every driver, twists from CAN frames.

The odometry the gateway integrates from the simulated encoders must match the ground truth
(the simulators' exact wheel angles) within 1 % of the distance travelled.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import pytest

from gateway.types import GatewayState
from tests.conftest import CONFIG_DIR
from tests.e2e_helpers import Rig, path_legs, virtual_config

if TYPE_CHECKING:
    from pathlib import Path

CONFIGS = sorted(CONFIG_DIR.glob("*.yaml"))


def drive(rig: Rig, shape: str) -> None:
    legs = path_legs(rig.config, shape)
    assert all(rig.config.model.feasible(t) for t, _ in legs)
    for twist, seconds in legs:
        rig.advance(seconds, lambda r, t=twist: r.send_can_twist(t))  # type: ignore[misc]
    rig.advance(1.0, lambda r: r.send_can_twist(type(twist)()))


@pytest.mark.parametrize("shape", ["square", "circle"])
@pytest.mark.parametrize("path", CONFIGS, ids=lambda p: p.stem)
def test_odometry_matches_ground_truth(path: Path, shape: str, channel: str) -> None:
    cfg = virtual_config(path, channel, rate_hz=100.0)
    with Rig(cfg) as rig:
        rig.enable()
        drive(rig, shape)
        assert rig.gw.state is GatewayState.RUNNING, rig.gw.supervisor.reason
        got, want = rig.gw.odometry.state, rig.truth.state
        assert want.distance_m > 2.0
        err = math.hypot(got.pose.x_m - want.pose.x_m, got.pose.y_m - want.pose.y_m)
        assert err <= 0.01 * want.distance_m, (got.pose, want.pose)
        heading = abs((got.pose.theta_rad - want.pose.theta_rad + math.pi) % (2 * math.pi)
                      - math.pi)
        assert heading <= 0.01 * want.distance_m
        assert rig.gw.counts["can_twists"] > 100
        assert rig.gw.counts["send_failures"] == 0
        assert rig.gw.supervisor.counts["infeasible"] == 0
