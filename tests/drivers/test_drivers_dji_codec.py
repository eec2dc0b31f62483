"""Tests of the DJI C620 / C610 codec and PI loop: golden bytes, round trips, the PI controller.

Golden frames are the worked examples of the RoboMaster C620/C610 user guides' CAN protocol
sections ("Worked
examples" table), which were checked against DJI's ``CAN_receive.c``.
"""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from drivers.dji import (
    C610,
    C620,
    DjiDriver,
    DjiFeedback,
    EscModel,
    SpeedPi,
)
from drivers.dji.codec import (
    decode_command,
    decode_feedback,
    encode_command,
    encode_feedback,
    feedback_fields,
    message_name,
    unwrap_delta,
)
from gateway.core.errors import DecodeError, EncodeError
from gateway.core.types import Frame
from tests.drivers.dji_helpers import TWO_PI, currents_in, motor

# ===================================================================== codec: golden bytes


def slots(**by_esc: int) -> list[int]:
    """The eight raw set points of ESC 1..8, ``e<n>=value`` for the ones that are not 0."""
    raw = [0] * 8
    for key, value in by_esc.items():
        raw[int(key[1:]) - 1] = value
    return raw


def test_golden_command_esc_1_4() -> None:
    # spec section 4, worked example 1: 4000, -4000, 0, 1000 on 0x200.
    frames = encode_command(slots(e1=4000, e2=-4000, e4=1000), (0,))
    assert frames == [Frame(0x200, bytes.fromhex("0FA0F060000003E8"))]
    assert C620.raw_to_amps(4000) == pytest.approx(4.88, abs=0.005)


def test_golden_command_esc_5_8() -> None:
    # spec section 4, worked example 2: ESC5 = -16384 (-20 A), ESC6 = +16384 on 0x1FF.
    frames = encode_command(slots(e5=-16384, e6=16384), (1,))
    assert frames == [Frame(0x1FF, bytes.fromhex("C000400000000000"))]
    assert C620.amps_to_raw(-20.0) == -16384


def test_golden_feedback() -> None:
    # spec section 4, worked example 3: ecd 8191, 1500 rpm, -200 current, 35 degC on 0x201.
    frame = Frame(0x201, bytes.fromhex("1FFF05DCFF382300"))
    assert decode_feedback(frame) == DjiFeedback(1, 8191, 1500, -200, 35)
    assert feedback_fields(frame) == (8191, 1500, -200, 35, 0)
    assert encode_feedback(DjiFeedback(1, 8191, 1500, -200, 35)) == frame


def test_golden_feedback_through_driver_gives_output_rpm() -> None:
    # 1500 rotor rpm = 78.11 rpm at the M3508 output (spec worked example 3).
    drv = DjiDriver([motor(1)])
    assert drv.measurement(0) is None
    assert drv.on_frame(Frame(0x201, bytes.fromhex("1FFF05DCFF382300"), timestamp_s=1.0))
    fb = drv.feedback(0)
    assert fb is not None
    assert fb.velocity_rad_s * 60.0 / TWO_PI == pytest.approx(78.11, abs=0.005)
    assert fb.position_rad == 0.0
    assert drv.measurement(0) == DjiFeedback(1, 8191, 1500, -200, 35)


def test_golden_wrap() -> None:
    # spec section 4, worked example 4: last ecd 8100, new 50 -> +142 counts.
    assert unwrap_delta(8100, 50) == 142
    assert unwrap_delta(50, 8100) == -142
    assert unwrap_delta(0, 4096) == 4096
    assert unwrap_delta(0, 4097) == -4095


def test_only_the_groups_asked_for() -> None:
    assert encode_command(slots(e2=100), (0,)) == [
        Frame(0x200, bytes.fromhex("0000006400000000"))
    ]
    assert encode_command(slots(e8=-1), (1,)) == [Frame(0x1FF, bytes.fromhex("000000000000FFFF"))]
    both = encode_command(slots(e7=1, e3=2), (0, 1))
    assert [f.arbitration_id for f in both] == [0x200, 0x1FF]
    assert encode_command(slots(), ()) == []


def test_encode_refuses_what_does_not_fit_an_int16() -> None:
    with pytest.raises(EncodeError, match="Expected int16 current set points for DJI ESCs"):
        encode_command(slots(e3=40000), (0,))


def test_message_names() -> None:
    assert [message_name(i) for i in (0x200, 0x1FF, 0x700, 0x201, 0x208, 0x209, 0x069)] == [
        "COMMAND_ESC_1_4", "COMMAND_ESC_5_8", "QUICK_ID_SET", "FEEDBACK_ESC_1",
        "FEEDBACK_ESC_8", None, None,
    ]


@pytest.mark.parametrize(
    ("frame", "message"),
    [
        (Frame(0x201, bytes(7)), "Expected 8 data bytes for DJI feedback 0x201, but got 7."),
        (Frame(0x202, bytes(9)), "but got 9."),
        (Frame(0x203, bytes(8), is_extended_id=True), "but got a 29-bit ID."),
        (Frame(0x204, is_remote_frame=True, dlc=8), "but got a remote frame."),
        (Frame(0x205, bytes.fromhex("2000000000000000")), "between 0 and 8191, but got 8192."),
    ],
)
def test_decode_rejects_malformed(frame: Frame, message: str) -> None:
    for decode in (decode_feedback, feedback_fields):
        with pytest.raises(DecodeError) as info:
            decode(frame)
        assert message in str(info.value)


@pytest.mark.parametrize("ident", [0x069, 0x200, 0x1FF, 0x209, 0x20B, 0x700])
def test_decode_ignores_foreign_ids(ident: int) -> None:
    assert decode_feedback(Frame(ident, bytes(8))) is None


def test_decode_command_checks() -> None:
    assert decode_command(Frame(0x201, bytes(8))) is None
    with pytest.raises(DecodeError, match="Expected 8 data bytes for DJI command 0x200"):
        decode_command(Frame(0x200, bytes(4)))
    with pytest.raises(DecodeError, match="29-bit"):
        decode_command(Frame(0x1FF, bytes(8), is_extended_id=True))


def test_encode_feedback_range() -> None:
    with pytest.raises(EncodeError, match="Expected angle for ESC 1 between 0 and 8191"):
        encode_feedback(DjiFeedback(1, 8192, 0, 0, 0))
    with pytest.raises(EncodeError, match="Expected temperature for ESC 2 between 0 and 255"):
        encode_feedback(DjiFeedback(2, 0, 0, 0, 256))


# ===================================================================== codec: round trips

_slot = st.integers(-16384, 16384)


@given(st.lists(_slot, min_size=8, max_size=8), st.sets(st.integers(0, 1)))
def test_command_round_trip(raw: list[int], groups: set[int]) -> None:
    frames = encode_command(raw, sorted(groups))
    decoded = currents_in(frames)
    assert decoded == {k + 1: raw[k] for g in groups for k in range(4 * g, 4 * g + 4)}
    assert all(f.dlc == 8 and not f.is_extended_id for f in frames)


@given(
    st.integers(1, 8),
    st.integers(0, 8191),
    st.integers(-32768, 32767),
    st.integers(-32768, 32767),
    st.integers(0, 255),
)
def test_feedback_round_trip(esc: int, angle: int, rpm: int, cur: int, temp: int) -> None:
    fb = DjiFeedback(esc, angle, rpm, cur, temp)
    assert decode_feedback(encode_feedback(fb)) == fb


@given(st.sampled_from([C620, C610]), st.floats(-20.0, 20.0))
def test_amps_round_trip_within_half_lsb(model: EscModel, amps: float) -> None:
    amps = max(-model.full_scale_a, min(model.full_scale_a, amps))
    lsb = model.full_scale_a / model.full_scale_raw
    assert abs(model.raw_to_amps(model.amps_to_raw(amps)) - amps) <= lsb / 2 + 1e-12


@given(st.integers(0, 8191), st.lists(st.integers(-4095, 4095), max_size=300))
def test_unwrap_many_turns_both_directions(start: int, steps: list[int]) -> None:
    true_total, last, total = 0, start, 0
    for step in steps:
        true_total += step
        count = (start + true_total) % 8192
        total += unwrap_delta(last, count)
        last = count
    assert total == true_total


# ===================================================================== PI controller


def test_pi_anti_windup() -> None:
    pi = SpeedPi(kp_a_per_rad_s=0.1, ki_a_per_rad=1.0, limit_a=20.0)
    integral = 0.0
    for _ in range(1000):  # 1 s saturated at full positive current
        out, integral = pi.step(integral, 1000.0, 0.001)
        assert out == 20.0
    assert integral == 0.0  # held: the proportional term alone saturates
    out, integral = pi.step(integral, -1.0, 0.001)
    assert out == pytest.approx(-0.101)  # reverses at once, nothing to unwind


def test_pi_integrates_to_the_limit_only() -> None:
    pi = SpeedPi(0.0, 10.0, 5.0)
    integral = 0.0
    for _ in range(100):
        out, integral = pi.step(integral, 1.0, 0.1)
    assert out == integral == 5.0
    assert pi.step(integral, -1.0, 0.1)[1] == pytest.approx(4.0)


def test_pi_non_finite_error_gives_zero() -> None:
    assert SpeedPi(0.1, 1.0, 20.0).step(3.0, math.nan, 0.001) == (0.0, 0.0)


def _clip(value: float, limit: float) -> float:
    return min(max(value, -limit), limit)


def _reference_step(
    pi: SpeedPi, integral_a: float, error: float, dt: float
) -> tuple[float, float]:
    """The control law of drivers.dji.pi as its docstring states it, with min / max."""
    lim = pi.limit_a
    p = pi.kp_a_per_rad_s * error
    integral = _clip(integral_a + pi.ki_a_per_rad * error * max(dt, 0.0), lim)
    if (p + integral > lim and error > 0.0) or (p + integral < -lim and error < 0.0):
        integral = _clip(integral_a, lim)  # conditional integration
    return _clip(p + integral, lim), integral


@given(
    st.floats(-30.0, 30.0),
    st.floats(-1e4, 1e4),
    st.floats(-0.01, 0.1),
    st.floats(0.0, 10.0),
    st.floats(0.0, 100.0),
    st.floats(0.1, 20.0),
)
def test_pi_step_is_the_stated_law(
    integral: float, err: float, dt: float, kp: float, ki: float, limit: float
) -> None:
    pi = SpeedPi(kp, ki, limit)
    assert pi.step(integral, err, dt) == _reference_step(pi, integral, err, dt)


@given(
    st.floats(-10.0, 10.0),
    st.floats(-1e4, 1e4),
    st.floats(0.0, 0.1),
    st.floats(0.0, 10.0),
    st.floats(0.0, 100.0),
)
def test_pi_output_within_limit(
    integral: float, err: float, dt: float, kp: float, ki: float
) -> None:
    pi = SpeedPi(kp, ki, 10.0)
    out, new_integral = pi.step(integral, err, dt)
    assert abs(out) <= 10.0 and abs(new_integral) <= 10.0
