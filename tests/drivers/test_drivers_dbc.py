"""Tests of the generic DBC driver: options, codec, unwrapping, driver and simulator.

Golden frames for ``config/example_controller.dbc`` are packed by hand with ``struct`` from the
layout in that file and cross-checked with cantools.  ODrive golden frames are the worked
examples of the ODrive CAN protocol documentation (docs.odriverobotics.com, can-protocol) ("Worked
examples" table), encoded here through
the official ODrive DBC (``tests/data/odrive-cansimple-0.5.6.dbc``, a pinned copy).
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import math
import struct
import subprocess
import sys
from typing import TYPE_CHECKING, ClassVar

import cantools
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from drivers.dbc import (
    DbcCodec,
    DbcDriver,
    DbcReading,
    Role,
    UnitConversion,
    describe_fault,
    parse_options,
)
from drivers.dbc.options import POSITION_UNITS, VELOCITY_UNITS
from drivers.dbc.sim import DbcSimulator
from gateway.core.errors import ConfigError, EncodeError
from gateway.core.types import DriveFault, DriveState, Frame, MotorConfig
from gateway.drive.claims import FrameClaim
from gateway.drive.registry import get_driver_class
from tests import factories
from tests.conftest import CONFIG_DIR, DATA_DIR, REPO

if TYPE_CHECKING:
    from collections.abc import Mapping
    from pathlib import Path

EXAMPLE_DBC = str(CONFIG_DIR / "example_controller.dbc")
ODRIVE_DBC = str(DATA_DIR / "odrive-cansimple-0.5.6.dbc")
ODRIVE_SHA256 = "4db07a4cef0ee1a87cfbfc779cabd7db3176072c688a694e3b8842c2dd9bcb55"
TWO_PI = 2.0 * math.pi
GEAR = 10.0
#: One encoder count of the example controller, as a wheel angle (rad).
COUNT_RAD = TWO_PI / 4096 / GEAR
SETTINGS = settings(
    max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)

EXAMPLE: dict[str, object] = {
    "dbc": EXAMPLE_DBC,
    "command_message": "WD_Velocity_Command",
    "command_signal": "Target_Velocity",
    "command_unit": "rpm",
    "feedback_message": "WD_Feedback",
    "velocity_signal": "Actual_Velocity",
    "velocity_unit": "rpm",
    "position_signal": "Position_Count",
    "position_unit": "counts",
    "counts_per_rev": 4096,
    "position_wrap_bits": 32,
    "enable_message": "WD_Enable",
    "enable_signal": "Enable",
    "fault_signal": "Fault_Code",
}
ANGLE: dict[str, object] = {
    "position_message": "WD_Angle",
    "position_signal": "Rotor_Angle",
    "position_unit": "deg",
    "position_wrap_bits": 13,
}


def odrive_options(axis: int = 3, **over: object) -> dict[str, object]:
    """A motor block that drives ODrive axis ``axis`` through the official DBC."""
    opts: dict[str, object] = {
        "dbc": ODRIVE_DBC,
        "command_message": f"Axis{axis}_Set_Input_Vel",
        "command_signal": "Input_Vel",
        "command_unit": "rev/s",
        "feedback_message": f"Axis{axis}_Get_Encoder_Estimates",
        "velocity_signal": "Vel_Estimate",
        "velocity_unit": "rev/s",
        "position_signal": "Pos_Estimate",
        "position_unit": "rev",
        "node_id_in_frame": "none",
        "enable_message": f"Axis{axis}_Set_Axis_State",
        "enable_signal": "Axis_Requested_State",
        "enable_value": 8,  # CLOSED_LOOP_CONTROL
        "disable_value": 1,  # IDLE
        "fault_message": f"Axis{axis}_Heartbeat",
        "fault_signal": "Axis_Error",
    }
    opts.update(over)
    return opts


def motor(
    node: int = 3,
    wheel: str = "left",
    gear: float = GEAR,
    invert: bool = False,
    extra: Mapping[str, object] | None = None,
    *,
    validate: bool = True,
    **over: object,
) -> MotorConfig:
    """An example-controller motor block of the factory (:func:`tests.factories.motor`), with
    ``extra`` and ``over`` replacing protocol keys."""
    return factories.motor("dbc", node, wheel, gear_ratio=gear, invert=invert, validate=validate,
                           options={**EXAMPLE, **(extra or {}), **over})


def odrive_motor(node: int = 3, **over: object) -> MotorConfig:
    """A motor block of the factory that drives ODrive axis ``node`` (:func:`odrive_options`)."""
    return factories.motor("dbc", node, options=odrive_options(node, **over))


@functools.cache
def odrive_codec() -> DbcCodec:
    """One codec for ODrive node 3 (the ODrive DBC takes about 30 ms to load)."""
    return DbcDriver([odrive_motor(3)]).codec


def load_example_db() -> cantools.database.can.Database:
    db = cantools.database.load_file(EXAMPLE_DBC)
    assert isinstance(db, cantools.database.can.Database)
    return db


def rpm(value: float) -> float:
    return value * TWO_PI / 60.0


# ----------------------------------------------------------------------------- registry, files


def test_registry_returns_the_dbc_driver() -> None:
    assert get_driver_class("dbc") is DbcDriver
    assert DbcDriver.NODE_ID_RANGE == (0, 0x7FF)


def test_vendored_odrive_dbc_is_the_pinned_official_file() -> None:
    with open(ODRIVE_DBC, "rb") as f:
        assert hashlib.sha256(f.read()).hexdigest() == ODRIVE_SHA256


# ----------------------------------------------------------------------------- golden frames


def test_example_command_golden_bytes() -> None:
    drv = DbcDriver([motor(3), motor(4, "right", invert=True)])
    drv.enable(0.0)
    wheel = rpm(1500.0) / GEAR  # 1500 rpm at the motor
    frames = drv.command([wheel, wheel], 0.0)
    # Target_Velocity int32 LE x0.1 rpm, Control_Mode u8 = GenSigStartValue 2 (VELOCITY),
    # Accel_Limit u16 = GenSigStartValue 1000, byte 7 unused.
    assert frames == [
        Frame(0x203, struct.pack("<iBHx", 15000, 2, 1000)),
        Frame(0x204, struct.pack("<iBHx", -15000, 2, 1000)),
    ]
    assert frames[0].data == bytes.fromhex("983A000002E80300")
    db = load_example_db()
    assert frames[1].data == db.encode_message(
        "WD_Velocity_Command",
        {"Target_Velocity": -1500.0, "Control_Mode": "VELOCITY", "Accel_Limit": 1000},
    )


def test_example_enable_and_disable_golden_bytes() -> None:
    drv = DbcDriver([motor(3)])
    zero = Frame(0x203, struct.pack("<iBHx", 0, 2, 1000))
    assert drv.enable(0.0) == [zero, Frame(0x183, b"\x01")]
    assert drv.command([1.0], 0.0)[0] != zero
    assert drv.disable(0.0) == [zero, Frame(0x183, b"\x00")]
    assert drv.command([1.0], 0.0) == [zero]  # a disarmed motor is commanded zero


def test_example_feedback_golden_bytes() -> None:
    drv = DbcDriver([motor(3)])
    # Actual_Velocity i16 x0.5 rpm, Position_Count i32 counts, Fault_Code u8, Drive_Temp i8.
    assert drv.on_frame(Frame(0x283, struct.pack("<hiBb", -300, 123456, 0, 25), timestamp_s=1.0))
    fb = drv.feedback(0)
    assert fb is not None
    assert fb.velocity_rad_s == pytest.approx(rpm(-150.0) / GEAR, rel=1e-12)
    assert fb.position_rad == 0.0  # counted from the first sample
    assert fb.timestamp_s == 1.0
    drv.on_frame(Frame(0x283, struct.pack("<hiBb", 0, 123456 + 4096, 0, 25), timestamp_s=1.01))
    fb = drv.feedback(0)
    assert fb is not None
    assert fb.position_rad == pytest.approx(TWO_PI / GEAR, rel=1e-12)


def test_example_angle_message_mixes_byte_orders() -> None:
    sim = DbcSimulator(motor(3, extra=ANGLE), initial_raw=2276)
    frames = sim.tick(0.0)
    # Rotor_Angle: 13 bits little endian at bit 0; Bus_Voltage: Motorola u16 at bytes 2-3
    # (start bit 23), default 0.  WD_Feedback carries the velocity.
    assert Frame(0x303, struct.pack("<H", 2276) + struct.pack(">H", 0)) in frames
    db = load_example_db()
    data = struct.pack("<H", 2276) + struct.pack(">H", 4800)
    assert data == bytes.fromhex("E40812C0")
    assert db.decode_message("WD_Angle", data) == pytest.approx(
        {"Rotor_Angle": 2276 * 360 / 8192, "Bus_Voltage": 48.0}
    )
    readings = sim.codec.decode(Frame(0x303, data))
    assert readings == (DbcReading(3, position_raw=2276),)


def test_odrive_golden_frames_through_the_generic_driver() -> None:
    drv = DbcDriver([odrive_motor(3)])
    # the ODrive CAN protocol documentation, worked examples: Set_Input_Vel node 3, 10 rev/s,
    # Set_Axis_State node 3 CLOSED_LOOP (8) and IDLE (1), DLC 8 as in the DBC.
    assert drv.enable(0.0) == [
        Frame(0x06D, bytes(8)),
        Frame(0x067, bytes.fromhex("0800000000000000")),
    ]
    assert drv.command([10.0 * TWO_PI], 0.0) == [Frame(0x06D, bytes.fromhex("0000204100000000"))]
    assert drv.disable(0.0)[-1] == Frame(0x067, bytes.fromhex("0100000000000000"))
    # Get_Encoder_Estimates reply, pos 12.5 rev, vel -2.25 rev/s.
    assert drv.on_frame(Frame(0x069, bytes.fromhex("00004841000010C0"), timestamp_s=2.0))
    assert drv.codec.decode(Frame(0x069, bytes.fromhex("00004841000010C0"))) == (
        DbcReading(3, velocity=-2.25, position_raw=12.5),
    )
    fb = drv.feedback(0)
    assert fb is not None
    assert fb.velocity_rad_s == pytest.approx(-2.25 * TWO_PI)
    # Heartbeat 0.5: no error, CLOSED_LOOP, trajectory done.
    assert drv.on_frame(Frame(0x061, bytes.fromhex("0000000008000080"), timestamp_s=2.0))
    assert drv.state(0, 2.0) == DriveState.DISABLED


def test_odrive_axis0_messages_with_shifted_node_id_match_the_golden_frame() -> None:
    opts = odrive_options(0, node_id_in_frame="add", node_id_shift=5)
    motors = [factories.motor("dbc", n, w, options=opts) for w, n in (("a", 1), ("b", 3))]
    drv = DbcDriver(motors)
    drv.enable(0.0)
    frames = drv.command([10.0 * TWO_PI, 10.0 * TWO_PI], 0.0)
    assert frames == [
        Frame(0x02D, bytes.fromhex("0000204100000000")),
        Frame(0x06D, bytes.fromhex("0000204100000000")),
    ]


def test_odrive_heartbeat_axis_error_is_a_fault() -> None:
    drv = DbcDriver([odrive_motor(3)])
    drv.enable(0.0)
    drv.on_frame(Frame(0x069, bytes(8), timestamp_s=0.0))
    drv.on_frame(Frame(0x061, struct.pack("<IBBBB", 0x40, 8, 0, 0, 0), timestamp_s=0.0))
    status = drv.status(0.0)[0]
    assert status.state == DriveState.FAULT
    assert status.faults == DriveFault.OTHER
    assert status.detail == "Axis_Error=MOTOR_FAILED"


# ----------------------------------------------------------------------------- encode errors


def test_out_of_range_command_names_signal_node_range_and_value() -> None:
    # A max_rpm beyond the signal's range: the signal's own limit is what refuses.
    drv = DbcDriver([dataclasses.replace(motor(3, gear=1.0, command_unit="rad/s"),
                                         max_rpm=300000.0)])
    drv.enable(0.0)
    with pytest.raises(EncodeError) as info:
        drv.command([20000.0], 0.0)
    assert str(info.value) == (
        'Expected signal "Target_Velocity" of message "WD_Velocity_Command" (0x203) for '
        'node 3 ("left") between -10000 and 10000 rpm, but got 20000.0.'
    )


@pytest.mark.parametrize("speed", [math.nan, math.inf, -math.inf, 31.5])
def test_speed_beyond_max_rpm_or_not_finite_is_refused(speed: float) -> None:
    drv = DbcDriver([motor(3, gear=10.0)])  # max_rpm 3000: 31.4159 rad/s at the wheel
    drv.enable(0.0)
    with pytest.raises(EncodeError) as info:
        drv.command([speed], 0.0)
    assert str(info.value) == (
        'Expected a wheel speed for DBC node 3 ("left") between -31.4159 and 31.4159 rad/s '
        f"(max_rpm 3000), but got {speed}."
    )


def test_wrong_number_of_speeds_is_refused() -> None:
    with pytest.raises(EncodeError) as info:
        DbcDriver([motor(3)]).command([0.0, 0.0], 0.0)
    assert str(info.value) == "Expected 1 setpoints for the DBC motors (left), but got 2."


def test_float32_signal_refuses_values_beyond_float32() -> None:
    drv = DbcDriver([dataclasses.replace(odrive_motor(3), max_rpm=1e42)])
    drv.enable(0.0)
    with pytest.raises(EncodeError, match=r'"Input_Vel".*between -3.40282e\+38 and'):
        drv.command([1e40], 0.0)


# ----------------------------------------------------------------------------- malformed frames


@pytest.mark.parametrize(
    ("frame", "reason"),
    [
        (Frame(0x283, bytes(7)), "Expected 8 bytes"),
        (Frame(0x283, is_remote_frame=True, dlc=8), "remote frame"),
        (Frame(0x303, bytes(5)), "Expected 4 bytes"),
    ],
)
def test_malformed_feedback_is_counted_not_raised(frame: Frame, reason: str) -> None:
    drv = DbcDriver([motor(3, extra=ANGLE)])
    assert drv.on_frame(frame) is True
    assert drv.feedback(0) is None
    assert drv.rejected == {"malformed": 1}
    assert reason in drv.last_rejection["malformed"]


def test_nan_in_a_float_feedback_signal_is_rejected() -> None:
    drv = DbcDriver([odrive_motor(3)])
    assert drv.on_frame(Frame(0x069, struct.pack("<ff", math.nan, 1.0)))
    assert drv.feedback(0) is None
    assert "finite value" in drv.last_rejection["malformed"]


def test_foreign_and_own_command_frames_are_not_feedback() -> None:
    drv = DbcDriver([motor(3)])
    assert drv.on_frame(Frame(0x284, bytes(8))) is False  # another node's feedback
    assert drv.on_frame(Frame(0x203, bytes(8))) is False  # our own command echoed
    # The same number as a 29-bit ID is another device's frame.
    assert drv.on_frame(Frame(0x283, bytes(8), is_extended_id=True)) is False
    assert not drv.rejected


def test_simulator_counts_malformed_commands() -> None:
    sim = DbcSimulator(motor(3))
    assert sim.handle(Frame(0x203, bytes(3)), 0.0) == []
    assert sim.handle(Frame(0x183, b"\x01", is_extended_id=True), 0.0) == []  # not its ID type
    assert sim.rejected == 1
    assert not sim.model.armed


# ----------------------------------------------------------------------------- round trips


@SETTINGS
@given(st.floats(-10000.0, 10000.0))
def test_command_round_trip_within_one_step(value: float) -> None:
    codec = DbcDriver([motor(3)]).codec
    (frame,) = codec.encode_command([value])
    requests = codec.decode_request(frame)
    assert requests is not None and len(requests) == 1
    assert (requests[0].node_id, requests[0].role) == (3, Role.COMMAND)
    assert abs(requests[0].value - value) <= 0.05 + 1e-9


@SETTINGS
@given(st.floats(width=32, allow_nan=False, allow_infinity=False))
def test_float32_command_round_trip_is_exact(value: float) -> None:
    codec = odrive_codec()
    (frame,) = codec.encode_command([value])
    requests = codec.decode_request(frame)
    assert requests is not None and requests[0].value == value


@SETTINGS
@given(st.integers(-32768, 32767), st.integers(-(2**31), 2**31 - 1), st.integers(0, 255))
def test_feedback_round_trip(vel_raw: int, pos_raw: int, fault: int) -> None:
    codec = DbcDriver([motor(3)]).codec
    velocity = vel_raw * 0.5
    (frame,) = codec.encode_feedback([DbcReading(3, velocity, pos_raw, fault)])
    assert frame.arbitration_id == 0x283
    assert struct.unpack("<hiB", frame.data[:7]) == (vel_raw, pos_raw, fault)
    assert codec.decode(frame) == (DbcReading(3, velocity, pos_raw, fault),)


@SETTINGS
@given(st.floats(-20.0, 20.0), st.sampled_from([1.0, 4.5, 19.2]), st.booleans())
def test_wheel_speed_reaches_the_simulated_motor_within_one_step(
    wheel: float, gear: float, invert: bool
) -> None:
    m = dataclasses.replace(motor(3, gear=gear, invert=invert), max_rpm=4000.0)  # 3667 rpm
    drv, sim = DbcDriver([m]), DbcSimulator(m)
    for frame in drv.enable(0.0) + drv.command([wheel], 0.0):
        sim.handle(frame, 0.0)
    assert sim.model.armed
    step = rpm(0.1)  # one Target_Velocity step, motor side
    assert abs(sim.model.target_rad_s - wheel * gear * m.sign) <= step / 2 + 1e-9


@SETTINGS
@given(
    st.integers(-(2**31), 2**31 - 1),
    st.lists(st.integers(-(2**31) + 1, 2**31 - 1), max_size=12),
)
def test_int32_position_unwraps_exactly(start: int, steps: list[int]) -> None:
    drv = DbcDriver([motor(3)])
    codec, raw, total = drv.codec, start, 0
    drv.on_frame(codec.encode_feedback([DbcReading(3, 0.0, raw)])[0])
    for step in steps:
        total += step
        raw = (raw + step + 2**31) % 2**32 - 2**31
        drv.on_frame(codec.encode_feedback([DbcReading(3, 0.0, raw)])[0])
        fb = drv.feedback(0)
        assert fb is not None
        assert fb.position_rad == pytest.approx(total * COUNT_RAD, rel=1e-12, abs=1e-12)


@SETTINGS
@given(st.integers(0, 8191), st.lists(st.integers(-4095, 4095), max_size=12))
def test_13_bit_angle_unwraps(start: int, steps: list[int]) -> None:
    drv = DbcDriver([motor(3, extra=ANGLE)])
    raw, total = start, 0
    drv.on_frame(Frame(0x283, bytes(8)))
    drv.on_frame(Frame(0x303, struct.pack("<HH", raw, 0)))
    for step in steps:
        total += step
        raw = (raw + step) % 8192
        drv.on_frame(Frame(0x303, struct.pack("<HH", raw, 0)))
        fb = drv.feedback(0)
        assert fb is not None
        assert fb.position_rad == pytest.approx(total * TWO_PI / 8192 / GEAR, abs=1e-12)


@pytest.mark.parametrize(
    ("opts", "first", "second", "counts"),
    [
        ({}, 0x7FFFFFFF, -(2**31), 1),  # int32 0x7FFFFFFF -> 0x80000000 is +1
        ({}, -(2**31), 0x7FFFFFFF, -1),
        (ANGLE, 8100, 50, 142),  # specs section 8: 13-bit 8100 -> 50 is +142
        (ANGLE, 50, 8100, -142),
        ({**ANGLE, "position_wrap_bits": 0}, 8100, 50, -8050),  # no wrap configured
    ],
)
def test_position_wrap_examples(
    opts: dict[str, object], first: int, second: int, counts: int
) -> None:
    drv = DbcDriver([motor(3, extra=opts)])
    sim_codec = drv.codec
    for raw in (first, second):
        for frame in sim_codec.encode_feedback([DbcReading(3, 0.0, raw)]):
            drv.on_frame(frame)
    fb = drv.feedback(0)
    assert fb is not None
    per_turn = 8192 if "position_message" in opts else 4096
    assert fb.position_rad == pytest.approx(counts * TWO_PI / per_turn / GEAR, abs=1e-12)


# ----------------------------------------------------------------------------- units, faults


@pytest.mark.parametrize(
    ("over", "expected"),
    [
        ({"command_unit": "rad/s"}, 10.0),
        ({"command_unit": "rpm"}, 10.0 * 60 / TWO_PI),
        ({"command_unit": "rev/s"}, 10.0 / TWO_PI),
        ({"command_unit": "deg/s"}, 10.0 * 180 / math.pi),
        ({"command_unit": "erpm", "pole_pairs": 7}, 70.0 * 60 / TWO_PI),
        ({"command_unit": "rpm", "command_side": "wheel"}, 60 / TWO_PI),
        ({"command_unit": "rpm", "command_scale": 10.0}, 100.0 * 60 / TWO_PI),
    ],
)
def test_command_units(over: dict[str, object], expected: float) -> None:
    m = motor(3, extra=over)
    units = UnitConversion.build(m, parse_options(m.options, "m"))
    assert units.wheel_to_command(1.0) == pytest.approx(expected, rel=1e-12)
    assert units.command_to_motor(expected) == pytest.approx(GEAR, rel=1e-12)


@SETTINGS
@given(
    st.sampled_from(sorted(VELOCITY_UNITS)),
    st.sampled_from(sorted(POSITION_UNITS)),
    st.sampled_from(["motor", "wheel"]),
    st.booleans(),
    st.floats(-1e4, 1e4),
)
def test_feedback_units_invert_the_device_side(
    vunit: str, punit: str, side: str, invert: bool, x: float
) -> None:
    m = motor(
        3,
        invert=invert,
        velocity_unit=vunit,
        position_unit=punit,
        feedback_side=side,
        pole_pairs=3,
        counts_per_rev=2048,
    )
    u = UnitConversion.build(m, parse_options(m.options, "m"))
    assert u.velocity_to_wheel(u.motor_to_velocity(x)) == pytest.approx(
        m.motor_to_wheel_rad_s(x), rel=1e-9, abs=1e-9
    )
    assert u.position_to_wheel(u.motor_to_position(x)) == pytest.approx(
        m.motor_to_wheel_rad_s(x), rel=1e-9, abs=1e-9
    )


class _Sig:
    name = "Fault_Code"
    choices: ClassVar[dict[int, str]] = {
        0: "NONE",
        1: "OVER_TEMPERATURE",
        2: "OVER_CURRENT",
        4: "ENCODER",
        7: "MELTDOWN",
    }


@pytest.mark.parametrize(
    ("raw", "flags", "detail"),
    [
        (0, DriveFault.NONE, ""),
        (1, DriveFault.OVER_TEMPERATURE, "Fault_Code=OVER_TEMPERATURE"),
        (6, DriveFault.OVER_CURRENT | DriveFault.ENCODER, "Fault_Code=OVER_CURRENT|ENCODER"),
        (7, DriveFault.OTHER, "Fault_Code=MELTDOWN"),
        (0x42, DriveFault.OVER_CURRENT | DriveFault.OTHER, "Fault_Code=OVER_CURRENT|0x40"),
        (-3, DriveFault.OTHER, "Fault_Code=-3"),
    ],
)
def test_fault_codes_map_onto_drive_faults(raw: int, flags: DriveFault, detail: str) -> None:
    assert describe_fault(_Sig(), raw) == (flags, detail)


# ----------------------------------------------------------------------------- configuration

KNOWN_MESSAGES = "WD_Angle, WD_Enable, WD_Feedback, WD_Velocity_Command"


@pytest.mark.parametrize(
    ("over", "message"),
    [
        ({"dbc": "/nonexistent/x.dbc"}, "motor.dbc: cannot read DBC file '/nonexistent/x.dbc'"),
        (
            {"command_message": "WD_Speed"},
            f"motor.command_message: no message 'WD_Speed' in {EXAMPLE_DBC}; "
            f"known messages: {KNOWN_MESSAGES}",
        ),
        (
            {"feedback_message": "Nope"},
            f"known messages: {KNOWN_MESSAGES}",
        ),
        (
            {"command_signal": "Speed"},
            "motor.command_signal: message 'WD_Velocity_Command' has no signal 'Speed'; "
            "known signals: Accel_Limit, Control_Mode, Target_Velocity",
        ),
        ({"velocity_signal": "Rpm"}, "motor.velocity_signal: message 'WD_Feedback' has no"),
        ({"position_signal": "Rotor_Angle"}, "motor.position_signal: message 'WD_Feedback'"),
        ({"enable_signal": "On"}, "motor.enable_signal: message 'WD_Enable' has no signal"),
        ({"fault_signal": "Err"}, "motor.fault_signal: message 'WD_Feedback' has no signal"),
        ({"enable_value": 5}, "motor.enable_value: expected a value between 0 and 1"),
        (
            {**ANGLE, "position_wrap_bits": 16},
            "motor.position_wrap_bits: expected 0 or 1..13 for signal 'Rotor_Angle', got 16",
        ),
        ({"command_unit": "kph"}, "motor.command_unit: expected one of 'rad/s', 'rpm'"),
        ({"position_unit": "turns"}, "motor.position_unit: expected one of"),
        ({"counts_per_rev": 0}, "motor.counts_per_rev: expected at least 1, got 0"),
        ({"command_scale": 0}, "motor.command_scale: expected a non-zero factor"),
        ({"node_id_in_frame": "or"}, "motor.node_id_in_frame: expected one of 'add', 'none'"),
        ({"enable_signal": ""}, "motor.enable_signal: required when enable_message is given"),
        (
            {"enable_message": "", "enable_signal": "Enable"},
            "motor.enable_message: required when enable_signal is given",
        ),
        ({"disable_value": 1}, "motor.disable_value: expected a value other than enable_value"),
        ({"fault_signal": "", "fault_message": "WD_Feedback"}, "motor.fault_signal: required"),
        (
            {"node_id_in_frame": "none", "node_id_shift": 5},
            "motor.node_id_shift: only used with node_id_in_frame 'add'",
        ),
        ({"colour": "red"}, "motor.colour: unknown key"),
        ({"command_signal": ""}, "motor.command_signal: expected a non-empty name"),
        ({"dbc": 3}, "motor.dbc: expected str, got 3"),
    ],
)
def test_config_errors_name_the_key(over: dict[str, object], message: str) -> None:
    with pytest.raises(ConfigError) as info:
        DbcDriver([motor(3, extra=over, validate=False)])
    assert message in str(info.value)
    assert str(info.value).startswith("wheels['left'].motor.")


def test_missing_required_key() -> None:
    opts = {k: v for k, v in EXAMPLE.items() if k != "position_signal"}
    with pytest.raises(ConfigError, match=r"motor\.position_signal: required key is missing"):
        DbcDriver([factories.motor("dbc", 3, validate=False, options=opts)])


def test_invalid_dbc_file(tmp_path: Path) -> None:
    bad = tmp_path / "bad.dbc"
    bad.write_text("this is not a DBC file\n")
    with pytest.raises(ConfigError, match=r"motor\.dbc: '.*bad\.dbc' is not a valid DBC file"):
        DbcDriver([motor(3, dbc=str(bad))])


def test_relative_dbc_path_uses_config_dir(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    DbcDriver([motor(3, dbc="example_controller.dbc", config_dir=str(CONFIG_DIR))])
    with pytest.raises(ConfigError, match=r"cannot read DBC file 'example_controller\.dbc'"):
        DbcDriver([motor(3, dbc="example_controller.dbc")])
    (tmp_path / "example_controller.dbc").write_bytes(
        (CONFIG_DIR / "example_controller.dbc").read_bytes()
    )
    DbcDriver([motor(3, dbc="example_controller.dbc")])  # cwd-relative


@pytest.mark.parametrize(
    ("motors", "message"),
    [
        ([motor(3), motor(3, "right")], "node 3 is already used by wheel 'left'"),
        (
            [motor(0x7FF)],
            "expected a frame ID of at most 0x7FF for message 'WD_Velocity_Command' (0x200) "
            "with node 2047, got 0x9FF",
        ),
        ([motor(0x800)], ".node_id: expected int 0..2047, got 2048"),
        # 0x180 + 0x83 = 0x203, the command ID of node 3.
        ([motor(3), motor(0x83, "right")], "frame ID 0x203 of node 131 ('right') message"),
        (
            [motor(3, node_id_in_frame="none"), motor(4, "right", node_id_in_frame="none")],
            'signal "Target_Velocity" of message "WD_Velocity_Command" (0x200) is configured '
            "for node 3 ('left') and node 4 ('right')",
        ),
        (
            [
                motor(
                    3,
                    feedback_message="WD_Velocity_Command",
                    velocity_signal="Accel_Limit",
                    position_message="WD_Feedback",
                    fault_signal="",
                )
            ],
            "frame ID 0x203 is configured both as a command",
        ),
    ],
)
def test_motors_that_collide_are_refused(motors: list[MotorConfig], message: str) -> None:
    with pytest.raises(ConfigError) as info:
        DbcDriver(motors)
    assert message in str(info.value)


def test_validate_options_fills_defaults_and_checks_rules_between_keys() -> None:
    out = DbcDriver.validate_options(EXAMPLE, "robot.yaml: wheels[0].motor")
    assert out["node_id_in_frame"] == "add" and out["liveness_s"] == 0.25
    assert out["position_message"] == ""  # resolved to feedback_message when parsed
    assert parse_options(out, "w").position_message == "WD_Feedback"
    with pytest.raises(ConfigError, match=r"robot\.yaml: wheels\[0\]\.motor\.fault_signal"):
        DbcDriver.validate_options(
            {**EXAMPLE, "fault_signal": "", "fault_message": "X"}, "robot.yaml: wheels[0].motor"
        )


# ----------------------------------------------------------------------------- shared messages

DUAL_DBC = str(DATA_DIR / "dual_controller.dbc")


def dual_motors() -> list[MotorConfig]:
    motors = []
    for node, side in ((1, "Left"), (2, "Right")):
        opts: dict[str, object] = {
            "dbc": DUAL_DBC,
            "node_id_in_frame": "none",
            "command_message": "Dual_Command",
            "command_signal": f"{side}_Speed",
            "feedback_message": "Dual_Status",
            "velocity_signal": f"{side}_Rpm",
            "position_signal": f"{side}_Ticks",
            "position_unit": "counts",
            "counts_per_rev": 100,
            "position_wrap_bits": 16,
            "enable_message": "Dual_Command",
            "enable_signal": "Drive_Enable",
        }
        motors.append(factories.motor("dbc", node, side.lower(), options=opts))
    return motors


def test_two_motors_share_one_command_and_one_extended_status_message() -> None:
    drv = DbcDriver(dual_motors())
    # Mode has no initial value and a range of 5..9, so it is sent as 5 (0 clamped).
    assert drv.enable(0.0) == [Frame(0x110, struct.pack("<hhBBxx", 0, 0, 1, 5))]
    frames = drv.command([rpm(100.0), rpm(-250.0)], 0.0)
    assert frames == [Frame(0x110, struct.pack("<hhBBxx", 100, -250, 1, 5))]
    assert drv.disable(0.0) == [Frame(0x110, struct.pack("<hhBBxx", 0, 0, 0, 5))]
    status = Frame(0x18FF0120, struct.pack("<hhHH", 10, -20, 65535, 3), is_extended_id=True)
    assert drv.codec.decode(status) == (DbcReading(1, 10.0, 65535), DbcReading(2, -20.0, 3))
    drv.on_frame(status.stamped(1.0))
    drv.on_frame(
        Frame(
            0x18FF0120,
            struct.pack("<hhHH", 10, -20, 4, 65533),
            is_extended_id=True,
            timestamp_s=1.01,
        )
    )
    left, right = drv.feedback(0), drv.feedback(1)
    assert left is not None and right is not None
    assert left.position_rad == pytest.approx(5 * TWO_PI / 100)  # 65535 -> 4 wraps: +5
    assert right.position_rad == pytest.approx(-6 * TWO_PI / 100)  # 3 -> 65533: -6
    # The same number as an 11-bit ID is another device's frame, not a malformed one.
    assert not drv.on_frame(status._replace(is_extended_id=False))


def test_codec_is_reusable_on_its_own() -> None:
    drv = DbcDriver([motor(3)])
    codec = DbcCodec(drv.bindings)
    assert codec.encode_command([150.0]) == [Frame(0x203, struct.pack("<iBHx", 1500, 2, 1000))]
    assert codec.encode_enable(True) == [Frame(0x183, b"\x01")]
    assert codec.decode(Frame(0x7FF, b"")) is None


def test_feedback_frames_carry_only_the_given_motors() -> None:
    codec = DbcDriver([motor(3), motor(4, "right")]).codec
    (frame,) = codec.encode_feedback([DbcReading(4, 1.5, 7, 0)])
    assert frame == Frame(0x284, struct.pack("<hiBb", 3, 7, 0, 0))


# ----------------------------------------------------------------------------- claims


def test_claims_are_the_bound_messages_with_their_dbc_names() -> None:
    drv = DbcDriver([motor(1, extra=ANGLE), motor(2, "right")])
    assert drv.claims() == (
        FrameClaim.exact(0x281, False, 0),  # WD_Feedback, feedback first, by ID
        FrameClaim.exact(0x282, False, 1),
        FrameClaim.exact(0x301, False, 0),  # WD_Angle
        FrameClaim.exact(0x201, False, 0, receive=False),  # WD_Velocity_Command
        FrameClaim.exact(0x181, False, 0, receive=False),  # WD_Enable
        FrameClaim.exact(0x202, False, 1, receive=False),
        FrameClaim.exact(0x182, False, 1, receive=False),
    )
    assert [str(f) for f in drv.receive_filters()] == ["281/7FF", "282/7FF", "301/7FF"]
    names = {c.can_id: drv.message_name(c.can_id, c.extended) for c in drv.claims()}
    assert names == {0x281: "WD_Feedback", 0x282: "WD_Feedback", 0x301: "WD_Angle",
                     0x201: "WD_Velocity_Command", 0x202: "WD_Velocity_Command",
                     0x181: "WD_Enable", 0x182: "WD_Enable"}
    assert drv.message_name(0x281, True) is None  # the other ID type
    assert drv.message_name(0x283, False) is None  # another node's


def test_a_shared_message_is_claimed_for_no_single_motor() -> None:
    drv = DbcDriver(dual_motors())
    assert drv.claims() == (
        FrameClaim.exact(0x18FF0120, True, None),
        FrameClaim.exact(0x110, False, None, receive=False),
    )
    assert drv.message_name(0x18FF0120, True) == "Dual_Status"
    assert drv.message_name(0x110, False) == "Dual_Command"


def test_every_frame_the_driver_sends_or_takes_is_claimed() -> None:
    m = motor(3, extra=ANGLE)
    drv, sim = DbcDriver([m]), DbcSimulator(m)
    sent = drv.enable(0.0) + drv.command([1.0], 0.0) + drv.disable(0.0)
    received = sim.tick(0.0)
    claims = drv.claims()
    for frame, receive in [*((f, False) for f in sent), *((f, True) for f in received)]:
        assert [c.receive for c in claims
                if c.matches(frame.arbitration_id, frame.is_extended_id)] == [receive], frame
        assert drv.on_frame(frame) is receive


def test_the_driver_never_imports_its_simulator() -> None:
    code = ("import sys, drivers.dbc; "
            "print(sorted(m for m in sys.modules if m.startswith(('drivers.dbc.sim', "
            "'gateway.sim'))))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, cwd=REPO)
    assert out.stdout.strip() == "[]"


def test_a_config_file_with_dbc_motors_loads_and_builds_the_driver(tmp_path: Path) -> None:
    from gateway.config import load_config

    protocol = "\n".join(f"  {k}: {v}" for k, v in EXAMPLE.items())
    (tmp_path / "robot.yaml").write_text(
        "drive: generic\nmotor_defaults:\n  driver: dbc\n  gear_ratio: 10.0\n  max_rpm: 3000\n"
        f"{protocol}\n"
        "wheels:\n"
        "  - {name: left, type: fixed, alpha: 1.5707963267948966, l: 0.2, beta: 0.0,\n"
        "     radius: 0.05, motor: {node_id: 1}}\n"
        "  - {name: right, type: fixed, alpha: -1.5707963267948966, l: 0.2,\n"
        "     beta: 3.141592653589793, radius: 0.05,\n"
        "     motor: {node_id: 2, controller_timeout_s: 0.3}}\n"
        "  - {name: castor, type: castor, alpha: 3.141592653589793, l: 0.25,\n"
        "     beta: -1.5707963267948966, radius: 0.025, d: 0.03}\n"
    )
    cfg = load_config(tmp_path / "robot.yaml")
    motors = [m for m in cfg.motors if m is not None]
    assert motors[1].options["controller_timeout_s"] == 0.3
    assert motors[0].options["command_scale"] == 1.0
    drv = DbcDriver(motors)
    assert [drv.opts[i].controller_timeout_s for i in (0, 1)] == [0.0, 0.3]
    drv.enable(0.0)
    assert [f.arbitration_id for f in drv.command([rpm(15.0), rpm(15.0)], 0.0)] == [0x201, 0x202]
    bad = (tmp_path / "robot.yaml").read_text().replace("velocity_unit: rpm", "velocity_unit: x")
    (tmp_path / "bad.yaml").write_text(bad)
    with pytest.raises(ConfigError, match=r"bad\.yaml: wheels\[0\]\.motor\.velocity_unit"):
        load_config(tmp_path / "bad.yaml")


def test_each_motor_keeps_its_own_liveness() -> None:
    drv = DbcDriver([motor(1), motor(2, "right", liveness_s=1.0)])
    assert drv.live.limits == [0.25, 1.0]
    assert drv.live.liveness_s == 1.0
