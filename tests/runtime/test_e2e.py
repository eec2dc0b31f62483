"""End to end on the virtual bus: every shipped config and so every driver, driving a square
and a circle with twists from CAN frames and from the control socket.

The odometry the gateway integrates from the simulated encoders must match the ground truth
(the simulators' exact wheel angles) within 1 % of the distance travelled.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import pytest

from gateway.core.types import GatewayState, Twist
from tests.conftest import CONFIG_DIR
from tests.e2e_helpers import Rig, SocketPilot, path_legs, virtual_config

if TYPE_CHECKING:
    from pathlib import Path

#: Longer than the 10 s default: each drives a whole path on simulated time (about 2 s idle).
pytestmark = pytest.mark.timeout(60)


CONFIGS = sorted(CONFIG_DIR.glob("*.yaml"))


def drive(rig: Rig, shape: str, pilot: SocketPilot | None) -> None:
    legs = path_legs(rig.config, shape)
    assert all(rig.config.model.feasible(t) for t, _ in legs)
    cycle = [0]

    def send(r: Rig, t: Twist) -> None:
        if pilot is None:
            r.send_can_twist(t)
        elif cycle[0] % 5 == 0:  # 20 Hz at 100 Hz, well inside the 0.5 s command timeout
            pilot.send(op="twist", vx=t.vx_m_s, vy=t.vy_m_s, wz=t.wz_rad_s)
            replies = pilot.messages()
            assert all(m["ok"] for m in replies if "ok" in m), replies
        cycle[0] += 1

    for twist, seconds in legs:
        rig.advance(seconds, lambda r, t=twist: send(r, t))  # type: ignore[misc]
    rig.advance(1.0, lambda r: send(r, Twist()))


@pytest.mark.parametrize("source", ["can", "socket"])
@pytest.mark.parametrize("shape", ["square", "circle"])
@pytest.mark.parametrize("path", CONFIGS, ids=lambda p: p.stem)
def test_odometry_matches_ground_truth(
    path: Path, shape: str, source: str, channel: str, sock_path: str
) -> None:
    cfg = virtual_config(path, channel, rate_hz=100.0)
    # (Frames at their send times: stamped with the 100 Hz cycle, a VESC's 50 Hz STATUS would
    # be up to 10 ms late, differently for each VESC; 1.2 % off on the differential tub.)
    with Rig(cfg, sock_path if source == "socket" else None, send_stamps=True) as rig:
        pilot = SocketPilot(sock_path) if source == "socket" else None
        try:
            rig.enable()
            drive(rig, shape, pilot)
        finally:
            if pilot is not None:
                pilot.close()
        assert rig.gw.state is GatewayState.RUNNING, rig.gw.supervisor.reason
        assert rig.gw.supervisor.counts.faults == 0, rig.gw.supervisor.reason
        got, want = rig.gw.odometry.state, rig.truth.state
        assert want.distance_m > 2.0
        err = math.hypot(got.pose.x_m - want.pose.x_m, got.pose.y_m - want.pose.y_m)
        assert err <= 0.01 * want.distance_m, (got.pose, want.pose)
        heading = abs((got.pose.theta_rad - want.pose.theta_rad + math.pi) % (2 * math.pi)
                      - math.pi)
        assert heading <= 0.01 * want.distance_m
        if source == "can":
            assert rig.gw.counts.can_twists > 100
        assert rig.gw.edge.counts.send_failures == 0
        assert rig.gw.supervisor.counts.infeasible == 0


def test_synchro_corners_under_a_low_acceleration_limit(
    channel: str, tmp_path: Path
) -> None:
    """The shipped synchro robot with its acceleration limit lowered to 20 rad/s^2 drives the
    square: at the corner from driving backwards to driving right, the interpolated twist's
    wheel angle starts beyond the steering range and sweeps back, and the steering actuator
    (a simulated CiA 402 drive in cyclic synchronous position mode, which overshoots a target
    that reverses at full rate) must turn once, not swing past and back until its tracking
    check faults the robot."""
    text = (CONFIG_DIR / "synchro.yaml").read_text()
    assert "max_wheel_accel_rad_s2: 60.0" in text
    path = tmp_path / "synchro.yaml"
    path.write_text(text.replace("max_wheel_accel_rad_s2: 60.0", "max_wheel_accel_rad_s2: 20.0"))
    with Rig(virtual_config(path, channel, rate_hz=100.0)) as rig:
        rig.enable()
        drive(rig, "square", None)
        # (A fault that the automatic recovery mended would leave the robot RUNNING.)
        assert rig.gw.supervisor.counts.faults == 0, rig.gw.supervisor.reason
        assert rig.gw.state is GatewayState.RUNNING
        got, want = rig.gw.odometry.state, rig.truth.state
        err = math.hypot(got.pose.x_m - want.pose.x_m, got.pose.y_m - want.pose.y_m)
        assert err <= 0.01 * want.distance_m, (got.pose, want.pose)
