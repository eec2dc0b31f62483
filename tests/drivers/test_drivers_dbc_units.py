"""Tests of the generic DBC driver's codec by property: round trips, unwrapping of positions,
units and fault codes."""

from __future__ import annotations

import dataclasses
import functools
import math
import struct
from typing import ClassVar

import pytest
from hypothesis import given
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
from gateway.core.types import DriveFault, Frame
from tests.drivers.dbc_helpers import (
    ANGLE,
    COUNT_RAD,
    GEAR,
    SETTINGS,
    TWO_PI,
    motor,
    odrive_motor,
    rpm,
)


@functools.cache
def odrive_codec() -> DbcCodec:
    """One codec for ODrive node 3 (the ODrive DBC takes about 30 ms to load)."""
    return DbcDriver([odrive_motor(3)]).codec


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
