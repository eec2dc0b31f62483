"""``wheelgate spin``'s pure part: the plan, the measurement, the operator's answer, the verdict
(golden advice texts and a property: following the advice gives the true configuration)."""

from __future__ import annotations

import dataclasses
import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from gateway.apps.spin.judge import (
    EXIT_FIX,
    Check,
    Measured,
    Sample,
    exit_status,
    judge,
    measure,
    parse_seen,
)
from gateway.apps.spin.plan import (
    NoRoomError,
    NoSpinError,
    SpinPlan,
    SpinUsageError,
    describe,
    drive_plan,
    someone_else,
    steer_plan,
)
from gateway.config import load_config
from gateway.core.can_ids import CanIds
from gateway.core.types import Frame, MotorConfig
from tests.conftest import CONFIG_DIR
from tests.factories import motor, steer_motor

RIGHT = motor("odrive", 2, "front_right")
STEER = steer_motor("odrive", 3, ("front_left",), steer_range_rad=(-0.5, 0.5))


def plan_of(m: MotorConfig = RIGHT, speed: float = 1.0) -> SpinPlan:
    return drive_plan(m, speed, 3.0, 10.0, math.inf, None)


def at(plan: SpinPlan, ratio: float) -> Measured:
    """What the encoder measures when the motor turns ``ratio`` times the command."""
    return Measured(plan.commanded * ratio, ratio, plan.travel_rad * ratio)


# ----------------------------------------------------------------------------- the plan


def test_a_drive_motor_ramps_holds_and_ramps_down() -> None:
    plan = drive_plan(RIGHT, -2.0, 3.0, 10.0, 4.0, None)  # 0.5 s ramps at 4 rad/s^2
    assert [plan.setpoint(t) for t in (-1.0, 0.25, 0.5, 1.5, 2.75, 3.0)] == [
        0.0, -1.0, -2.0, -2.0, -1.0, 0.0]
    assert plan.window == (0.8, 2.5)
    assert plan.travel_rad == pytest.approx(-5.0)


def test_speeds_a_controller_does_not_control_are_commanded_as_zero() -> None:
    plan = drive_plan(RIGHT, None, 3.0, 10.0, 10.0, (0.0, 2.0))  # the default: above the band
    assert plan.speed_rad_s == 2.5 and plan.floor_rad_s == 2.0
    assert plan.setpoint(0.1) == 0.0 and plan.setpoint(0.2) == 2.0  # ramp: 2.5 rad/s in 0.25 s


def test_half_the_limit_is_the_fastest_spin() -> None:
    assert drive_plan(RIGHT, -5.0, 3.0, 10.0, 9.0, None).speed_rad_s == -5.0
    assert steer_plan(STEER, 0.5, 3.0, 1.0).speed_rad_s == 0.5
    with pytest.raises(SpinUsageError, match=r"expected 0.1 to 0.5 rad/s of steering angle"):
        steer_plan(STEER, 0.6, 3.0, 1.0)


@pytest.mark.parametrize(("speed", "duration", "band", "option", "text"), [
    # At most half the limit (10 rad/s), as the help says: 5.5 is refused, 5 (below) is not.
    (5.5, 3.0, None, "--speed", "front_right: expected 0.1 to 5 rad/s at the wheel either way "
                                "(a spin goes at most half the limit, 10, of max_rpm"),
    (-5.5, 3.0, None, "--speed", "got -5.5"),
    (-0.05, 3.0, None, "--speed", "got -0.05"),
    (1.0, 3.0, (0.0, 2.0), "--speed", "at least 2 rad/s"),
    (1.0, 0.9, None, "--duration", "expected 1 to 30 s, got 0.9"),
    (1.0, 31.0, None, "--duration", "got 31"),
    (4.5, 1.0, None, "--duration",
     "takes 0.5 s each way to ramp up and down, got 1 s; at least 1.7 s"),
])
def test_a_plan_out_of_bounds_names_the_option(speed: float, duration: float,
                                               band: tuple[float, float] | None, option: str,
                                               text: str) -> None:
    with pytest.raises(SpinUsageError) as err:
        drive_plan(RIGHT, speed, duration, 10.0, 9.0, band)
    assert err.value.option == option and text in str(err.value)


@pytest.mark.parametrize(("origin", "amplitude"), [
    (0.0, math.radians(15)), (0.4, -math.radians(15)), (-0.4, math.radians(15)),
])
def test_a_sweep_turns_towards_the_side_with_room(origin: float, amplitude: float) -> None:
    plan = steer_plan(STEER, 0.5, 3.0, 1.0).from_origin(origin)
    assert plan.amplitude_rad == pytest.approx(amplitude)
    assert plan.setpoint(1.5) == pytest.approx(origin + amplitude)
    assert plan.setpoint(3.0) == origin and plan.ramp_s == pytest.approx(abs(amplitude) / 0.5)


def test_a_short_travel_is_swept_in_part_or_refused() -> None:
    narrow = dataclasses.replace(STEER, steer_range_rad=(-0.1, 0.1))
    plan = steer_plan(narrow, 0.3, 3.0, 1.0)
    assert plan.amplitude_rad == pytest.approx(0.08)  # announced as it will be, from the middle
    assert plan.from_origin(0.0).amplitude_rad == pytest.approx(0.08)
    assert plan.from_origin(0.09).amplitude_rad == pytest.approx(-0.08)


def test_no_room_to_sweep_is_refused_before_anything_is_sent() -> None:
    # The travel from the neutral angle is known from the configuration: refused when the plan
    # is made (before arming), naming the key and the travel needed.
    stuck = dataclasses.replace(STEER, steer_range_rad=(-0.03, 0.03))
    with pytest.raises(NoSpinError) as err:
        steer_plan(stuck, 0.3, 3.0, 1.0, "geometry max_steer 0.03 rad")
    assert str(err.value) == (
        "front_left steering: no room to sweep: expected 2.5 deg (0.0436 rad) of travel on one "
        "side of its neutral angle, to sweep 2 deg clear of the end stop, but its travel is "
        "-1.72..+1.72 deg, from geometry max_steer 0.03 rad; widen it if its steering turns "
        "further")


def test_no_room_where_the_wheels_stand_is_an_error_after_enabling() -> None:
    # Where the wheels stand is known once enabled: a runtime error (the runner then sends
    # the stop), not a usage error.
    lopsided = dataclasses.replace(STEER, steer_range_rad=(-0.01, 0.05))
    plan = steer_plan(lopsided, 0.3, 3.0, 1.0)
    assert plan.amplitude_rad == pytest.approx(0.04)
    with pytest.raises(NoRoomError, match=r"its wheels stand at \+1.1 deg within its travel "
                                          r"-0.6..\+2.9 deg: expected 2.5 deg of room on one "
                                          r"side") as err:
        plan.from_origin(0.02)
    assert not isinstance(err.value, SpinUsageError)


def test_no_speed_at_all_when_the_dead_band_reaches_past_half_the_limit() -> None:
    # A TurtleBot-like wheel on a VESC: min_erpm 900 at 7 pole pairs, gear_ratio 1 is 13.46
    # rad/s, above max_rpm 61 (6.39 rad/s): whatever --speed, no spin; said before arming.
    vesc = motor("vesc", 1, "left", max_rpm=61.0, min_erpm=900.0, pole_pairs=7)
    limit, band = vesc.max_wheel_rad_s, (0.0, 900.0 / 7 * 2 * math.pi / 60)
    for speed in (None, 3.0, 13.5):
        with pytest.raises(NoSpinError) as err:
            drive_plan(vesc, speed, 3.0, limit, 40.0, band)
        assert str(err.value) == (
            "left: no spin speed is possible: its vesc controller does not speed-control wheel "
            "speeds below 13.5 rad/s (min_erpm 900 through pole_pairs 7 and gear_ratio 1), and "
            "a spin goes at most 3.19 rad/s at the wheel (half the limit, 6.39, of max_rpm 61 "
            "through gear_ratio 1 and the robot's wheel speeds); lower min_erpm (on the "
            "controller, then in the configuration), or check pole_pairs, gear_ratio and "
            "max_rpm (the motor's own)")
    # The band just below half the limit leaves a speed.
    assert drive_plan(vesc, None, 3.0, limit, 40.0, (0.0, 3.0)).speed_rad_s == pytest.approx(
        0.5 * limit)
    with pytest.raises(NoSpinError, match=r"a spin goes at least 0\.1 rad/s"):
        drive_plan(vesc, None, 3.0, 0.15, 40.0, None)


def test_the_operator_is_told_which_way_the_robot_would_roll() -> None:
    cfg = load_config(CONFIG_DIR / "turtlebot3_burger.yaml")
    right = cfg.wheels[1]
    assert describe(plan_of(speed=1.0), right).endswith("rolling the robot forward")
    assert describe(plan_of(speed=-1.0), right).endswith("rolling the robot backward")
    sweep = steer_plan(STEER, 0.3, 3.0, 1.0).from_origin(0.4)
    assert describe(sweep, None).startswith(
        "its wheels turn right (clockwise seen from above) by up to 15 deg")


def test_someone_else_on_the_bus() -> None:
    ids = CanIds()
    commands = frozenset({(0x04D, False)})
    assert someone_else([Frame(0x04D, bytes(8))], commands, ids, RIGHT) == (
        "heard 04D#0000000000000000 (a command to front_right's odrive node 2 from another "
        "sender) on the bus")
    assert "WG_Odom_Pose of a running wheelgate" in str(
        someone_else([Frame(0x101, bytes(8))], commands, ids, RIGHT))
    assert someone_else([Frame(0x049, bytes(8)), Frame(0x101, bytes(8), True)], commands, ids,
                        RIGHT) is None


# ----------------------------------------------------------------------------- the measurement


def test_a_speed_is_measured_from_the_positions_over_the_steady_part() -> None:
    plan = plan_of()  # window 0.5 .. 2.8 s
    samples = [Sample(t / 100, 0.9 * t / 100 + (5.0 if t > 290 else 0.0), 0.0)
               for t in range(0, 320, 5)]
    got = measure(plan, samples)
    assert got is not None and got.value == pytest.approx(0.9) and got.ratio == pytest.approx(0.9)
    assert got.travel_rad == pytest.approx(0.9 * 3.15 + 5.0)
    assert measure(plan, samples, until_s=0.6) is None  # stopped before 0.2 s were measured
    assert measure(plan, samples[:10]) is None


def test_a_sweep_is_measured_as_its_held_offset() -> None:
    plan = steer_plan(STEER, 0.5, 3.0, 1.0).from_origin(0.1)
    half = [Sample(t / 100, 0.1 + 0.5 * (plan.setpoint(t / 100) - 0.1), 0.0) for t in range(300)]
    overshoot = Sample(plan.ramp_s, 0.1 + 0.7 * plan.amplitude_rad, 0.0)  # before the hold
    got = measure(plan, sorted([*half, overshoot], key=lambda s: s.t_s))
    assert got is not None and got.ratio == pytest.approx(0.5)
    assert got.travel_rad == pytest.approx(0.7 * plan.amplitude_rad)  # the largest offset


@pytest.mark.parametrize(("text", "seen"), [
    ("", 1.0), (" Y ", 1.0), ("f", 1.0), ("r", -1.0), ("b", -1.0), ("n", 0.0), ("0", 0.0),
    ("s", None), ("?", None), ("0.25", 0.5), ("-1", -2.0), ("10x", 10.0), ("-0.1X", -0.1),
])
def test_the_operator_answers(text: str, seen: float | None) -> None:
    assert parse_seen(text, 0.5) == seen


@pytest.mark.parametrize("text", ["forward", "x", "1/2", "nan", "inf", "1e999x"])
def test_an_answer_that_is_none_of_those_says_what_is_expected(text: str) -> None:
    with pytest.raises(ValueError, match=r"expected Enter \(as described\), r \(the other way\)"):
        parse_seen(text, 0.5)


# ----------------------------------------------------------------------------- the verdict


@pytest.mark.parametrize(("ratio", "seen", "checks"), [
    (1.0, 1.0, []),
    (1.1, 0.8, []),
    (1.0, None, []),
    (0.05, None, [Check.NO_MOTION]),
    (-1.0, None, [Check.CONTROLLER_REVERSED]),
    (0.5, 1.0, [Check.CONTROLLER_SCALE]),
    (1.0, -1.0, [Check.INVERT]),
    (1.0, 10.0, [Check.GEAR_RATIO]),
    (1.0, -0.1 - 1e-9, [Check.INVERT, Check.GEAR_RATIO]),
    (1.0, 0.0, [Check.NOT_SEEN]),
    (1.0, 0.05, [Check.GEAR_RATIO]),  # a little is not nothing: far too small a gear_ratio
    (0.0, -1.0, [Check.NO_MOTION]),  # no answer is judged when the motor did not turn
])
def test_the_rules(ratio: float, seen: float | None, checks: list[Check]) -> None:
    plan = plan_of()
    got = judge(plan, at(plan, ratio), seen)
    assert [f.check for f in got.findings] == checks
    assert got.ok is (not checks) and got.judged


def test_the_advice_in_words() -> None:
    plan = plan_of()
    m = at(plan, 1.0)
    assert judge(plan, m, -1.0).lines() == [
        "front_right: seen -1.00 rad/s for +1.00 rad/s: set invert: true on front_right"]
    inverted = plan_of(dataclasses.replace(RIGHT, invert=True, gear_ratio=10.0))
    assert judge(inverted, at(inverted, 1.0), -1.0).lines() == [
        "front_right: seen -1.00 rad/s for +1.00 rad/s: set invert: false on front_right"]
    assert judge(inverted, at(inverted, 1.0), 0.1).lines() == [
        "front_right: seen +0.10 rad/s for +1.00 rad/s (0.1x the command): check gear_ratio on "
        "front_right: 10 would be about 100"]
    assert judge(plan, m, 1.0).lines() == [
        "front_right: agrees: measured +1.00 rad/s for +1.00 rad/s, and the wheel did as "
        "described"]
    unseen = judge(plan, m, None)
    assert unseen.ok and unseen.notes[0].startswith("invert and gear_ratio were not checked")
    scale = judge(plan, at(plan, 2.0), None).lines()[0]
    assert scale.startswith("front_right: measured +2.00 rad/s for +1.00 rad/s (2x): the "
                            "odrive controller of front_right (node 2) does not follow")
    assert scale.endswith("not the motor: gear_ratio 1 would be 0.5")
    sweep = steer_plan(STEER, 0.5, 3.0, 1.0).from_origin(0.0)
    assert judge(sweep, at(sweep, 1.0), -1.0).lines() == [
        "front_left steering: seen -15.0 deg for +15.0 deg: set invert: true on front_left "
        "steering"]


def test_what_cannot_be_judged() -> None:
    plan = plan_of()
    assert [f.check for f in judge(plan, None, None).findings] == [Check.NO_FEEDBACK]
    faulted = judge(plan, None, None, fault="fault: 'MOTOR_ERROR'")
    assert faulted.lines() == ["front_right: the odrive controller of front_right (node 2) "
                               "stopped during the spin: fault: 'MOTOR_ERROR'; fix that first"]
    stopped = judge(plan, None, None, stopped_by="a key")
    assert not stopped.judged and stopped.lines() == [
        "front_right: nothing judged: stopped early by a key; the motion was not measured"]
    doc = stopped.as_json(exit_status(stopped))
    assert doc["judged"] is False and doc["stopped_by"] == "a key" and doc["measured"] is None
    assert doc["ok"] is False


@pytest.mark.parametrize(("seen", "unchecked", "signalled", "status"), [
    (1.0, "", 0, 0),
    (-1.0, "", 0, EXIT_FIX),
    (None, "--no-ask", 0, 0),
    (None, "answered: not seen", 0, 1),  # s: invert and gear_ratio went unchecked
    (None, "no answer: standard input ended", 0, 1),
    (None, "Ctrl-C", 130, 130),
    (1.0, "", 130, 130),
])
def test_json_ok_is_exactly_exit_status_zero(seen: float | None, unchecked: str,
                                             signalled: int, status: int) -> None:
    plan = plan_of()
    verdict = judge(plan, at(plan, 1.0), seen, unchecked=unchecked)
    assert exit_status(verdict, signalled) == status
    doc = verdict.as_json(status)
    assert doc["ok"] is (status == 0)
    assert doc["judged"] is True and doc["config_checked"] is (seen is not None)


@given(g_true=st.floats(0.05, 100.0), g_cfg=st.floats(0.05, 100.0), inv_true=st.booleans(),
       inv_cfg=st.booleans(), speed=st.floats(0.1, 5.0))
def test_following_the_advice_gives_the_true_configuration(
        g_true: float, g_cfg: float, inv_true: bool, inv_cfg: bool, speed: float) -> None:
    # The motor turns as commanded through the configured ratio and sign; the wheel turns it
    # through the true ones; the encoder sees the configured ones again (it agrees).
    configured = dataclasses.replace(RIGHT, gear_ratio=g_cfg, invert=inv_cfg)
    plan = plan_of(configured, speed)
    true = dataclasses.replace(RIGHT, gear_ratio=g_true, invert=inv_true)
    wheel = true.motor_to_wheel_rad_s(configured.wheel_to_motor_rad_s(speed))
    got = judge(plan, at(plan, 1.0), wheel / speed)
    checks = {f.check for f in got.findings}
    assert (Check.INVERT in checks) is (inv_true != inv_cfg)
    ratio = g_cfg / g_true
    assert (Check.GEAR_RATIO in checks) is not (1 / 1.5 <= ratio <= 1.5)
    fixed = configured
    for f in got.findings:
        if f.check is Check.INVERT:
            fixed = dataclasses.replace(fixed, invert=f.advice.split("invert: ")[1].startswith(
                "true"))
        else:
            fixed = dataclasses.replace(fixed, gear_ratio=float(f.advice.rsplit(" ", 1)[1]))
    assert fixed.invert == inv_true
    if Check.GEAR_RATIO in checks:
        assert fixed.gear_ratio == pytest.approx(g_true, rel=5e-3)
