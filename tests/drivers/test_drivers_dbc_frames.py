"""Tests of the generic DBC driver's frames: the registry and the vendored files, golden frames,
encode errors and malformed frames.

Golden frames for ``config/example_controller.dbc`` are packed by hand with ``struct`` from the
layout in that file and cross-checked with cantools.  ODrive golden frames are the worked
examples of the ODrive CAN protocol documentation (docs.odriverobotics.com, can-protocol) ("Worked
examples" table), encoded here through
the official ODrive DBC (``tests/data/odrive-cansimple-0.5.6.dbc``, a pinned copy).
"""

from __future__ import annotations

import hashlib
import math
import struct

import cantools
import pytest

from drivers.dbc import (
    DbcDriver,
    DbcReading,
)
from drivers.dbc.sim import DbcSimulator
from gateway.core.errors import EncodeError
from gateway.core.types import DriveFault, DriveState, Frame
from gateway.drive.registry import get_driver_class
from tests import factories
from tests.drivers.dbc_helpers import (
    ANGLE,
    EXAMPLE_DBC,
    GEAR,
    ODRIVE_DBC,
    TWO_PI,
    motor,
    odrive_motor,
    odrive_options,
    rpm,
)

ODRIVE_SHA256 = "4db07a4cef0ee1a87cfbfc779cabd7db3176072c688a694e3b8842c2dd9bcb55"


def load_example_db() -> cantools.database.can.Database:
    db = cantools.database.load_file(EXAMPLE_DBC)
    assert isinstance(db, cantools.database.can.Database)
    return db


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
    # The codec's own check (binding refuses a max_rpm beyond the signal's range, so the
    # driver never sends such a value: test_drivers_dbc_bind.py).
    codec = DbcDriver([motor(3, gear=1.0, command_unit="rad/s")]).codec
    with pytest.raises(EncodeError) as info:
        codec.encode_command([20000.0])
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
    codec = DbcDriver([odrive_motor(3)]).codec  # (binding refuses a max_rpm beyond float32)
    with pytest.raises(EncodeError, match=r'"Input_Vel".*between -3.40282e\+38 and'):
        codec.encode_command([1e40])


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
