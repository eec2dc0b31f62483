"""How well the driven wheels tell the motions apart (gateway.core.kinematics.layout)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from gateway.config import load_config
from gateway.core.kinematics import PRESETS, Wheel, WheelType
from gateway.core.kinematics.layout import (
    MIN_EXTENT_M,
    NOTICED_LITTLE_M_S,
    NOTICED_NONE_M_S,
    closest_pair,
    equations,
    weakest_motion,
)
from tests.conftest import CONFIG_DIR

HALF_PI = math.pi / 2


def differential(right_alpha: float, right_l: float, right_beta: float) -> list[Wheel]:
    """A differential drive with a castor: the right wheel as given (REP-103: at
    alpha -pi/2, beta pi; a copy of the left wheel's line at alpha +pi/2, beta 0)."""
    return [
        Wheel("left", WheelType.FIXED, HALF_PI, 0.2, 0.0, 0.05),
        Wheel("right", WheelType.FIXED, right_alpha, right_l, right_beta, 0.05),
        Wheel("castor", WheelType.CASTOR, math.pi, 0.25, -HALF_PI, 0.025, d=0.03),
    ]


DRIVEN = [True, True, False]


def centre(twist: object) -> tuple[float, float]:
    """The point a twist turns about."""
    vx, vy, wz = (getattr(twist, k) for k in ("vx_m_s", "vy_m_s", "wz_rad_s"))
    return -vy / wz, vx / wz


@pytest.mark.parametrize("path", sorted(CONFIG_DIR.glob("*.yaml")), ids=lambda p: p.stem)
def test_every_shipped_robot_notices_every_motion(path: object) -> None:
    cfg = load_config(path)  # type: ignore[arg-type]
    _, noticed = weakest_motion(cfg.model.wheels, [m is not None for m in cfg.motors])
    assert 0.45 < noticed <= 1.0 + 1e-12


@pytest.mark.parametrize("name", sorted(PRESETS))
def test_every_preset_at_its_default_geometry_notices_every_motion(name: str) -> None:
    preset = PRESETS[name]
    required = {"wheel_radius": 0.05, "track": 0.4, "wheelbase": 0.5, "wheel_distance": 0.2}
    wheels = preset.wheels(**{k: v for k, v in required.items()
                              if k in preset.params and preset.params[k] is None})
    _, noticed = weakest_motion(wheels, [w.driven for w in wheels])
    assert 0.45 < noticed <= 1.0 + 1e-12


def test_a_right_wheel_written_as_a_second_left_wheel_is_not_noticed_turning_about_it() -> None:
    """The typo the check is for: alpha and beta of the left wheel kept for the right one.
    ``ik --wz 1`` then turns both wheels alike, which drives the robot backwards."""
    twist, noticed = weakest_motion(differential(HALF_PI, 0.2, 0.0), DRIVEN)
    assert noticed < 1e-12
    assert centre(twist) == pytest.approx((0.0, 0.2), abs=1e-12)
    sound, fine = weakest_motion(differential(-HALF_PI, 0.2, math.pi), DRIVEN)
    assert fine == pytest.approx(0.4878, abs=1e-4)  # the shipped differential_castor.yaml
    assert sound.wz_rad_s > 0.0


def test_wheels_a_tenth_of_a_millimetre_apart_are_noticed_too_little() -> None:
    twist, noticed = weakest_motion(differential(HALF_PI, 0.2001, 0.0), DRIVEN)
    assert NOTICED_NONE_M_S < noticed < NOTICED_LITTLE_M_S
    # Turning at wz about (0, 0.2): the wheels' rims move 0.1 mm * wz apart, the castor
    # (0.32 m away) at 1 m/s: wz = 1 / 0.3202, noticed = 1e-4 * wz / 2 either way of 0.20005.
    assert noticed == pytest.approx(0.5e-4 / math.hypot(0.25, 0.20005), rel=1e-3)
    assert centre(twist) == pytest.approx((0.0, 0.20005), abs=1e-6)
    pair = closest_pair(differential(HALF_PI, 0.2001, 0.0))
    assert pair is not None
    assert pair[:2] == ("left", "right")
    assert pair[2] == pytest.approx(1e-4)


def test_too_few_equations_leave_a_motion_unnoticed() -> None:
    one = [Wheel("only", WheelType.SWEDISH, 0.0, 0.2, 0.0, 0.05)]
    _, noticed = weakest_motion(one, [True])
    assert noticed == 0.0
    assert closest_pair(one) is None


angles = st.floats(-math.pi, math.pi, allow_nan=False)


@st.composite
def layouts(draw: st.DrawFn) -> tuple[list[Wheel], list[bool]]:
    n = draw(st.integers(2, 5))
    wheels = []
    for i in range(n):
        kind = draw(st.sampled_from(list(WheelType)))
        wheels.append(Wheel(
            f"w{i}", kind, draw(angles), draw(st.floats(0.05, 1.0)), draw(angles), 0.05,
            gamma=draw(st.floats(-1.2, 1.2)) if kind is WheelType.SWEDISH else 0.0,
            d=0.03 if kind is WheelType.CASTOR else 0.0))
    return wheels, draw(st.lists(st.booleans(), min_size=n, max_size=n))


def moved(w: Wheel, turn: float, dx: float, dy: float, scale: float) -> Wheel:
    """The same wheel seen from a body frame turned, moved and scaled."""
    x, y = w.x * scale, w.y * scale
    x, y = (x * math.cos(turn) - y * math.sin(turn) + dx,
            x * math.sin(turn) + y * math.cos(turn) + dy)
    alpha = math.atan2(y, x)
    heading = w.heading() + turn
    return dataclasses.replace(w, alpha=alpha, l=math.hypot(x, y),
                               beta=heading + HALF_PI - alpha, d=w.d * scale)


@settings(max_examples=200, deadline=None)
@given(layouts(), angles, st.floats(-2.0, 2.0), st.floats(-2.0, 2.0), st.floats(0.1, 10.0))
def test_what_is_noticed_does_not_depend_on_the_body_frame_or_the_size(
    layout: tuple[list[Wheel], list[bool]], turn: float, dx: float, dy: float, scale: float,
) -> None:
    wheels, driven = layout
    sv = np.linalg.svd(equations(wheels, driven)[0], compute_uv=False)
    assume(sv[-2] - sv[-1] > 1e-3 * sv[0])  # one weakest direction, not a plane of them
    assume(all(math.hypot(w.x * scale + dx, w.y * scale + dy) > 1e-3 for w in wheels))
    extent = max(math.hypot(a.x - b.x, a.y - b.y) for a in wheels for b in wheels)
    assume(extent * min(scale, 1.0) > 10 * MIN_EXTENT_M)  # a robot, not a point
    twist, noticed = weakest_motion(wheels, driven)
    other = [moved(w, turn, dx, dy, scale) for w in wheels]
    twist2, noticed2 = weakest_motion(other, driven)
    assert noticed2 == pytest.approx(noticed, rel=1e-6, abs=1e-9)
    if noticed > 1e-6 and abs(twist.wz_rad_s) > 1e-3:  # the same turn, about the moved centre
        cx, cy = (c * scale for c in centre(twist))
        expected = (cx * math.cos(turn) - cy * math.sin(turn) + dx,
                    cx * math.sin(turn) + cy * math.cos(turn) + dy)
        assert centre(twist2) == pytest.approx(expected, rel=1e-5, abs=1e-5)
