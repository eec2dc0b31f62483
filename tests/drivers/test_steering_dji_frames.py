"""Tests of DJI C620 / C610 steering actuators: the host-side position loop, the options, golden
frames and the position round trip.

The ESCs take only a torque current (the RoboMaster C620/C610 user guides' CAN protocol sections),
so a steering
actuator's frames are the same current slots as a wheel's: golden frames reuse the section's
worked examples (``0x200`` ``0F A0 ...`` = 4000 raw in ESC 1's slot, ``0x1FF`` ``C0 00 40 00 ...``
= -16384 / +16384 in ESC 5 / 6's, feedback ``0x201`` ``1F FF 05 DC FF 38 23 00`` = angle 8191,
1500 rpm), which were checked against DJI's ``CAN_receive.c`` (``CAN_cmd_chassis``,
``get_motor_measure``).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import pytest
from hypothesis import given
from hypothesis import strategies as st

from drivers.dji import (
    M3508_GEAR_RATIO,
    STEERING_OPTIONS,
    DjiDriver,
    DjiOptions,
    PositionLoop,
    power_up_position_rad,
)
from drivers.dji.codec import encode_feedback
from drivers.dji.sim import DjiSimulator
from gateway.core.errors import ConfigError, EncodeError
from gateway.core.types import Frame
from tests.drivers.steering_dji_helpers import ACK, COUNT_RAD, TWO_PI, drive, steer

if TYPE_CHECKING:
    from collections.abc import Callable
#: How messages name the block of :func:`steer`.
STEER = "motor 'fl steering'"


# ===================================================================== pure parts


def test_position_loop_law() -> None:
    loop = PositionLoop(kp_1_s=35.0, kd=0.7, max_speed_rad_s=100.0)
    assert loop.speed_target(1.0, 0.0, 0.0) == 35.0
    assert loop.speed_target(1.0, 0.0, 10.0) == pytest.approx(35.0 - 7.0)
    # following a turning target without error: the feed-forward alone, no damping against it
    assert loop.speed_target(0.0, 20.0, 20.0) == pytest.approx(20.0)
    assert loop.speed_target(10.0, 0.0, 0.0) == 100.0  # clipped to max_rpm
    assert loop.speed_target(-10.0, 0.0, 0.0) == -100.0
    assert loop.speed_target(math.nan, 0.0, 0.0) == 0.0
    assert loop.speed_target(0.0, math.inf, 0.0) == 0.0


def test_position_loop_defaults() -> None:
    assert {k: s.default for k, s in STEERING_OPTIONS.items()} == {
        "steer_kp": 35.0,
        "steer_kd": 0.7,
    }
    specs = DjiOptions.specs()
    assert {k: specs[k] for k in STEERING_OPTIONS} == dict(STEERING_OPTIONS)
    opts = DjiOptions.from_block({"steer_kp": 10, **ACK}, "w")
    assert (opts.steer_kp, opts.steer_kd) == (10.0, 0.7)


@pytest.mark.parametrize(
    ("count", "zero_rad", "turns"),
    [
        (0, 0.0, 0),
        (8191, 0.0, -1),  # just below the wrap, zero just above it: one turn less
        (1, TWO_PI - 0.01, 1),  # the other way round
        (4096, 0.0, 0),  # exactly half a turn away counts as above zero_rad
        (4097, 0.0, -1),
        (100, 10 * TWO_PI + 0.01, 10),  # zero_rad given with whole turns
        (8000, -3.0, -1),
    ],
)
def test_power_up_position_nearest_turn(count: int, zero_rad: float, turns: int) -> None:
    got = power_up_position_rad(count, zero_rad)
    assert got == pytest.approx(count * COUNT_RAD + turns * TWO_PI, abs=1e-12)
    assert -math.pi <= got - zero_rad <= math.pi


# ===================================================================== options


def test_steering_keys_only_where_given() -> None:
    assert DjiDriver.STEERING is True
    assert "steer_kp" not in DjiDriver.validate_options(ACK, "w")
    opts = DjiDriver.validate_options({"steer_kp": 20, "steer_kd": 1, **ACK}, "w")
    assert (opts["steer_kp"], opts["steer_kd"]) == (20.0, 1.0)
    drv = DjiDriver([steer(steer_kp=20.0), steer(node_id=6)])
    assert drv._axes[0].loop == PositionLoop(20.0, 0.7, 3000.0 * TWO_PI / 60.0)
    assert drv._axes[1].loop == PositionLoop(35.0, 0.7, 3000.0 * TWO_PI / 60.0)
    assert DjiDriver([drive(1)])._axes[0].loop is None


@pytest.mark.parametrize(
    ("build", "message"),
    [
        (
            lambda: DjiDriver([drive(1, steer_kp=10.0)]),
            "motor 'w1'.steer_kp: expected only in a steering actuator's block (steering:), "
            "got it in a drive motor's block",
        ),
        (lambda: steer(steer_kd=-1.0), f"{STEER}.steer_kd: expected at least 0, got -1.0"),
        (lambda: steer(steer_kp="stiff"), f"{STEER}.steer_kp: expected float, got 'stiff'"),
        (lambda: steer(steer_ki=1.0), f"{STEER}.steer_ki: unknown key"),
    ],
)
def test_steering_option_errors(build: Callable[[], object], message: str) -> None:
    with pytest.raises(ConfigError) as info:
        build()
    assert message in str(info.value)


def test_non_finite_angle_is_refused() -> None:
    drv = DjiDriver([drive(1), steer(5)])
    for bad in (math.nan, math.inf):
        with pytest.raises(EncodeError) as info:
            drv.command([0.0, bad], 0.0)
        assert str(info.value) == (
            f'Expected a finite steering angle for DJI node 5 ("fl steering") in rad, but got '
            f"{bad}."
        )
    with pytest.raises(EncodeError) as info:
        drv.preview_command([0.0])
    assert str(info.value) == (
        "Expected 2 setpoints for the DJI motors (w1, fl steering), but got 1."
    )


# ===================================================================== golden frames


def test_golden_preview_steering_slot() -> None:
    # steer_kp 20, gear 1, kp 0.1: 2.44140625 rad -> 48.828125 rad/s -> 4.8828125 A -> raw 4000,
    # ESC 1's slot of spec section 4 worked example 1 (0F A0).  6 rad (210 rad/s with the
    # default steer_kp 35) saturates at 20 A (ESC 5 / 6 of worked example 2: C0 00 / 40 00, the
    # inverted actuator on ESC 5).
    drv = DjiDriver(
        [
            steer(1, gear=1.0, zero_rad=0.3, steer_kp=20.0, max_rpm=9000.0),
            steer(5, gear=1.0, zero_rad=0.3, invert=True, max_rpm=9000.0),
            steer(6, gear=1.0, zero_rad=0.3, max_rpm=9000.0),
        ]
    )
    assert drv.preview_command([2.44140625, 6.0, 6.0]) == [
        Frame(0x200, bytes.fromhex("0FA0000000000000")),
        Frame(0x1FF, bytes.fromhex("C000400000000000")),
    ]


def test_golden_feedback_absolute() -> None:
    # spec section 4 worked example 3 on ESC 1: angle 8191, 1500 rotor rpm (78.11 rpm output).
    frame = Frame(0x201, bytes.fromhex("1FFF05DCFF382300"), timestamp_s=1.0)
    near_wrap = DjiDriver([steer(1, zero_rad=0.0)])
    assert near_wrap.on_frame(frame)
    fb = near_wrap.feedback(0)
    assert fb is not None
    # 8191 is one count below zero_rad 0, not a turn above: the nearest turn is taken.
    assert fb.position_rad == pytest.approx(-COUNT_RAD / M3508_GEAR_RATIO, abs=1e-15)
    assert fb.velocity_rad_s * 60.0 / TWO_PI == pytest.approx(78.11, abs=0.005)
    assert fb.timestamp_s == 1.0
    # not from the first sample, as a drive motor: absolute, from zero_rad (inverted here).
    mid = DjiDriver([steer(1, zero_rad=3.5, invert=True)])
    mid.on_frame(frame)
    fb = mid.feedback(0)
    assert fb is not None
    assert fb.position_rad == pytest.approx(-(8191 * COUNT_RAD - 3.5) / M3508_GEAR_RATIO)
    assert fb.velocity_rad_s < 0.0


# ===================================================================== position round trip


@given(
    st.floats(0.0, TWO_PI),
    st.floats(-0.999, 0.999),
    st.lists(st.floats(-0.49, 0.49), max_size=30),
    st.booleans(),
)
def test_angle_round_trip_within_one_count(
    zero_rad: float, start_turn: float, moves: list[float], invert: bool
) -> None:
    """Sim rotor angle -> 13-bit feedback -> driver angle, within one count, over many turns.

    Powered up anywhere within half a rotor turn of zero_rad; then moves of less than half a
    turn per sample (the unwrapping's limit) in any direction.
    """
    m = steer(1, zero_rad=zero_rad, invert=invert)
    sim = DjiSimulator(m, initial_position_rad=zero_rad + start_turn * math.pi)
    drv = DjiDriver([m])
    t = 0.0
    for move in [0.0, *moves]:
        sim.physics.position_rad += move * TWO_PI
        t += 0.001
        assert drv.on_frame(encode_feedback(sim.measure()).stamped(t))
        fb = drv.feedback(0)
        assert fb is not None
        assert abs(fb.position_rad - sim.steer_rad) <= COUNT_RAD / m.gear_ratio + 1e-12


def test_power_up_beyond_half_a_turn_is_off_by_a_turn() -> None:
    """The documented limit: the ESC's angle is absolute only within one rotor turn."""
    m = steer(1, zero_rad=1.0)
    sim = DjiSimulator(m, initial_position_rad=1.0 + 0.6 * TWO_PI)
    drv = DjiDriver([m])
    drv.on_frame(encode_feedback(sim.measure()))
    fb = drv.feedback(0)
    assert fb is not None
    assert fb.position_rad - sim.steer_rad == pytest.approx(-TWO_PI / m.gear_ratio, abs=1e-3)


def test_sim_starts_at_zero_rad_without_position_mode() -> None:
    m = steer(2, zero_rad=2.5)
    sim = DjiSimulator(m)
    assert sim.physics.position_rad == 2.5
    assert sim.physics.target_position_rad is None  # current-driven: no position mode on the ESC
    assert sim.steer_rad == 0.0
    assert sim.measure().angle_count == math.floor(2.5 / COUNT_RAD)
    assert DjiSimulator(drive(1)).physics.position_rad == 0.0
