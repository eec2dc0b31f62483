"""Tests of DJI C620 / C610 steering actuators: the host-side position cascade.

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
import yaml
from hypothesis import given
from hypothesis import strategies as st

from drivers.dji import (
    M2006_GEAR_RATIO,
    M3508_GEAR_RATIO,
    STEERING_OPTIONS,
    DjiDriver,
    DjiFeedback,
    DjiOptions,
    PositionLoop,
    power_up_position_rad,
)
from drivers.dji.codec import COUNTS_PER_REV, RAD_S_PER_RPM, decode_command, encode_feedback
from drivers.dji.sim import DjiSimulator
from gateway.bus.can_bus import send_frames
from gateway.config import parse_config
from gateway.core.errors import ConfigError, EncodeError
from gateway.core.types import DriveFault, DriveState, Frame, MotorConfig
from gateway.drive.driveset import DriveSet
from gateway.sim.device import SimFault
from tests import factories
from tests.conftest import CONFIG_DIR
from tests.drivers.test_drivers_dji import Rig, _rig, currents_in

if TYPE_CHECKING:
    from collections.abc import Callable, Sequence

TWO_PI = 2.0 * math.pi
COUNT_RAD = TWO_PI / COUNTS_PER_REV
#: Every DJI motor block acknowledges that the ESC has no stop of its own.
ACK = {"no_controller_stop": "acknowledged"}
#: How messages name the block of :func:`steer`.
STEER = "motor 'fl steering'"


def steer(
    node_id: int = 5,
    esc: str = "c620",
    gear: float | None = None,
    zero_rad: float = 1.0,
    invert: bool = False,
    max_rpm: float = 3000.0,
    **options: object,
) -> MotorConfig:
    """A DJI steering actuator ``"fl steering"`` of the factory
    (:func:`tests.factories.steer_motor`), the gearbox of the ESC's motor unless ``gear``."""
    ratio = gear if gear is not None else (M3508_GEAR_RATIO if esc == "c620" else M2006_GEAR_RATIO)
    return factories.steer_motor(
        "dji", node_id, ("front_left",), wheel="fl steering", zero_rad=zero_rad,
        gear_ratio=ratio, invert=invert, max_rpm=max_rpm, options={"esc": esc, **ACK, **options},
    )


def drive(node_id: int = 1, **options: object) -> MotorConfig:
    """A DJI drive motor ``w<node>`` of the factory (:func:`tests.factories.motor`)."""
    return factories.motor("dji", node_id, f"w{node_id}", gear_ratio=M3508_GEAR_RATIO,
                           max_rpm=9000.0, options={"esc": "c620", **ACK, **options})


def fb_frame(esc_id: int, angle: int, rpm: int = 0, temp: int = 35, t: float = 0.0) -> Frame:
    return encode_feedback(DjiFeedback(esc_id, angle, rpm, 0, temp)).stamped(t)


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


# ===================================================================== mixed driver


def test_mixed_driver_slots_and_loops() -> None:
    """Drive motors (speed loop) and steering actuators (position cascade) in one instance,
    in any order: every motor's current goes in its own ESC slot of 0x200 / 0x1FF."""
    motors = [steer(2, zero_rad=1.0), drive(1), drive(6), steer(5, zero_rad=0.5, invert=True)]
    drv = DjiDriver(motors)
    t = 0.0
    for esc, count in ((2, round(1.0 / COUNT_RAD)), (1, 0), (6, 0), (5, round(0.5 / COUNT_RAD))):
        drv.on_frame(fb_frame(esc, count, t=t))
    drv.enable(t)
    frames = drv.command([0.0, 0.0, 0.0, 0.0], 0.001)
    assert [f.arbitration_id for f in frames] == [0x200, 0x1FF]
    assert currents_in(frames) == dict.fromkeys(range(1, 9), 0)  # all where they should be
    frames = drv.command([0.2, 5.0, -5.0, 0.2], 0.002)
    cur = currents_in(frames)
    assert cur[1] > 0 > cur[6]  # wheels: speed loop, sign of the speed
    assert cur[2] > 0 > cur[5]  # steering: position error, inverted actuator negative
    # the steering current is the cascade's: feed-forward 0.2 * gear / 1 ms clipped to max_rpm
    lim = 3000.0 * TWO_PI / 60.0
    loop = PositionLoop(35.0, 0.7, lim)
    error = 0.2 * M3508_GEAR_RATIO + (1.0 - round(1.0 / COUNT_RAD) * COUNT_RAD)
    speed = loop.speed_target(error, 0.2 * M3508_GEAR_RATIO / 0.001, 0.0)
    assert speed == lim
    expected_a = min(0.1 * speed + 1.0 * speed * 0.001, 20.0)
    assert drv.currents_a[0] == pytest.approx(expected_a)
    assert all(f.arbitration_id != 0x700 for f in frames)
    # disable: zero current for every motor, steering included
    assert currents_in(drv.disable(0.003)) == dict.fromkeys(range(1, 9), 0)
    assert all(drv.state(i, 0.003) is DriveState.DISABLED for i in range(4))


def test_feed_forward_only_between_commands_after_enable() -> None:
    m = steer(1, gear=1.0, zero_rad=0.0, steer_kd=0.0, max_rpm=9000.0, ki=0.0)
    drv = DjiDriver([m])
    drv.on_frame(fb_frame(1, 0, t=0.0))
    drv.enable(0.0)
    drv.command([0.5], 0.0)  # first call: no feed-forward, only P
    assert drv.currents_a[0] == pytest.approx(0.1 * 35.0 * 0.5)
    drv.on_frame(fb_frame(1, 0, t=0.01))
    drv.command([0.6], 0.01)  # 0.1 rad in 10 ms: 10 rad/s of feed-forward
    assert drv.currents_a[0] == pytest.approx(0.1 * (10.0 + 35.0 * 0.6))
    drv.enable(0.01)  # re-arming forgets the last target
    drv.command([0.6], 0.02)
    assert drv.currents_a[0] == pytest.approx(0.1 * 35.0 * 0.6)


# ===================================================================== on the virtual bus


@pytest.mark.parametrize(
    ("esc", "period_ms"), [("c620", 1), ("c620", 5), ("c610", 1), ("c610", 5), ("c620", 20)]
)
def test_step_settles_in_about_0_3_s(channel: str, esc: str, period_ms: int) -> None:
    """A 0.5 rad step of the wheel's plane with the default gains, at 1 kHz, 200 Hz and 50 Hz:
    within 2 % (0.01 rad) from 0.33 s on, overshoot under 2 %."""
    motors = [drive(1), steer(5, esc=esc, zero_rad=4.0)]
    sims = [DjiSimulator(m) for m in motors]
    one_count = COUNT_RAD / motors[1].gear_ratio

    def check(rig: Rig) -> None:
        rig.drv.enable(rig.t)
        held = rig.run(0.1, [3.0, 0.0], period_ms, probe=sims[1])
        assert max(abs(a) for a in held) < 0.002  # holds neutral while the wheel turns
        trace = rig.run(0.6, [3.0, 0.5], period_ms, probe=sims[1])
        assert max(trace) < 0.5 * 1.02
        late = trace[330:]
        assert max(abs(a - 0.5) for a in late) < 0.01, f"settled at {_settle_s(trace):.3f} s"
        fb = rig.drv.feedback(1)
        assert fb is not None
        assert abs(fb.position_rad - sims[1].steer_rad) < one_count + 1e-3
        assert sims[1].steer_rad == pytest.approx(0.5, abs=2e-3)
        assert sims[0].wheel_velocity_rad_s == pytest.approx(3.0, rel=0.02)

    _rig(channel, motors, sims, check)


def _settle_s(trace: Sequence[float]) -> float:
    last_out = max((k for k, a in enumerate(trace) if abs(a - 0.5) >= 0.01), default=-1)
    return (last_out + 1) * 0.001


def test_fault_zero_current_and_recover(channel: str) -> None:
    """Over-temperature on the steering ESC: FAULT, zero current in its slot (the wheel on the
    same frame keeps its own), recovery after cooling and an enable, back to the angle."""
    motors = [drive(1), steer(2, zero_rad=0.2)]
    sims = [DjiSimulator(m) for m in motors]

    def check(rig: Rig) -> None:
        rig.drv.enable(rig.t)
        rig.run(0.5, [3.0, -0.4])
        assert sims[1].steer_rad == pytest.approx(-0.4, abs=2e-3)
        sims[1].inject(SimFault.FAULT)
        rig.run(0.05, [3.0, -0.4])
        status = rig.drv.status(rig.t)[1]
        assert status.state is DriveState.FAULT
        assert status.faults == DriveFault.OVER_TEMPERATURE
        assert sims[1].command_raw == 0 and rig.drv.currents_a[1] == 0.0
        assert rig.drv.state(0, rig.t) is DriveState.ENABLED and sims[0].command_raw != 0
        sims[1].clear(SimFault.FAULT)
        rig.run(0.05, [3.0, 0.3])
        assert rig.drv.state(1, rig.t) is DriveState.DISABLED  # cool, but not re-armed
        assert sims[1].command_raw == 0
        rig.drv.enable(rig.t)
        rig.run(0.6, [3.0, 0.3])
        assert rig.drv.state(1, rig.t) is DriveState.ENABLED
        fb = rig.drv.feedback(1)
        assert fb is not None
        assert sims[1].steer_rad == pytest.approx(0.3, abs=2e-3)
        assert fb.position_rad == pytest.approx(sims[1].steer_rad, abs=1e-3)
        send_frames(rig.gw, rig.drv.disable(rig.t))
        rig.run(0.01, [3.0, 0.3])
        assert [s.command_raw for s in sims] == [0, 0]

    _rig(channel, motors, sims, check)


def test_follows_a_turning_target_without_lag(channel: str) -> None:
    """A steady steering rate: the feed-forward makes the angle follow closely."""
    motors = [steer(3, zero_rad=0.0)]
    sims = [DjiSimulator(m) for m in motors]

    def check(rig: Rig) -> None:
        rig.drv.enable(rig.t)
        rig.run(0.05, [0.0])
        angle = 0.0
        for _ in range(80):  # 1 rad/s for 0.4 s, commanded at 200 Hz
            angle += 0.005
            rig.run(0.005, [angle], period_ms=5)
        assert sims[0].steer_rad == pytest.approx(angle, abs=0.01)

    _rig(channel, motors, sims, check)


# ===================================================================== through the config


def test_swerve_config_with_dji_steering() -> None:
    """The swerve preset with C610 / M2006 steering actuators: the ``steering:`` block takes
    the DJI protocol keys, and the gains reach the driver that also serves no drive motor."""
    doc = yaml.safe_load((CONFIG_DIR / "swerve.yaml").read_text())
    doc["steering_defaults"] = {
        "driver": "dji",
        "esc": "c610",
        "gear_ratio": 72.0,  # the M2006's 36:1 and a 2:1 belt to the module
        "max_rpm": 15000,
        "zero_rad": 1.5,
        **ACK,
    }
    doc["steering"] = {
        "front_left": {"node_id": 1, "steer_kp": 30},
        "front_right": {"node_id": 2},
        "rear_left": {"node_id": 3},
        "rear_right": {"node_id": 4, "invert": True},
    }
    cfg = parse_config(doc, "robot.yaml")
    assert "steer_kd" not in cfg.steering[0].options  # defaults are the driver's
    drives = DriveSet(cfg)
    (dji,) = [drv for drv, _ in drives.groups if isinstance(drv, DjiDriver)]
    assert [m.wheel for m in dji.motors][:1] == ["front_left steering"]
    lim = 15000.0 * RAD_S_PER_RPM
    assert dji._axes[0].loop == PositionLoop(30.0, 0.7, lim)
    assert dji._axes[3].loop == PositionLoop(35.0, 0.7, lim)
    frames = drives.preview([0.0] * 4, [0.0, 0.01, 0.0, 0.01])
    (current,) = [f for f in frames if f.arbitration_id == 0x200]
    cur = decode_command(current)
    assert cur is not None
    assert cur[1] == cur[3] == 0 and cur[2] > 0 > cur[4]  # the inverted module the other way
    doc["motors"]["front_left"] = {"node_id": 1, "steer_kd": 1.0}
    with pytest.raises(ConfigError, match="steer_kd: unknown key"):
        parse_config(doc, "robot.yaml")  # an ODrive drive motor does not take it
