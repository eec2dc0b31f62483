"""The anchor loop (tools/anchor_loop.py) is correct, so the benchmark compares like with like.

Its inverse kinematics agrees with wheelgate's, its frames are Set_Input_Vel in the official
ODrive DBC with the expected turns/s, and its odometry follows a straight drive against
simulated ODrives on a python-can virtual bus.
"""

from __future__ import annotations

import json
import logging
import math
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

import cantools
import pytest

from drivers.odrive.sim import OdriveSimulator
from gateway.cli import main as cli
from gateway.config import load_config
from gateway.core.types import Twist

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "tools"))

from anchor_loop import DEFAULT_CONFIG, AnchorLoop, Robot, wheel_speeds
from throughput_rig import Sims

if TYPE_CHECKING:
    import can
    from click.testing import CliRunner

    from gateway.core.settings import GatewayConfig

DBC_PATH = Path(__file__).resolve().parents[1] / "data" / "odrive-cansimple-0.5.6.dbc"
TWISTS = [(0.3, 0.0, 0.0), (0.0, 0.2, 0.0), (0.0, 0.0, 0.5), (0.3, 0.1, 0.2),
          (-0.2, 0.4, -1.0)]
TAU = 2.0 * math.pi


@pytest.fixture
def config() -> GatewayConfig:
    return load_config(DEFAULT_CONFIG)


@pytest.fixture
def robot() -> Robot:
    return Robot.from_file()


@pytest.mark.parametrize("twist", TWISTS)
def test_ik_agrees_with_robot_model(config: GatewayConfig, robot: Robot,
                                    twist: tuple[float, float, float]) -> None:
    expected = config.model.ik(Twist(*twist)).wheel_rad_s
    assert wheel_speeds(robot, *twist) == pytest.approx(expected, abs=1e-12)


def test_motor_speeds_agree_with_wheelgate_ik(runner: CliRunner, robot: Robot) -> None:
    vx, vy, wz = TWISTS[3]
    result = runner.invoke(cli, ["ik", "--vx", str(vx), "--vy", str(vy), "--wz", str(wz),
                                 "--json"])
    assert result.exit_code == 0, result.output
    rpm = [w["motor_rpm"] for w in json.loads(result.output)["wheels"]]
    turns = [w * c for w, c in zip(wheel_speeds(robot, vx, vy, wz), robot.turns_per_rad,
                                   strict=True)]
    assert [t * 60.0 for t in turns] == pytest.approx(rpm, rel=1e-12)


def test_frames_are_set_input_vel(config: GatewayConfig, robot: Robot,
                                  buses: tuple[can.BusABC, can.BusABC]) -> None:
    logging.getLogger("cantools").setLevel(logging.ERROR)
    dbc: Any = cantools.database.load_file(str(DBC_PATH))
    bus, peer = buses
    loop = AnchorLoop(robot, bus)
    loop.set_twist(*TWISTS[3])
    loop.cycle()
    got = []
    while (msg := peer.recv(0.0)) is not None:
        got.append(msg)
    wheels = config.model.ik(Twist(*TWISTS[3])).wheel_rad_s
    motors = [m for m in config.motors if m is not None]
    assert len(got) == len(motors) == 4
    for msg, motor, w in zip(got, motors, wheels, strict=True):
        assert not msg.is_extended_id and msg.dlc == 8
        assert dbc.get_message_by_frame_id(msg.arbitration_id).name == (
            f"Axis{motor.node_id}_Set_Input_Vel")
        fields = dbc.decode_message(msg.arbitration_id, msg.data)
        expected = w * motor.gear_ratio * motor.sign / TAU
        assert fields["Input_Vel"] == pytest.approx(expected, rel=1e-6)
        assert fields["Input_Torque_FF"] == 0.0


@pytest.mark.parametrize(("twist", "pattern"), [
    ((0.3, 0.0, 0.0), (1, 1, 1, 1)),  # forward: every wheel forward
    ((0.0, 0.2, 0.0), (-1, 1, 1, -1)),  # to the left: the diagonals against each other
])
def test_odometry_of_a_straight_drive(config: GatewayConfig, robot: Robot,
                                      buses: tuple[can.BusABC, can.BusABC],
                                      twist: tuple[float, float, float],
                                      pattern: tuple[int, ...]) -> None:
    bus, sim_bus = buses
    motors = [m for m in config.motors if m is not None]
    sims = [OdriveSimulator(m) for m in motors]
    stepper = Sims(list(sims), sim_bus)
    loop = AnchorLoop(robot, bus)
    loop.arm()
    t, dt = 0.0, 0.001

    def run(cycles: int) -> None:
        nonlocal t
        for _ in range(cycles):
            loop.cycle()
            t += dt
            stepper.step(t)

    run(200)
    assert loop.axis_state == [8, 8, 8, 8] and loop.axis_error == [0, 0, 0, 0]
    start = [s.position_turns for s in sims]
    loop.set_twist(*twist)
    run(1000)
    loop.set_twist(0.0, 0.0, 0.0)
    run(300)
    # The truth: every wheel's travel from the simulators' exact positions, each in the
    # direction the drive turns it.
    travel = [(s.position_turns - p0) / c * robot.wheel_radius * d
              for s, p0, c, d in zip(sims, start, robot.turns_per_rad, pattern, strict=True)]
    assert min(travel) > 0.15
    along = sum(travel) / 4
    assert (loop.x, loop.y) == pytest.approx(
        (along, 0.0) if twist[0] else (0.0, along), abs=1e-4)
    assert loop.theta == pytest.approx(0.0, abs=1e-6)
    assert loop.distance == pytest.approx(along, abs=1e-4)
