"""Steering actuators through the generic DBC driver: golden frames, refused angles, round
trips, and the absolute position across counter wraps.

Golden frames:

* ODrive through the official DBC (``tests/data/odrive-cansimple-0.5.6.dbc``, pinned):
  the ODrive CAN protocol documentation (docs.odriverobotics.com, can-protocol), worked example
  "Set_Input_Pos, node 0: pos 1.5" (bytes
  0-3 ``00 00 C0 3F``, float32 turns) and the Set_Controller_Mode layout (i32 Control_Mode @0,
  i32 Input_Mode @4; POSITION_CONTROL = 3 and PASSTHROUGH = 1 from the DBC's ``VAL_ 107``
  tables, i.e. ``ODriveEnums.h``).
* A position-commanded variant of the fictional example controller: ``WD_Position_Command``,
  defined in :mod:`tests.drivers.steering_dbc_helpers` and added to a copy of
  ``config/example_controller.dbc`` (whose messages other tests pin), packed by hand with
  ``struct`` and cross-checked with cantools.
"""

from __future__ import annotations

import functools
import math
import struct

import cantools
import pytest
from hypothesis import given
from hypothesis import strategies as st

from drivers.dbc import DbcDriver, DbcReading, Role
from drivers.dbc.sim import DbcSimulator
from gateway.core.errors import EncodeError
from gateway.core.types import Frame, MotorConfig
from tests.drivers import steering_dbc_helpers
from tests.drivers.dbc_helpers import ODRIVE_DBC, SETTINGS, TWO_PI
from tests.drivers.steering_dbc_helpers import (
    COUNT_STEER,
    GEAR,
    counts,
    drive_motor,
    odrive_steer,
    steer_motor,
)

# The shared fixtures (steering_dbc_helpers.py), bound here so that pytest finds them.
steer_dbc = steering_dbc_helpers.steer_dbc


# ----------------------------------------------------------------------------- golden frames


def test_driver_declares_steering() -> None:
    assert DbcDriver.STEERING is True


def test_odrive_steering_golden_frames() -> None:
    # gear 1, neutral at 0.5 turn: an angle of one turn is motor position 1.5 turns.
    m = odrive_steer(0, zero_rad=0.5 * TWO_PI, gear=1.0)
    drv = DbcDriver([m])
    mode = Frame(0x00B, struct.pack("<ii", 3, 1))
    hold = Frame(0x00C, struct.pack("<fhh", 0.5, 0, 0))
    arm, idle = Frame(0x007, struct.pack("<I4x", 8)), Frame(0x007, struct.pack("<I4x", 1))
    assert drv.enable(0.0) == [mode, hold, arm]
    (frame,) = drv.command([TWO_PI], 0.0)
    assert frame == Frame(0x00C, bytes.fromhex("0000C03F00000000"))  # spec: pos 1.5 = 00 00 C0 3F
    db = cantools.database.load_file(ODRIVE_DBC)
    assert isinstance(db, cantools.database.can.Database)
    assert frame.data == db.encode_message(
        "Axis0_Set_Input_Pos", {"Input_Pos": 1.5, "Vel_FF": 0.0, "Torque_FF": 0.0}
    )
    assert mode.data == db.encode_message(
        "Axis0_Set_Controller_Mode", {"Control_Mode": "POSITION_CONTROL", "Input_Mode": 1}
    )
    # Feedback 1.25 turns: absolute, so the angle is 0.75 turn from neutral (no first-sample
    # subtraction).  The disable holds where it stands, then goes IDLE.
    assert drv.on_frame(Frame(0x009, struct.pack("<ff", 1.25, -0.5), timestamp_s=1.0))
    fb = drv.feedback(0)
    assert fb is not None
    assert (fb.position_rad, fb.velocity_rad_s) == (0.75 * TWO_PI, -0.5 * TWO_PI)
    assert drv.disable(1.0) == [Frame(0x00C, struct.pack("<fhh", 1.25, 0, 0)), idle]
    assert drv.command([TWO_PI], 1.0) == [Frame(0x00C, struct.pack("<fhh", 1.25, 0, 0))]


def test_example_position_command_golden_bytes(steer_dbc: str) -> None:
    m = steer_motor(steer_dbc, node=5, zero_rad=1.0)
    drv = DbcDriver([m])
    # Target_Position i32 LE counts, Position_Mode u8 = 3, 3 bytes unused; ID 0x380 + 5.
    hold = Frame(0x385, struct.pack("<iB3x", counts(1.0), 3))
    assert drv.enable(0.0) == [hold, Frame(0x185, b"\x01")]
    (frame,) = drv.command([0.25], 0.0)
    target = counts(1.0 + 0.25 * GEAR)
    assert frame == Frame(0x385, struct.pack("<iB3x", target, 3))
    db = cantools.database.load_file(steer_dbc)
    assert isinstance(db, cantools.database.can.Database)
    assert frame.data == db.encode_message(
        "WD_Position_Command", {"Target_Position": target, "Position_Mode": 3}
    )


def test_inverted_actuator_turns_the_other_way(steer_dbc: str) -> None:
    drv = DbcDriver([steer_motor(steer_dbc, zero_rad=0.5, invert=True)])
    drv.enable(0.0)
    (frame,) = drv.command([0.25], 0.0)
    assert struct.unpack_from("<i", frame.data)[0] == counts(0.5 - 0.25 * GEAR)


def test_mixed_driver_sends_velocity_and_position_frames(steer_dbc: str) -> None:
    drive, steer = drive_motor(steer_dbc, 1), steer_motor(steer_dbc, 2, zero_rad=0.0)
    drv = DbcDriver([steer, drive])  # any order
    assert drv.enable(0.0) == [
        Frame(0x382, struct.pack("<iB3x", 0, 3)),
        Frame(0x201, struct.pack("<iBHx", 0, 2, 1000)),
        Frame(0x182, b"\x01"),
        Frame(0x181, b"\x01"),
    ]
    frames = drv.command([0.1, 2.0], 0.0)
    rpm_x10 = round(2.0 * 10.0 * 60.0 / TWO_PI * 10)
    assert frames == [
        Frame(0x382, struct.pack("<iB3x", counts(0.1 * GEAR), 3)),
        Frame(0x201, struct.pack("<iBHx", rpm_x10, 2, 1000)),
    ]
    kinds = {
        f.arbitration_id: [r.role for r in drv.codec.decode_request(f) or ()] for f in frames
    }
    assert kinds == {0x382: [Role.POSITION_COMMAND, Role.MODE], 0x201: [Role.COMMAND]}
    assert drv.preview_command([0.1, 2.0]) == frames


@pytest.mark.parametrize("angle", [math.nan, math.inf, -math.inf])
def test_non_finite_steering_angle_is_refused(steer_dbc: str, angle: float) -> None:
    drv = DbcDriver([drive_motor(steer_dbc, 1), steer_motor(steer_dbc, 2)])
    drv.enable(0.0)
    with pytest.raises(EncodeError) as info:
        drv.command([1.0, angle], 0.0)
    assert str(info.value) == (
        'Expected a finite steering angle for DBC node 2 ("front_left steering") in rad, '
        f"but got {angle!r}."
    )


def test_angle_beyond_the_signal_names_signal_and_range(steer_dbc: str) -> None:
    m = steer_motor(steer_dbc, position_command_message="WD_Small_Position_Command",
                    position_command_signal="Small_Target", position_mode_message="",
                    position_mode_values={}, travel=0.5)
    drv = DbcDriver([m])
    drv.enable(0.0)
    with pytest.raises(EncodeError, match=r'"Small_Target" of message "WD_Small_Position_Command"'
                       r' \(0x3A5\) for node 5 .* between -32768 and 32767 counts'):
        drv.command([5.0], 0.0)


# ----------------------------------------------------------------------------- round trips


@SETTINGS
@given(st.floats(-math.pi, math.pi), st.floats(-2.0, 2.0), st.booleans())
def test_position_command_reaches_the_simulator_within_half_a_count(
    steer_dbc: str, angle: float, zero: float, invert: bool
) -> None:
    m = steer_motor(steer_dbc, zero_rad=zero, invert=invert)
    drv, sim = DbcDriver([m]), DbcSimulator(m)
    for frame in drv.enable(0.0) + drv.command([angle], 0.0):
        sim.handle(frame, 0.0)
    assert sim.model.armed and sim.position_mode
    target = sim.model.target_position_rad
    assert target is not None
    assert abs(target - m.steer_to_motor_rad(angle)) <= TWO_PI / 4096 / 2 + 1e-12


@SETTINGS
@given(st.floats(-math.pi, math.pi), st.floats(-3.0, 3.0), st.sampled_from([0, 16, 32]))
def test_feedback_is_absolute_within_one_count(
    steer_dbc: str, angle: float, zero: float, bits: int
) -> None:
    m = steer_motor(steer_dbc, zero_rad=zero, position_wrap_bits=bits)
    drv, sim = DbcDriver([m]), DbcSimulator(m)
    sim.model.position_rad = m.steer_to_motor_rad(angle)
    for frame in sim.tick(0.0):
        drv.on_frame(frame)
    fb = drv.feedback(0)
    assert fb is not None
    assert abs(fb.position_rad - angle) <= COUNT_STEER + 1e-12


@functools.cache
def odrive_pair(zero: float) -> tuple[MotorConfig, DbcDriver, DbcSimulator]:
    """One ODrive steering driver and simulator per neutral (the DBC takes ~30 ms to load)."""
    m = odrive_steer(3, zero_rad=zero)
    return m, DbcDriver([m]), DbcSimulator(m)


@SETTINGS
@given(st.floats(-math.pi, math.pi), st.sampled_from([-10.0, -0.3, 0.0, 2.0, 7.5]))
def test_float32_odrive_round_trip(angle: float, zero: float) -> None:
    m, drv, sim = odrive_pair(zero)
    for frame in drv.enable(0.0) + drv.command([angle], 0.0):
        sim.handle(frame, 0.0)
    target = sim.model.target_position_rad
    assert target is not None
    motor = m.steer_to_motor_rad(angle)
    assert abs(target - motor) <= abs(motor) * 2**-23 + 1e-9
    sim.model.position_rad = motor
    for frame in sim.codec.encode_feedback([DbcReading(3, 0.0, sim.position_raw())]):
        drv.on_frame(frame)
    fb = drv.feedback(0)
    assert fb is not None
    assert abs(fb.position_rad - angle) <= (abs(motor) * 2**-23 + 1e-9) / GEAR


@pytest.mark.parametrize(
    ("zero", "raw", "angle_counts"),
    [
        (-3.0, (counts(-3.0) + 100) % 65536, 100),  # neutral just below the 16-bit wrap
        (-3.0, (counts(-3.0) - 20000) % 65536, -20000),
        (3.0, counts(3.0) + 20000, 20000),
        (0.0, 65535, -1),
    ],
)
def test_first_sample_of_a_wrapping_counter_is_taken_nearest_neutral(
    steer_dbc: str, zero: float, raw: int, angle_counts: int
) -> None:
    m = steer_motor(steer_dbc, zero_rad=zero, position_wrap_bits=16)
    drv = DbcDriver([m])
    drv.on_frame(Frame(0x285, struct.pack("<hiBb", 0, raw, 0, 0)))
    fb = drv.feedback(0)
    assert fb is not None
    expected = m.motor_to_steer_rad(counts(zero) * TWO_PI / 4096) + angle_counts * COUNT_STEER
    assert fb.position_rad == pytest.approx(expected, abs=1e-12)
