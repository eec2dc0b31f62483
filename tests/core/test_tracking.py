"""The tracking-error check (gateway.core.tracking) and the supervisor's use of it, pure."""

from __future__ import annotations

import dataclasses
import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from gateway.config import parse_config
from gateway.core.control import Fault, StatusBoard, Supervisor
from gateway.core.errors import ConfigError
from gateway.core.kinematics import PRESETS, RobotModel
from gateway.core.settings import LoopConfig, TrackingLimits
from gateway.core.tracking import RUNAWAY_WEIGHT_MAX, TrackingFault, TrackingMonitor
from gateway.core.types import DriveFault, DriveState, ErrorCode, GatewayState, MotorStatus, Twist
from gateway.core.types import WheelFeedback as Fb
from tests.conftest import SIM_ODRIVE_ENDPOINTS

LIMITS = TrackingLimits(tolerance_rad_s=1.0, tolerance_ratio=0.1, time_s=0.5)
DT = 0.01


def fb(v: float, t: float = 0.0) -> Fb:
    return Fb(0.0, v, t)


def run(mon: TrackingMonitor, cmd: list[float], measured: list[float], seconds: float,
        start: float = 0.0) -> tuple[float, TrackingFault] | None:
    """Check every DT for ``seconds``; the first fault and its time."""
    for k in range(round(seconds / DT) + 1):
        t = start + k * DT
        fault = mon.check(cmd, [fb(v, t) for v in measured], t)
        if fault is not None:
            return t, fault
    return None


def test_window_widens_with_the_command() -> None:
    assert LIMITS.window(0.0) == 1.0
    assert LIMITS.window(-20.0) == pytest.approx(3.0)
    assert not TrackingLimits(time_s=0.0).enabled


def test_inside_the_window_never_faults() -> None:
    mon = TrackingMonitor(LIMITS)
    assert run(mon, [20.0, -20.0], [17.01, -22.99], 10.0) is None  # window 3.0 rad/s
    assert mon.worst_ratio == 0.0


def test_outside_the_window_faults_after_time_s_naming_the_wheel() -> None:
    mon = TrackingMonitor(LIMITS)
    got = run(mon, [20.0, 20.0], [20.0, 16.9], 2.0)
    assert got is not None
    t, fault = got
    assert t == pytest.approx(0.5)  # the first check starts the count
    assert (fault.index, fault.command_rad_s, fault.measured_rad_s) == (1, 20.0, 16.9)
    assert (fault.window_rad_s, fault.duration_s) == pytest.approx((3.0, 0.5))
    assert mon.worst_ratio == pytest.approx(3.1 / 3.0)


def test_a_short_excursion_is_forgiven_and_counts_down() -> None:
    mon = TrackingMonitor(LIMITS)
    assert run(mon, [10.0], [0.0], 0.4) is None  # a ramp the motor lags behind
    assert run(mon, [10.0], [10.0], 0.2, start=0.41) is None  # back on: 0.4 -> 0.2
    got = run(mon, [10.0], [0.0], 1.0, start=0.62)
    assert got is not None
    assert got[0] == pytest.approx(0.62 + 0.3)  # the remaining 0.3 s of the count


def at_rest(limits: TrackingLimits = LIMITS, wheels: int = 1) -> TrackingMonitor:
    """A monitor whose first check (at t = 0) saw every wheel standing still."""
    mon = TrackingMonitor(limits)
    assert mon.check([0.0] * wheels, [fb(0.0)] * wheels, 0.0) is None
    return mon


def test_a_runaway_counts_in_proportion_a_lagging_wheel_does_not() -> None:
    # A wheel at 40 rad/s against a command of 2 (window 1.2): 32x outside, capped at 10x.
    got = run(at_rest(), [2.0], [40.0], 1.0)
    assert got is not None and got[0] == pytest.approx(LIMITS.time_s / RUNAWAY_WEIGHT_MAX)
    # The wrong way, faster than commanded: the same.
    got = run(at_rest(), [2.0], [-40.0], 1.0)
    assert got is not None and got[0] == pytest.approx(LIMITS.time_s / RUNAWAY_WEIGHT_MAX)
    # 2.5x outside, faster: 2.5x the plain rate.
    got = run(at_rest(), [10.0], [15.0], 1.0)  # window 2.0, error 5.0
    assert got is not None and got[0] == pytest.approx(LIMITS.time_s / 2.5)
    # Far behind its command (a heavy robot accelerating, a blocked wheel): the plain rate.
    got = run(at_rest(), [40.0], [0.0], 1.0)
    assert got is not None and got[0] == pytest.approx(LIMITS.time_s)
    # A reversal without acceleration limits: still turning at the last command's -13 rad/s
    # against +4.5 is lagging, not running away (no faster than recently commanded).
    mon = TrackingMonitor(LIMITS)
    assert run(mon, [-13.0], [-13.0], 0.2) is None
    got = run(mon, [4.5], [-13.0], 1.0, start=0.21)
    assert got is not None and got[0] == pytest.approx(0.21 + LIMITS.time_s)
    # ... but once the old command is more than 2 time_s in the past, it would be.
    assert run(mon, [4.5], [4.5], 1.5, start=2.0) is None
    got = run(mon, [4.5], [-13.0], 1.0, start=3.6)
    assert got is not None and got[0] < 3.6 + LIMITS.time_s / 2
    # A zero window (no tolerance at standstill): any motion counts at the most.
    zero = dataclasses.replace(LIMITS, tolerance_rad_s=0.0)
    got = run(at_rest(zero), [0.0], [0.1], 1.0)
    assert got is not None and got[0] == pytest.approx(LIMITS.time_s / RUNAWAY_WEIGHT_MAX)


def test_a_wheel_coasting_when_the_check_starts_lags_until_it_speeds_up() -> None:
    """Motors enabled again while their wheels still coast (a released DJI ESC): braking
    from the speed a wheel had at the first check is lagging, not running away."""
    mon = TrackingMonitor(LIMITS)
    coasting = [fb(-8.5, 0.0)]
    assert mon.check([0.0], coasting, 0.0) is None
    got = run(mon, [0.0], [-8.5], 1.0)  # it never slows down: the plain rate
    assert got is not None and got[0] == pytest.approx(LIMITS.time_s)
    mon = TrackingMonitor(LIMITS)
    assert mon.check([0.0], coasting, 0.0) is None
    assert run(mon, [0.0], [-8.0], 0.1) is None  # braking
    got = run(mon, [0.0], [-20.0], 1.0, start=0.11)  # then faster than ever: a runaway
    assert got is not None and got[0] < 0.11 + LIMITS.time_s / 4


def test_an_oscillation_through_the_window_is_caught() -> None:
    """A speed loop swinging +-15 rad/s around its command is inside the window a few ms per
    swing: a plain "outside for time_s in a row" rule never fires, the count does."""
    mon = TrackingMonitor(LIMITS)
    fault = None
    for k in range(300):
        t = k * DT
        v = 5.0 + 15.0 * math.sin(2 * math.pi * 3.0 * t)
        fault = fault or mon.check([5.0], [fb(v, t)], t)
    assert fault is not None


def test_nan_speed_is_outside_and_missing_feedback_is_skipped() -> None:
    mon = TrackingMonitor(LIMITS)
    assert run(mon, [1.0], [math.nan], 1.0) is not None
    mon = TrackingMonitor(LIMITS)
    for k in range(200):
        assert mon.check([5.0], [None], k * DT) is None


def test_reset_forgets_and_a_long_gap_adds_at_most_a_tenth() -> None:
    mon = TrackingMonitor(LIMITS)
    assert run(mon, [10.0], [0.0], 0.45) is None
    mon.reset()
    assert run(mon, [10.0], [0.0], 0.45, start=1.0) is None
    mon.reset()
    assert mon.check([10.0], [fb(0.0)], 0.0) is None
    assert mon.check([10.0], [fb(0.0)], 60.0) is None  # a stalled loop: one sample
    assert mon.check([10.0], [fb(0.0)], 60.01) is None


def test_disabled_check_never_faults() -> None:
    mon = TrackingMonitor(dataclasses.replace(LIMITS, time_s=0.0))
    assert run(mon, [10.0], [-10.0], 5.0) is None


@given(
    cmd=st.floats(-200.0, 200.0),
    offsets=st.lists(st.floats(-1.0, 1.0), min_size=10, max_size=200),
)
def test_property_a_wheel_within_its_window_never_faults(cmd: float,
                                                         offsets: list[float]) -> None:
    mon = TrackingMonitor(LIMITS)
    window = LIMITS.window(cmd)
    for k, x in enumerate(offsets):
        assert mon.check([cmd], [fb(cmd + x * window, k * DT)], k * DT) is None


@given(seconds=st.floats(0.6, 3.0), cmd=st.floats(-200.0, 200.0))
def test_property_a_stopped_wheel_faults_by_time_s_plus_a_check(seconds: float,
                                                                 cmd: float) -> None:
    mon = TrackingMonitor(LIMITS)
    got = run(mon, [cmd], [cmd + 2 * LIMITS.window(cmd)], seconds)
    assert got is not None and got[0] <= LIMITS.time_s + DT + 1e-9


# -- the supervisor ----------------------------------------------------------------------------

MODEL = RobotModel(PRESETS["differential"].wheels(wheel_radius=0.05, track=0.3))


def statuses(left: float, right: float, t: float) -> StatusBoard:
    return StatusBoard([MotorStatus(name, i + 1, DriveState.ENABLED, DriveFault.NONE, "", 0.0,
                                    fb(v, t))
                        for i, (name, v) in enumerate((("left", left), ("right", right)))])


def running(**cfg: object) -> Supervisor:
    sup = Supervisor(MODEL, dataclasses.replace(LoopConfig(), **cfg))  # type: ignore[arg-type]
    sup.enable(0.0)
    sup.take_enable_request()
    sup.motors(statuses(0.0, 0.0, 0.0), 0.0)
    assert sup.state is GatewayState.RUNNING
    sup.twist(Twist(0.2, 0.0, 0.0), 0.0)
    return sup


def test_supervisor_faults_on_a_wheel_off_its_command() -> None:
    sup = running()
    fault = None
    t = 0.0
    while fault is None and t < 2.0:
        t += DT
        fault = sup.motors(statuses(4.0, 0.0, t), t, [4.0, 4.0])
    assert isinstance(fault, Fault) and fault.code is ErrorCode.TRACKING_ERROR
    assert t == pytest.approx(0.51)  # default tracking_time_s 0.5; the first check counts 0
    assert fault.message.startswith("motor 'right' (node 2) does not follow its command: "
                                    "0.00 rad/s measured, 4.00 rad/s commanded")
    assert sup.state is GatewayState.FAULT and sup.faulted == ("right",)
    assert sup.decide(t).twist == Twist()


def test_supervisor_checks_only_while_running_and_starts_afresh() -> None:
    sup = running()
    for k in range(40):  # 0.4 s off
        assert sup.motors(statuses(4.0, 0.0, k * DT), k * DT, [4.0, 4.0]) is None
    sup.disable()
    for k in range(100):  # not RUNNING: not checked, and the count is forgotten
        assert sup.motors(statuses(4.0, 0.0, 1 + k * DT), 1 + k * DT, [4.0, 4.0]) is None
    sup.enable(3.0)
    assert sup.take_enable_request()
    sup.motors(statuses(0.0, 0.0, 3.0), 3.0)
    assert sup.state is GatewayState.RUNNING
    for k in range(40):
        assert sup.motors(statuses(4.0, 0.0, 3 + k * DT), 3 + k * DT, [4.0, 4.0]) is None


def test_supervisor_without_commands_skips_the_check() -> None:
    sup = running()
    for k in range(200):
        assert sup.motors(statuses(4.0, 0.0, k * DT), k * DT) is None


def robot(gateway: dict[str, object]) -> dict[str, object]:
    """A differential robot's raw config with this ``gateway:`` block."""
    return {"drive": "differential", "geometry": {"wheel_radius": 0.05, "track": 0.3},
            "motor_defaults": {"driver": "odrive", "max_rpm": 3000,
                               "watchdog_endpoints": SIM_ODRIVE_ENDPOINTS},
            "motors": {"left": {"node_id": 1}, "right": {"node_id": 2}}, "gateway": gateway}


@pytest.mark.parametrize(("key", "value", "expected"), [
    ("tracking_time_s", -1.0, "expected at least 0"),
    ("tracking_tolerance_rad_s", "wide", "expected"),
    ("tracking_tolerance_ratio", math.inf, "expected"),
])
def test_config_rejects_bad_tracking_settings(key: str, value: object, expected: str) -> None:
    with pytest.raises(ConfigError, match=rf"gateway.*{key}.*{expected}"):
        parse_config(robot({key: value}), "<test>")


def test_config_carries_the_tracking_limits() -> None:
    raw = robot({"tracking_time_s": 1.5, "tracking_tolerance_rad_s": 0.5})
    assert parse_config(raw, "<test>").loop.tracking == TrackingLimits(0.5, 0.2, 1.5)
