"""The gamepad of ``wheelgate jog --joystick``, pure part: joydev events, the pad's state and
the motion it holds in the jog session (``gateway.apps.jog.pad``, ``JogState.on_pad``)."""

from __future__ import annotations

import math
import struct
from typing import TYPE_CHECKING

import pytest
from hypothesis import given
from hypothesis import strategies as st

from gateway.apps.jog.keys import PAD_KEY, STOP, JogLimits, JogState, Request
from gateway.apps.jog.pad import AXIS, BUTTON, INIT, Pad, PadError, PadEvent, PadMap, parse_events
from gateway.cli import main
from gateway.core.types import Twist

if TYPE_CHECKING:
    from click.testing import CliRunner


def js(value: int, kind: int, number: int, time_ms: int = 0) -> bytes:
    """One ``struct js_event`` as the kernel writes it (Documentation/input/joydev/
    joystick-api.rst: u32 time, s16 value, u8 type, u8 number), in this machine's order."""
    return struct.pack("=IhBB", time_ms, value, kind, number)


def test_events_are_read_from_the_kernels_eight_bytes() -> None:
    # Golden bytes on a little-endian machine (x86, ARM): time 0x01020304, value -32767
    # (0x8001), type axis, number 1.
    if struct.pack("=H", 1) == b"\x01\x00":
        assert js(-32767, AXIS, 1, 0x01020304) == b"\x04\x03\x02\x01\x01\x80\x02\x01"
    data = js(1, BUTTON | INIT, 4) + js(-32767, AXIS, 1) + js(5, AXIS, 3)[:5]
    events, rest = parse_events(data)
    assert events == [PadEvent(BUTTON, 4, 1, True), PadEvent(AXIS, 1, -32767, False)]
    assert rest == js(5, AXIS, 3)[:5]  # half an event waits for the rest
    more, rest = parse_events(rest + js(5, AXIS, 3)[5:])
    assert more == [PadEvent(AXIS, 3, 5, False)] and rest == b""


def test_bytes_that_are_not_joydev_events_are_refused() -> None:
    # An evdev node (/dev/input/eventN) writes 24-byte input_events: the first 8 bytes are a
    # time in seconds, whose type byte reads 0.
    evdev = struct.pack("=qqHHi", 1_790_000_000, 0, 3, 1, -300)
    with pytest.raises(PadError, match=r"got type 0x00: not a joydev device \(/dev/input/jsN\)"):
        parse_events(evdev)


def test_a_button_held_at_open_does_not_drive_until_pressed_again() -> None:
    pad = Pad(PadMap()).apply([PadEvent(BUTTON, 4, 1, True), PadEvent(AXIS, 1, -32767, True)])
    assert pad.held and not pad.armed and pad.direction(True) is None
    pad = pad.apply([PadEvent(BUTTON, 4, 0, False)])
    assert pad.direction(True) is None
    pad = pad.apply([PadEvent(BUTTON, 4, 1, False)])
    assert pad.direction(True) == (1.0, 0.0, 0.0)  # stick full up: forward
    pad = pad.apply([PadEvent(BUTTON, 4, 0, False)])
    assert not pad.armed and pad.direction(True) is None
    other = pad.apply([PadEvent(BUTTON, 5, 1, False)])  # another button enables nothing
    assert other.direction(True) is None


def armed(*axes: tuple[int, int]) -> Pad:
    pad = Pad(PadMap()).apply([PadEvent(BUTTON, 4, 1, False)])
    return pad.apply([PadEvent(AXIS, n, v, False) for n, v in axes])


def test_axes_map_to_rep_103_signs_with_a_dead_zone() -> None:
    # Up and left read negative on joydev: forward, left and counter-clockwise here.
    assert armed((1, -32767), (0, -32767), (3, -32767)).direction(True) == (1.0, 1.0, 1.0)
    assert armed((1, 32767), (0, 32767), (3, 32767)).direction(True) == (-1.0, -1.0, -1.0)
    assert armed((1, -32768)).direction(True) == (1.0, 0.0, 0.0)  # (the s16 minimum: clamped)
    assert armed((1, -1600), (3, 1600)).direction(True) == (0.0, 0.0, 0.0)  # inside 5 %
    x, _, _ = armed((1, -16384)).direction(True) or (0.0, 0.0, 0.0)
    assert x == pytest.approx((16384 / 32767 - 0.05) / 0.95)
    assert armed((0, -32767)).direction(False) == (0.0, 0.0, 0.0)  # no vy on such a drive
    assert armed((2, -32767), (5, 9)).direction(True) == (0.0, 0.0, 0.0)  # unmapped axes


@given(st.integers(-32768, 32767))
def test_an_axis_is_continuous_and_bounded(value: int) -> None:
    x, _, _ = armed((1, value)).direction(True) or (0.0, 0.0, 0.0)
    assert -1.0 <= x <= 1.0
    f = -max(-1.0, min(1.0, value / 32767))
    assert abs(x - f) <= 0.05 + 1e-12  # never farther from the stick than the dead zone
    assert x == 0.0 or math.copysign(1.0, x) == math.copysign(1.0, f)


def test_the_pad_says_which_mapped_inputs_the_device_lacks() -> None:
    assert Pad(PadMap()).missing() == ""  # no INIT events yet: unknown
    small = Pad(PadMap()).apply([*(PadEvent(BUTTON, n, 0, True) for n in range(4)),
                                 *(PadEvent(AXIS, n, 0, True) for n in range(2))])
    assert small.missing() == "button 4, axis 3"


LIMITS = JogLimits(1.0, 2.0, "max_linear_m_s", "max_angular_rad_s", True, "mecanum")


def session() -> JogState:
    return JogState.start(LIMITS, 0.5, 1.0, deadman_s=0.6)


def test_a_held_pad_drives_resends_and_stops_when_let_go() -> None:
    state = session()
    step = state.on_pad(None, 0.0)
    assert step.requests == () and not step.state.moving
    step = step.state.on_pad((1.0, 0.0, 0.5), 0.0)
    assert step.requests == (Request("twist", Twist(0.5, 0.0, 0.5)),)
    assert step.state.key == PAD_KEY
    state = step.state
    for k in range(1, 30):  # 2.9 s held: the deadman (0.6 s) never fires, re-sent at 10 Hz
        now = k * 0.1 + 1e-6  # (a pass a hair after each send time)
        step = state.on_pad((0.5, 0.0, 0.0), now)
        assert step.requests == ()
        step = step.state.on_tick(now)
        assert step.requests == (Request("twist", Twist(0.25, 0.0, 0.0)),)
        state = step.state
    step = state.on_pad(None, 3.0)
    assert step.requests == (STOP,) and not step.state.moving
    assert step.state.message == "joystick: enable button released: sent stop"
    again = session().on_pad((0.2, 0.0, 0.0), 0.0).state.on_pad((0.0, 0.0, 0.0), 0.05)
    assert again.requests == (STOP,)
    assert again.state.message == "joystick: sticks centred: sent stop"


def test_a_pad_that_stops_being_read_is_stopped_by_the_deadman() -> None:
    # (the loop gives the pad's state every pass; should it stop passing, the deadman stops)
    state = session().on_pad((1.0, 0.0, 0.0), 0.0).state
    assert state.on_tick(0.59).requests == (Request("twist", Twist(0.5, 0.0, 0.0)),)
    assert state.on_tick(0.6).requests == (STOP,)


def test_an_idle_pad_leaves_a_key_motion_alone_and_a_held_one_takes_over() -> None:
    state = session().on_key("i", 0.0).state
    assert state.on_pad(None, 0.05).requests == ()
    assert state.on_pad((0.0, 0.0, 0.0), 0.05).requests == ()
    step = state.on_pad((0.0, 0.0, 1.0), 0.05)
    assert step.requests == (Request("twist", Twist(0.0, 0.0, 1.0)),)
    assert step.state.key == PAD_KEY


@pytest.mark.parametrize(("args", "says"), [
    (["--joy-axes", "1,2"], "expected three axis numbers 0 to 255 for vx, vy and wz, as 1,0,3; "
                            "got '1,2'"),
    (["--joy-axes", "1,\u00b2,3"], "got '1,\u00b2,3'"),  # (a digit to isdigit, not to int)
    (["--joy-axes", "1,0,256"], "got '1,0,256'"),
    (["--joy-enable", "-1"], "-1 is not in the range 0<=x<=255"),
])
def test_a_pad_map_that_cannot_be_is_a_usage_error(
        runner: CliRunner, args: list[str], says: str) -> None:
    result = runner.invoke(main, ["jog", *args])
    assert result.exit_code == 2, result.output
    assert says in result.output
