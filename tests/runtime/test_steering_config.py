"""Steering actuators over CAN, without a bus: the ``steering:`` block, the ODrive position
commands and driver, and the Ackermann linkage.

Golden frame: the ODrive CAN protocol documentation (docs.odriverobotics.com, can-protocol),
"Set_Input_Pos, node 0: pos 1.5, vel_ff 2.0,
torque_ff -0.5", cross-checked with the official 0.5.6 DBC (``Axis0_Set_Input_Pos``).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import cantools
import pytest
import yaml
from hypothesis import given
from hypothesis import strategies as st

from drivers.odrive import OdriveDriver
from drivers.odrive.codec import OdriveCodec
from drivers.odrive.commands import SetControllerMode, SetInputPos, decode_command
from drivers.odrive.enums import CmdId, ControlMode
from gateway.config import load_config, parse_config
from gateway.core.errors import ConfigError, EncodeError
from gateway.core.linkage import virtual_angle
from gateway.core.types import MotorConfig, MotorRole, Twist
from gateway.drive.driveset import DriveSet
from tests import factories
from tests.conftest import CONFIG_DIR, SIM_ODRIVE_ENDPOINTS
from tests.runtime.steering_helpers import ACKERMANN, SWERVE

pytestmark = pytest.mark.timeout(60)

DBC_PATH = Path(__file__).resolve().parent.parent / "data" / "odrive-cansimple-0.5.6.dbc"


def _doc(path: Path = SWERVE) -> dict[str, Any]:
    doc = yaml.safe_load(path.read_text())
    assert isinstance(doc, dict)
    return doc


def _steer_motor(node_id: int = 5, zero_rad: float = 0.0, invert: bool = False) -> MotorConfig:
    return factories.steer_motor("odrive", node_id, zero_rad=zero_rad, gear_ratio=12.8,
                                 invert=invert)


# ----------------------------------------------------------------------------- configuration


def test_swerve_config_has_four_actuators() -> None:
    cfg = load_config(SWERVE)
    assert [a.wheel for a in cfg.steering] == [
        "front_left steering", "front_right steering", "rear_left steering",
        "rear_right steering",
    ]
    assert all(a.role is MotorRole.STEER and a.gear_ratio == 12.8 for a in cfg.steering)
    assert [a.steers for a in cfg.steering] == [
        ("front_left",), ("front_right",), ("rear_left",), ("rear_right",)
    ]
    assert all(m is not None and m.role is MotorRole.DRIVE for m in cfg.motors)


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"steering": {"middle": {"node_id": 9}}},
         "steering.middle: unknown steered wheel or steer group (this robot's: front_left, "
         "front_right, rear_left, rear_right)"),
        ({"steering": {"front_left": {"node_id": 2}}},
         "the motors of 'front_right' and 'front_left steering' share odrive node_id 2"),
        ({"steering": {"front_left": {"node_id": 9, "driver": "vesc", "pole_pairs": 7}}},
         "steering.front_left.driver: the vesc driver does not command steering actuators"),
        ({"steering": {"front_left": {"node_id": 9, "zero_rad": "a"}}},
         "steering.front_left.zero_rad: expected float"),
        ({"steering": {"front_left": {"node_id": 9, "input_mode": 2}}},
         "input_mode: expected 1 (passthrough) for a steering actuator"),
        ({"steering": [1]}, "steering: expected a mapping of steered wheel or steer group"),
        ({"steering": {"front_left": 5}}, "steering.front_left: expected a mapping, got 5"),
    ],
)
def test_steering_block_errors(change: dict[str, Any], message: str) -> None:
    doc = _doc()
    del doc["steering"], doc["steering_defaults"]
    doc["steering_defaults"] = {"driver": "odrive", "max_rpm": 3000}
    doc.update(change)
    with pytest.raises(ConfigError) as info:
        cfg = parse_config(doc, "robot.yaml")
        DriveSet(cfg)
    assert message in str(info.value)


def test_steering_needs_a_steerable_wheel() -> None:
    doc = _doc(CONFIG_DIR / "differential_castor.yaml")
    castor = next(w for w in load_config(CONFIG_DIR / "differential_castor.yaml").wheels
                  if w.type.value == "castor")
    doc["steering"] = {castor.name: {"driver": "odrive", "node_id": 9, "max_rpm": 100}}
    with pytest.raises(ConfigError, match="is a castor wheel; it swivels by itself"):
        parse_config(doc, "robot.yaml")
    doc["steering"] = {"left": {"driver": "odrive", "node_id": 9, "max_rpm": 100}}
    with pytest.raises(ConfigError, match=r"wheel 'left' is not steered \(a fixed wheel\)"):
        parse_config(doc, "robot.yaml")


def test_synchro_group_takes_one_actuator() -> None:
    doc = _doc(CONFIG_DIR / "synchro.yaml")
    cfg = load_config(CONFIG_DIR / "synchro.yaml")
    member = cfg.wheels[0].name
    doc["steering"] = {member: {"driver": "odrive", "node_id": 20, "max_rpm": 100}}
    with pytest.raises(ConfigError, match="steered together with its group 'synchro'"):
        parse_config(doc, "robot.yaml")
    doc["steering"] = {"synchro": {"driver": "odrive", "node_id": 20, "max_rpm": 100,
                                   "watchdog_endpoints": SIM_ODRIVE_ENDPOINTS}}
    cfg = parse_config(doc, "robot.yaml")
    (actuator,) = cfg.steering
    assert actuator.steers == tuple(w.name for w in cfg.wheels)
    drives = DriveSet(cfg)
    assert drives.steered_by == (tuple(range(len(cfg.wheels))),)


def test_steering_defaults_without_steering_is_an_error() -> None:
    doc = _doc()
    del doc["steering"]
    with pytest.raises(ConfigError, match="steering_defaults: given without a steering: block"):
        parse_config(doc, "robot.yaml")


# ----------------------------------------------------------------------------- ODrive codec


def test_set_input_pos_golden() -> None:
    frame = OdriveCodec().make_set_input_pos(0, 1.5, 2.0, -0.5)
    assert frame.arbitration_id == 0x00C
    assert frame.data == bytes.fromhex("0000C03FD0070CFE")
    assert decode_command(OdriveCodec(), frame) == SetInputPos(0, 1.5, 2.0, -0.5)


@given(
    node=st.integers(0, 0x3E),
    pos=st.floats(-1e6, 1e6, width=32),
    vel=st.floats(-32.0, 32.0),
    torque=st.floats(-32.0, 32.0),
)
def test_set_input_pos_matches_official_dbc(
    node: int, pos: float, vel: float, torque: float
) -> None:
    dbc: Any = cantools.database.load_file(str(DBC_PATH), frame_id_mask=0x1F)
    frame = OdriveCodec().make_set_input_pos(node, pos, vel, torque)
    decoded: dict[str, Any] = dbc.get_message_by_frame_id(CmdId.SET_INPUT_POS).decode(frame.data)
    assert decoded["Input_Pos"] == pos
    assert abs(decoded["Vel_FF"] - vel) <= 0.0005 + 1e-9
    assert abs(decoded["Torque_FF"] - torque) <= 0.0005 + 1e-9
    back = decode_command(OdriveCodec(), frame)
    assert isinstance(back, SetInputPos)
    assert back.pos_turns == pos and abs(back.vel_ff_turns_s - vel) <= 0.0005 + 1e-9


def test_feed_forward_is_clipped_and_position_must_be_finite() -> None:
    codec = OdriveCodec()
    big = decode_command(codec, codec.make_set_input_pos(1, 0.0, 1e6))
    assert isinstance(big, SetInputPos) and big.vel_ff_turns_s == pytest.approx(32.767)
    with pytest.raises(EncodeError, match="Expected Input_Pos for node 1"):
        codec.make_set_input_pos(1, math.nan)


# ----------------------------------------------------------------------------- ODrive driver


def test_driver_arms_steering_in_position_control() -> None:
    drive = factories.motor("odrive", 1, "front_left", gear_ratio=6.75, max_rpm=6000.0)
    drv = OdriveDriver([drive, _steer_motor()])
    codec = OdriveCodec()
    modes = [decode_command(codec, f) for f in drv.enable(0.0)]
    assert SetControllerMode(1, ControlMode.VELOCITY_CONTROL, 1) in modes
    assert SetControllerMode(5, ControlMode.POSITION_CONTROL, 1) in modes
    first = [decode_command(codec, f) for f in drv.command([2.0, 0.5], 0.0)]
    assert first[0] is not None and first[0].node_id == 1
    # 0.5 rad of the wheel's plane is 0.5 * 12.8 / (2 pi) motor turns; no rate known yet.
    assert isinstance(first[1], SetInputPos)
    assert first[1].node_id == 5 and first[1].vel_ff_turns_s == 0.0
    assert first[1].pos_turns == pytest.approx(0.5 * 12.8 / (2 * math.pi), rel=1e-6)
    # 0.01 s later at 0.6 rad: 10 rad/s of the plane, 10 * 12.8 / (2 pi) turns/s forward.
    second = decode_command(codec, drv.command([2.0, 0.6], 0.01)[1])
    assert isinstance(second, SetInputPos)
    assert second.vel_ff_turns_s == pytest.approx(10 * 12.8 / (2 * math.pi), abs=0.001)
    with pytest.raises(
        EncodeError, match=r'^Expected a finite steering angle for ODrive node 5 \("front_left'
    ):
        drv.command([0.0, math.inf], 0.02)


def test_driver_reports_absolute_steering_angle() -> None:
    motor = _steer_motor(zero_rad=3.0, invert=True)
    drv = OdriveDriver([motor])
    codec = OdriveCodec()
    turns = (3.0 - 0.25 * 12.8) / (2 * math.pi)  # -0.25 rad through the inversion
    for t in (1.0, 2.0):  # the same reading twice: absolute, not counted from the first
        drv.on_frame(codec.make_encoder_estimates(5, turns, 0.0).stamped(t))
        fb = drv.feedback(0)
        assert fb is not None and fb.position_rad == pytest.approx(0.25, abs=1e-6)
    assert motor.motor_to_steer_rad(motor.steer_to_motor_rad(-1.2)) == pytest.approx(-1.2)


# ----------------------------------------------------------------------------- Ackermann linkage


@given(vx=st.floats(-1.0, 1.0), curvature=st.floats(-1.0, 1.0))
def test_linkage_angle_is_the_same_from_either_front_wheel(vx: float, curvature: float) -> None:
    cfg = load_config(ACKERMANN)
    res = cfg.model.try_ik(Twist(vx, 0.0, vx * curvature))
    if res is None:
        return
    drives = DriveSet(cfg)
    (delta,) = drives.steer_setpoints(res.steer_rad)
    left, right = (cfg.wheels[cfg.model.index(n)] for n in ("front_left", "front_right"))
    front = [res.steer_rad[cfg.model.index(n)] or 0.0 for n in ("front_left", "front_right")]
    for _, angle in drives.wheel_angles(0, delta):
        assert abs(angle) <= 0.6 + 1e-12  # the linkage keeps both within their limits
    # A twist too slow to slip beyond the tolerance may leave a wheel stopped at its limit, or
    # (standing still) where it was: the geometry is exact otherwise.
    if max(abs(a) for a in front) >= 0.6 - 1e-9 or abs(vx) < 1e-3:
        return
    for angle, wheel in zip(front, (left, right), strict=True):
        assert virtual_angle(angle, wheel.x, wheel.y) == pytest.approx(delta, abs=1e-12)
    for i, angle in drives.wheel_angles(0, delta):
        # And back: the linkage puts each wheel where the inverse kinematics wants it.
        assert angle == pytest.approx(res.steer_rad[i], abs=1e-12)
    if curvature > 0.01:  # a left turn, forward or back
        assert front[0] > delta > 0.0  # the inner wheel turns more
    assert left.x == right.x


def test_linkage_travel_is_where_both_wheels_are_within_limits() -> None:
    cfg = load_config(ACKERMANN)
    (a,) = cfg.steering
    assert a.linkage == "ackermann" and a.steers == ("front_left", "front_right")
    low, high = a.steer_range_rad
    assert high == pytest.approx(-low)
    # At full travel the inner wheel is at its 0.6 rad limit, the virtual wheel short of it.
    drives = DriveSet(cfg)
    angles = dict(drives.wheel_angles(0, high))
    assert max(angles.values()) == pytest.approx(0.6)
    assert high < 0.6


@pytest.mark.parametrize(
    ("block", "message"),
    [
        ({"linkage": "ackermann"}, "steering.axle.wheels: expected the wheels a ackermann "
                                   "linkage turns, got none"),
        ({"wheels": ["front_left", "front_right"]},
         "steering.axle.wheels: expected linkage: ackermann with a list of wheels"),
        ({"wheels": ["front_left"], "linkage": "ackermann"},
         "expected a list of two or more of this robot's steered wheels"),
        ({"wheels": ["front_left", "rear_left"], "linkage": "ackermann"},
         "wheel 'rear_left' is not steered (a fixed wheel)"),
        ({"wheels": ["front_left", "front_right"], "linkage": "sideways"},
         "steering.axle.linkage: expected one of 'direct', 'ackermann', got 'sideways'"),
    ],
)
def test_linkage_errors(block: dict[str, Any], message: str) -> None:
    doc = _doc(ACKERMANN)
    doc["steering"] = {"axle": {"driver": "odrive", "node_id": 3, "max_rpm": 3000, **block}}
    with pytest.raises(ConfigError) as info:
        parse_config(doc, "robot.yaml")
    assert message in str(info.value)


def test_linkage_needs_one_axle_and_less_than_a_quarter_turn() -> None:
    doc = _doc()
    del doc["steering_defaults"]
    doc["steering"] = {"pair": {"driver": "odrive", "node_id": 9, "max_rpm": 3000,
                                "wheels": ["front_left", "rear_left"], "linkage": "ackermann"}}
    with pytest.raises(ConfigError, match="expected wheels of one axle ahead of or behind"):
        parse_config(doc, "robot.yaml")
    doc["steering"]["pair"]["wheels"] = ["front_left", "front_right"]
    with pytest.raises(ConfigError, match=r"steers to 3\.14159 rad; an Ackermann linkage turns "
                                          r"its wheels less than pi/2 either way"):
        parse_config(doc, "robot.yaml")
    doc = _doc(ACKERMANN)
    doc["steering"] = {"front_left": {"driver": "odrive", "node_id": 9, "max_rpm": 3000},
                       "pair": {"driver": "odrive", "node_id": 10, "max_rpm": 3000,
                                "wheels": ["front_left", "front_right"], "linkage": "ackermann"}}
    with pytest.raises(ConfigError, match=r"wheel 'front_left' is already turned by "
                                          r"steering\.front_left"):
        parse_config(doc, "robot.yaml")
