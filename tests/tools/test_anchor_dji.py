"""The DJI anchor loop (tools/anchor_dji.py) is correct, so the benchmark compares like with
like: its command frame is the C620 current frame for the right ESCs, its speed loops make the
simulated wheels follow the mecanum inverse kinematics of wheelgate, and its odometry follows
the simulated wheels.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import TYPE_CHECKING

import pytest

from drivers.dji.codec import COMMAND_STRUCT
from drivers.dji.sim import DjiSimulator
from gateway.core.types import Twist

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "tools"))

from anchor_dji import DjiAnchorLoop
from throughput_rig import Sims, robot_config, robot_raw

if TYPE_CHECKING:
    import can


def test_the_command_frame_is_zero_until_every_esc_reported(
        buses: tuple[can.BusABC, can.BusABC]) -> None:
    bus, peer = buses
    loop = DjiAnchorLoop.from_mapping(robot_raw("dji", "x"), bus)
    loop.set_twist(0.3, 0.0, 0.0)
    loop.cycle()
    msg = peer.recv(0.0)
    assert msg is not None and peer.recv(0.0) is None
    assert (msg.arbitration_id, msg.is_extended_id, msg.dlc) == (0x200, False, 8)
    assert COMMAND_STRUCT.unpack(msg.data) == (0, 0, 0, 0)


@pytest.mark.parametrize("twist", [(0.3, 0.0, 0.0), (0.0, 0.2, 0.0), (0.1, 0.1, 0.5)])
def test_the_wheels_follow_the_twist_and_odometry_follows_the_wheels(
        buses: tuple[can.BusABC, can.BusABC], twist: tuple[float, float, float]) -> None:
    bus, sim_bus = buses
    config = robot_config("dji", "x")
    motors = [m for m in config.motors if m is not None]
    sims = [DjiSimulator(m) for m in motors]
    stepper = Sims(list(sims), sim_bus)
    loop = DjiAnchorLoop.from_mapping(robot_raw("dji", "x"), bus)
    assert loop.period_s == 0.001 and (loop.kp, loop.ki, loop.limit_a) == (0.1, 1.0, 20.0)
    t = 0.0
    start = [0.0] * 4

    def run(cycles: int) -> None:
        nonlocal t
        for _ in range(cycles):
            loop.cycle()
            t += 0.001
            stepper.step(t)

    run(50)
    assert loop.healthy()
    start = [s.wheel_position_rad for s in sims]
    x0, y0, th0 = loop.x, loop.y, loop.theta
    loop.set_twist(*twist)
    run(1500)
    expected = config.model.ik(Twist(*twist)).wheel_rad_s
    assert [s.wheel_velocity_rad_s for s in sims] == pytest.approx(expected, rel=0.02, abs=0.05)
    # Odometry against the truth: wheelgate's forward kinematics of the simulated wheels'
    # travel (the twist is constant, the start transient small: one SE(2) step of the mean).
    travel = [s.wheel_position_rad - p for s, p in zip(sims, start, strict=True)]
    mean = config.model.fk(travel).twist
    assert loop.theta - th0 == pytest.approx(mean.wz_rad_s, abs=2e-3)
    if not twist[2]:
        assert (loop.x - x0, loop.y - y0) == pytest.approx(
            (mean.vx_m_s, mean.vy_m_s), abs=2e-3)
