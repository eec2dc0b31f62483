"""Numbers for people (:mod:`gateway.core.numfmt`): the quantity's resolution, no negative
zero, no exponent."""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from gateway.core.numfmt import fixed, rounded, short
from gateway.core.types import Twist

#: What a least-squares solve leaves where zero is meant (fk on the mecanum robot).
NOISE = (-2.7755575615628914e-17, 1.3877787807814457e-17, -1e-300, -0.0)


@pytest.mark.parametrize("value", NOISE)
def test_noise_is_zero(value: float) -> None:
    assert fixed(value, 3) == "0.000"
    assert fixed(value, 3, sign=True) == "+0.000"
    assert short(value, 4) == "0"
    assert short(value, 4, sign=True) == "+0"
    assert math.copysign(1.0, rounded(value, 2)) == 1.0


@pytest.mark.parametrize(("value", "places", "text"), [
    (-0.004, 2, "0.00"), (-0.005, 2, "-0.01"), (-0.0051, 2, "-0.01"), (0.5, 3, "0.500"),
    (-12.3456, 1, "-12.3"), (1e6, 0, "1000000"),
])
def test_fixed(value: float, places: int, text: str) -> None:
    assert fixed(value, places) == text


@pytest.mark.parametrize(("value", "text"), [
    (0.5, "0.5"), (-0.125, "-0.125"), (100.0, "100"), (0.30000000000000004, "0.3"),
    (1e-5, "0"), (-4.9e-5, "0"), (1.23456, "1.2346"), (12345.0, "12345"),
])
def test_short(value: float, text: str) -> None:
    assert short(value, 4) == text


@pytest.mark.parametrize("value", [math.nan, math.inf, -math.inf])
def test_not_finite_is_written_as_it_is(value: float) -> None:
    assert fixed(value, 2) == f"{value:.2f}"
    assert short(value, 2) == f"{value:.2f}"


@given(st.floats(allow_nan=False, allow_infinity=False, min_value=-1e9, max_value=1e9),
       st.integers(min_value=0, max_value=6))
def test_never_a_negative_zero_nor_an_exponent(value: float, places: int) -> None:
    text = fixed(value, places)
    assert "e" not in text
    assert float(text) != 0.0 or not text.startswith("-")
    assert text == f"{value:.{places}f}" or float(text) == 0.0  # only the sign of zero differs
    assert "e" not in short(value, places) and short(value, places) != "-0"


def test_twist_str_has_no_noise() -> None:
    # The nearest feasible twist of ``ik --vx 0.1 --vy 0.1 --wz 0.3`` on a differential drive.
    assert str(Twist(0.1, -2.7755575615628914e-17, 0.3)) == "(vx=0.1 m/s, vy=0 m/s, wz=0.3 rad/s)"
    assert str(Twist(-0.0, 0.25, -1.578e-17)) == "(vx=0 m/s, vy=0.25 m/s, wz=0 rad/s)"
