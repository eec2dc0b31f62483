"""The pure part of ``wheelgate jog`` (key map, speeds, deadman) and its CLI errors; the screen
is tests/apps/test_jog_screen.py."""

from __future__ import annotations

import dataclasses
import itertools
import math
from typing import TYPE_CHECKING

import pytest

from gateway.apps.jog.keys import (
    HOLONOMIC_BINDINGS,
    MOVE_BINDINGS,
    NO_LIMIT,
    SPEED_BINDINGS,
    STOP,
    JogLimits,
    JogState,
    Request,
    jog_limits,
    key_name,
    split_keys,
    step_error,
)
from gateway.cli import COMMANDS, main
from gateway.config import load_config
from gateway.core.types import Twist
from tests.conftest import CONFIG_DIR

if TYPE_CHECKING:
    from click.testing import CliRunner

#: teleop_twist_keyboard's moveBindings (x, y, z, th), copied from its source.
TELEOP_MOVE = {
    "i": (1, 0, 0, 0), "o": (1, 0, 0, -1), "j": (0, 0, 0, 1), "l": (0, 0, 0, -1),
    "u": (1, 0, 0, 1), ",": (-1, 0, 0, 0), ".": (-1, 0, 0, 1), "m": (-1, 0, 0, -1),
    "O": (1, -1, 0, 0), "I": (1, 0, 0, 0), "J": (0, 1, 0, 0), "L": (0, -1, 0, 0),
    "U": (1, 1, 0, 0), "<": (-1, 0, 0, 0), ">": (-1, -1, 0, 0), "M": (-1, 1, 0, 0),
}
#: teleop_twist_keyboard's speedBindings (linear factor, angular factor).
TELEOP_SPEED = {"q": (1.1, 1.1), "z": (0.9, 0.9), "w": (1.1, 1.0), "x": (0.9, 1.0),
                "e": (1.0, 1.1), "c": (1.0, 0.9)}

HOLO = JogLimits(2.0, 4.0, "motor max_rpm", "motor max_rpm", holonomic=True, drive="mecanum")
DIFF = JogLimits(0.6, 1.2, "limits.max_linear_m_s", "motor max_rpm", holonomic=False,
                 drive="differential")


def twist_of(step_requests: tuple[Request, ...]) -> Twist:
    assert len(step_requests) == 1 and step_requests[0].op == "twist", step_requests
    return step_requests[0].twist


# --------------------------------------------------------------------- key bindings


def test_bindings_are_teleop_twist_keyboard_s() -> None:
    assert set(MOVE_BINDINGS) | set(HOLONOMIC_BINDINGS) == set(TELEOP_MOVE)
    assert dict(SPEED_BINDINGS) == TELEOP_SPEED


@pytest.mark.parametrize("key", sorted(TELEOP_MOVE))
def test_every_move_key_sends_its_twist_at_once(key: str) -> None:
    x, y, _, th = TELEOP_MOVE[key]
    step = JogState.start(HOLO).on_key(key, 10.0)
    assert twist_of(step.requests) == Twist(0.5 * x, 0.5 * y, 1.0 * th)
    assert step.state.moving and step.state.key == key
    assert step.state.twist == Twist(0.5 * x, 0.5 * y, 1.0 * th)


@pytest.mark.parametrize("key", sorted(HOLONOMIC_BINDINGS))
def test_holonomic_keys_are_refused_with_stop_on_other_drives(key: str) -> None:
    moving = JogState.start(DIFF).on_key("i", 0.0).state
    step = moving.on_key(key, 0.05)
    assert step.requests == (STOP,)
    assert not step.state.moving
    assert step.state.message == (f"{key!r} is a holonomic (sideways) key: this differential "
                                  "drive cannot follow vy; sent stop")


@pytest.mark.parametrize("key", ["k", " ", "a", "\x1b[A", "\x1bOP", "\x1bi", "\x07", "t", "b"])
def test_stop_keys_and_unknown_keys_stop(key: str) -> None:
    moving = JogState.start(HOLO).on_key("i", 0.0).state
    step = moving.on_key(key, 0.05)
    assert step.requests == (STOP,)
    assert not step.state.moving and step.state.twist == Twist()
    assert step.state.ended == ""
    assert step.state.next_deadline_s() == math.inf
    # An explicit stop goes out even when already stopped.
    assert step.state.on_key(key, 0.1).requests == (STOP,)


def test_z_keys_say_why_they_stop() -> None:
    step = JogState.start(HOLO).on_key("t", 0.0)
    assert step.state.message == "'t' moves along z in teleop_twist_keyboard; a ground robot " \
                                 "has none: sent stop"


@pytest.mark.parametrize(("key", "name"), [("\x03", "Ctrl-C"), ("\x04", "Ctrl-D"),
                                           ("\x1b", "Esc")])
def test_quit_keys_stop_and_end(key: str, name: str) -> None:
    moving = JogState.start(HOLO).on_key("u", 0.0).state
    step = moving.on_key(key, 0.1)
    assert step.requests == (STOP,)
    assert step.state.ended == name
    assert not step.state.moving
    assert step.state.message == f"{name}: quit, sent stop"


def test_end_of_input_stops_and_ends() -> None:
    step = JogState.start(HOLO).on_key("i", 0.0).state.on_quit("end of input")
    assert step.requests == (STOP,) and step.state.ended == "end of input"


def test_q_is_speed_up_not_quit() -> None:
    step = JogState.start(HOLO).on_key("q", 0.0)
    assert step.state.ended == "" and step.requests == ()
    assert step.state.linear_m_s == pytest.approx(0.55)


# --------------------------------------------------------------------- speeds


@pytest.mark.parametrize("key", sorted(TELEOP_SPEED))
def test_speed_keys_scale_by_ten_percent(key: str) -> None:
    lin_f, ang_f = TELEOP_SPEED[key]
    step = JogState.start(HOLO).on_key(key, 0.0)
    assert step.state.linear_m_s == pytest.approx(0.5 * lin_f)
    assert step.state.angular_rad_s == pytest.approx(1.0 * ang_f)
    assert step.requests == ()  # nothing moves
    assert step.state.message.startswith(f"linear {0.5 * lin_f:.3g} m/s, angular")


def test_speed_key_while_moving_resends_but_does_not_feed_the_deadman() -> None:
    state = JogState.start(HOLO).on_key("u", 0.0).state
    step = state.on_key("q", 0.5)
    assert twist_of(step.requests) == Twist(0.55, 0.0, 1.1)
    state = step.state
    assert state.last_key_s == 0.0
    assert state.on_tick(0.6).requests == (STOP,)  # holding q does not drive the robot


def test_speeds_are_clamped_to_the_limits_and_say_so() -> None:
    state = JogState.start(DIFF)
    for _ in range(10):
        state = state.on_key("w", 0.0).state
    assert state.linear_m_s == 0.6
    assert state.message == ("linear 0.6 m/s, angular 1 rad/s; linear speed limit reached "
                             "(limits.max_linear_m_s)")
    for _ in range(10):
        state = state.on_key("e", 0.0).state
    assert state.angular_rad_s == 1.2
    assert state.message.endswith("angular speed limit reached (motor max_rpm)")
    assert state.on_key("x", 0.0).state.linear_m_s == pytest.approx(0.54)


def test_start_clamps_the_default_speeds() -> None:
    state = JogState.start(JogLimits(0.2, 0.5, "motor max_rpm", "limits.max_angular_rad_s"))
    assert (state.linear_m_s, state.angular_rad_s) == (0.2, 0.5)
    assert state.message == ("linear speed 0.5 m/s clamped to 0.2 m/s by motor max_rpm; "
                             "angular speed 1 rad/s clamped to 0.5 rad/s by "
                             "limits.max_angular_rad_s")
    assert JogState.start(HOLO).message == "ready"


def test_start_takes_the_first_speeds_given() -> None:
    # jog --speed/--turn, as teleop_twist_keyboard's speed and turn parameters.
    state = JogState.start(HOLO, 1.5, 0.25)
    assert (state.linear_m_s, state.angular_rad_s, state.message) == (1.5, 0.25, "ready")
    assert twist_of(state.on_key("u", 0.0).requests) == Twist(1.5, 0.0, 0.25)
    assert state.on_key("q", 0.0).state.linear_m_s == pytest.approx(1.65)
    assert JogState.start(HOLO, None, 3.0).linear_m_s == 0.5  # None: teleop's 0.5 m/s


@pytest.mark.parametrize(("value", "ok"), [
    (0.5, True), (4.654, True), (4.6542, True), (4.6543, False), (0.0, False), (-0.5, False),
    (math.nan, False), (math.inf, False), (-math.inf, False), (1e-9, True),
])
def test_step_error_bounds(value: float, ok: bool) -> None:
    why = step_error(value, 4.654211338651545, "motor max_rpm", "a linear", "m/s")
    assert (why == "") is ok
    if not ok:
        assert why == ("expected a linear speed above 0 and at most 4.654 m/s (motor max_rpm), "
                       f"got {value!r}")


def test_the_limit_said_is_one_that_is_accepted() -> None:
    burger = 0.2108008670558751  # 61 rpm wheels: rounded, 0.211 would be refused
    assert step_error(0.3, burger, "motor max_rpm", "a linear", "m/s").startswith(
        "expected a linear speed above 0 and at most 0.21 m/s (motor max_rpm)")
    assert step_error(0.21, burger, "motor max_rpm", "a linear", "m/s") == ""
    assert "(the control socket's largest twist)" in step_error(200.0, 100.0, NO_LIMIT,
                                                                "a linear", "m/s")


@pytest.mark.parametrize(("name", "holonomic"), [
    ("mecanum", True), ("omni3", True), ("omni_delta", True), ("omni3_swedish", True),
    ("swerve", True), ("synchro", True), ("turtlebot3_burger", False),
    ("differential_tub", False), ("skid_steer", False), ("ackermann", False),
    ("tricycle", False),
])
def test_holonomic_is_decided_by_the_model(name: str, holonomic: bool) -> None:
    assert jog_limits(load_config(CONFIG_DIR / f"{name}.yaml")).holonomic is holonomic


def test_limits_from_the_config() -> None:
    cfg = load_config(CONFIG_DIR / "turtlebot3_burger.yaml")
    lim = jog_limits(cfg)
    wheel = 61 * 2 * math.pi / 60  # rad/s at 61 rpm, gear ratio 1
    assert lim.max_linear_m_s == pytest.approx(wheel * 0.033)  # 0.2108 < 0.22 of the config
    assert lim.linear_by == "motor max_rpm"
    assert lim.max_angular_rad_s == pytest.approx(wheel * 0.033 / 0.080)  # < 2.84
    assert lim.angular_by == "motor max_rpm"
    assert lim.command_scale(Twist(0.1, 0.0, 0.0)) == 1.0
    assert lim.command_scale(Twist(0.2108, 0.0, 1.0)) == pytest.approx(
        wheel / ((0.2108 + 0.08) / 0.033))
    assert lim.command_scale(Twist(0.0, 0.1, 0.0)) is None  # infeasible
    tight = dataclasses.replace(cfg, limits=dataclasses.replace(cfg.limits, max_linear_m_s=0.1))
    assert jog_limits(tight).max_linear_m_s == pytest.approx(0.1)
    assert jog_limits(tight).linear_by == "limits.max_linear_m_s"
    free = dataclasses.replace(cfg, limits=dataclasses.replace(
        cfg.limits, max_wheel_rad_s=(math.inf, math.inf), max_linear_m_s=math.inf))
    assert (jog_limits(free).max_linear_m_s, jog_limits(free).linear_by) == (100.0, NO_LIMIT)
    ackermann = jog_limits(load_config(CONFIG_DIR / "ackermann.yaml"))
    assert ackermann.angular_by == "infeasible alone"  # it cannot turn in place


# --------------------------------------------------------------------- deadman


def test_deadman_on_simulated_auto_repeat() -> None:
    """A key pressed at 0, auto-repeat from 0.4 s every 33 ms until 2.0 s, then released."""
    keys = [0.0] + [0.4 + 0.033 * k for k in range(int(1.6 / 0.033) + 1)]
    state = JogState.start(HOLO, deadman_s=0.6)
    sent: list[tuple[float, Request]] = []
    events = sorted([(t, "key") for t in keys] + [(t / 100, "tick") for t in range(400)])
    for t, what in events:
        step = state.on_key("i", t) if what == "key" else state.on_tick(t)
        state = step.state
        sent += [(t, r) for r in step.requests]
    twists = [t for t, r in sent if r.op == "twist"]
    stops = [t for t, r in sent if r.op == "stop"]
    last_key = keys[-1]
    assert twists[0] == 0.0
    assert all(r.twist == Twist(0.5, 0.0, 0.0) for _, r in sent if r.op == "twist")
    # 10 Hz re-sends while the key is held (through the initial repeat delay too).
    gaps = [b - a for a, b in itertools.pairwise(twists)]
    assert all(g == pytest.approx(0.1, abs=0.011) for g in gaps), gaps
    assert twists[-1] <= last_key + 0.6
    # Exactly one stop, at the first tick at or after the last key + the deadman time.
    assert stops == [pytest.approx(math.ceil((last_key + 0.6) * 100) / 100)]
    assert not state.moving


def test_deadman_boundaries_and_deadlines() -> None:
    state = JogState.start(HOLO, deadman_s=0.6).on_key("l", 1.0).state
    assert state.next_deadline_s() == pytest.approx(1.1)
    assert state.on_tick(1.05).requests == ()
    step = state.on_tick(1.1)
    assert twist_of(step.requests) == Twist(0.0, 0.0, -1.0)
    state = step.state.on_key("l", 1.5).state  # repeat: keeps it alive, sends nothing
    assert state.next_deadline_s() == pytest.approx(1.2)
    assert state.on_tick(2.099).state.moving
    assert state.on_tick(2.1).requests == (STOP,)
    assert state.on_tick(2.1).state.message == "deadman: no key for 0.6 s: sent stop"
    assert state.on_tick(2.1).state.on_tick(5.0).requests == ()  # stop goes out once


def test_a_late_tick_does_not_burst() -> None:
    state = JogState.start(HOLO).on_key("i", 0.0).state
    step = state.on_key("i", 0.35).state.on_tick(0.35)  # the loop was busy for 0.35 s
    assert len(step.requests) == 1
    assert step.state.next_send_s == pytest.approx(0.45)


def test_new_direction_or_stale_repeat_sends_at_once() -> None:
    state = JogState.start(HOLO).on_key("i", 0.0).state
    assert twist_of(state.on_key("o", 0.03).requests) == Twist(0.5, 0.0, -1.0)
    # The same key after the deadman time without a tick in between: a fresh press.
    assert twist_of(state.on_key("i", 0.7).requests) == Twist(0.5, 0.0, 0.0)
    assert state.on_key("i", 0.5).requests == ()


# --------------------------------------------------------------------- terminal input


@pytest.mark.parametrize(("data", "keys"), [
    (b"iii", ["i", "i", "i"]),
    (b"\x1b", ["\x1b"]),
    (b"i\x1b", ["i", "\x1b"]),
    (b"\x1b[A\x1b[1;5C", ["\x1b[A", "\x1b[1;5C"]),
    (b"\x1bOPk", ["\x1bOP", "k"]),
    (b"\x1bi", ["\x1bi"]),
    (b"\x03", ["\x03"]),
    ("\u00e9".encode(), ["\u00c3", "\u00a9"]),
])
def test_split_keys(data: bytes, keys: list[str]) -> None:
    assert split_keys(data) == keys


def test_key_names() -> None:
    assert [key_name(k) for k in ("i", " ", "\x03", "\x1b", "\x01", "\x1b[A")] == [
        "'i'", "space", "Ctrl-C", "Esc", "Ctrl-A", "escape sequence"]


def test_request_payloads() -> None:
    assert Request("twist", Twist(0.1, -0.2, 0.3)).payload() == {
        "op": "twist", "vx": 0.1, "vy": -0.2, "wz": 0.3}
    assert STOP.payload() == {"op": "stop"}


# --------------------------------------------------------------------- command line


@pytest.fixture
def jog_registered(monkeypatch: pytest.MonkeyPatch) -> None:
    """``jog`` in the root group, as the lead registers it."""
    monkeypatch.setitem(COMMANDS, "jog", "jog")


@pytest.mark.parametrize("value", ["0", "-1", "abc", "nan", "6"])
def test_bad_deadman_is_a_usage_error(runner: CliRunner, jog_registered: None,
                                      value: str) -> None:
    result = runner.invoke(main, ["jog", "--deadman", value])
    assert result.exit_code == 2, result.output
    assert "--deadman" in result.stderr


@pytest.mark.parametrize(("args", "message"), [
    (["--sim"], "--sim needs --standalone"),
    (["--standalone", "--socket", "/tmp/x.sock"], "--standalone uses a private socket"),
    ([], "jog reads keys from a terminal, but stdin is not a terminal"),
])
def test_usage_errors(runner: CliRunner, jog_registered: None, args: list[str],
                      message: str) -> None:
    result = runner.invoke(main, ["jog", *args])
    assert result.exit_code == 2, result.output
    assert message in result.stderr
    if not args:  # well formed, only no terminal: no usage lines
        assert "Usage:" not in result.stderr


@pytest.mark.parametrize(("args", "message"), [
    (["--speed", "5"], "Invalid value for --speed: expected a linear speed above 0 and at "
                       "most 4.654 m/s (motor max_rpm), got 5.0"),
    (["--turn", "13.2"], "Invalid value for --turn: expected an angular speed above 0 and "
                         "at most 13.164 rad/s (motor max_rpm), got 13.2"),
    (["--speed", "nan"], "Invalid value for --speed: expected a linear speed above 0"),
    (["--turn", "inf"], "Invalid value for --turn: expected an angular speed above 0"),
    (["--speed", "0"], "got 0.0"),
    (["--turn", "-1"], "got -1.0"),
    (["--speed", "fast"], "Invalid value for '--speed': 'fast' is not a valid float"),
])
def test_speed_and_turn_beyond_the_robot_are_usage_errors(
        runner: CliRunner, jog_registered: None, args: list[str], message: str) -> None:
    result = runner.invoke(main, ["jog", "-c", str(CONFIG_DIR / "swerve.yaml"), *args])
    assert result.exit_code == 2, result.output
    assert message in result.stderr


def test_speed_and_turn_within_the_robot_pass(runner: CliRunner, jog_registered: None) -> None:
    result = runner.invoke(main, ["jog", "-c", str(CONFIG_DIR / "swerve.yaml"), "--speed",
                                  "4.654", "--turn", "0.1"])
    assert "jog reads keys from a terminal" in result.stderr  # the next check, not theirs


def test_missing_config_file(runner: CliRunner, jog_registered: None) -> None:
    result = runner.invoke(main, ["jog", "-c", "/nonexistent/robot.yaml"])
    assert result.exit_code == 2
    assert "/nonexistent/robot.yaml: cannot read the file" in result.stderr
