"""Screens that fit the terminal (:mod:`gateway.apps.layout`): colour and NO_COLOR, cutting,
packing, fitting to a height, steering actuators beside their wheels."""

from __future__ import annotations

import pytest

from gateway.apps.layout import (
    Level,
    Line,
    fit,
    pack,
    paint,
    pair_steering,
    steering_of,
    wants_colour,
    wrap,
)
from gateway.config import load_config
from tests.conftest import CONFIG_DIR


@pytest.mark.parametrize(("isatty", "environ", "colour"), [
    (True, {}, True),
    (True, {"NO_COLOR": ""}, True),  # no-color.org: present *and not empty*
    (True, {"NO_COLOR": "1"}, False),
    (True, {"NO_COLOR": "0"}, False),  # any value
    (False, {}, False),  # a pipe or a file
])
def test_colour_only_on_a_terminal_without_no_color(isatty: bool, environ: dict[str, str],
                                                     colour: bool) -> None:
    assert wants_colour(isatty, environ) is colour


def test_paint_cuts_before_it_colours() -> None:
    line = Line("  left   fault   over_temperature", Level.ERROR, 9)
    assert paint(line, 20, colour=False) == "  left   fault   ov~"  # the cut shows
    assert paint(line, 20, colour=True) == "  left   \x1b[31mfault   ov~\x1b[0m"
    assert paint(Line("exactly ten"), 11, False) == "exactly ten"  # nothing cut, no mark
    assert paint(Line("note: x", Level.WARNING), 80, True) == "\x1b[33mnote: x\x1b[0m"
    assert paint(Line("plain"), 80, True) == "plain"
    assert paint(Line("ab", Level.ERROR, 5), 80, True) == "ab"  # nothing to colour


def test_wrap_and_pack_keep_to_the_width_and_the_lines() -> None:
    text = "last error: " + "word " * 40
    lines = wrap(text, 30, 3, Level.ERROR, 12)
    assert len(lines) == 3 and all(len(ln.text) <= 30 for ln in lines)
    assert lines[-1].text.endswith("[...]")
    assert (lines[0].start, lines[1].start, lines[1].text[:4]) == (12, 0, "    ")
    parts = ["errors: rejected by odrive 0", "send failures 2", "bus reopens 0"]
    assert [ln.text for ln in pack(parts, 50, 3, sep=", ")] == [
        "errors: rejected by odrive 0, send failures 2,", "    bus reopens 0"]
    assert [ln.text for ln in pack(parts, 50, 1, sep=", ")] == [
        "errors: rejected by odrive 0 [...]"]  # whole parts left out, and the marker fits
    assert [ln.text for ln in pack(parts, 51, 1, sep=", ")] == [
        "errors: rejected by odrive 0, send failures 2 [...]"]
    assert [ln.text for ln in pack(["x" * 30, "y"], 20, 1)] == ["x" * 14 + " [...]"]
    assert [ln.text for ln in pack(parts, 200, 1, sep=", ")] == [", ".join(parts)]


def test_fit_gives_way_in_the_order_given() -> None:
    a = [[Line("a1"), Line("a2"), Line("a3")], [Line("a")]]
    b = [[Line("b1"), Line("b2")], [Line("b")], []]
    assert [ln.text for ln in fit([a, b], None, [0, 1, 1])] == ["a1", "a2", "a3", "b1", "b2"]
    assert [ln.text for ln in fit([a, b], 5, [1, 0])] == ["a1", "a2", "a3", "b1", "b2"]
    assert [ln.text for ln in fit([a, b], 4, [1, 0])] == ["a1", "a2", "a3", "b"]
    assert [ln.text for ln in fit([a, b], 2, [1, 0])] == ["a", "b"]
    assert [ln.text for ln in fit([a, b], 1, [1, 1, 0])] == ["a"]
    assert fit([a, b], 0, [0]) == []  # cut as a last resort


def test_steering_actuators_go_beside_their_wheels() -> None:
    swerve = load_config(CONFIG_DIR / "swerve.yaml")
    names = [*(m.wheel for m in swerve.motors if m is not None),
             *(a.wheel for a in swerve.steering)]
    assert names[4] == "front_left steering"
    assert pair_steering(names, steering_of(swerve)) == [(0, 4), (1, 5), (2, 6), (3, 7)]
    # An actuator of two wheels (an Ackermann linkage) stands on its own, after the wheels.
    ackermann = load_config(CONFIG_DIR / "ackermann.yaml")
    steers = steering_of(ackermann)
    assert steers == {"front_axle steering": ("front_left", "front_right")}
    names = ["rear_left", "rear_right", "front_axle steering"]
    assert pair_steering(names, steers) == [(0, None), (1, None), (2, None)]
    names = ["front_left", "front_right", "front_axle steering"]  # even beside one of them
    assert pair_steering(names, steers) == [(0, None), (1, None), (2, None)]
    assert pair_steering(["a", "b"], {}) == [(0, None), (1, None)]
