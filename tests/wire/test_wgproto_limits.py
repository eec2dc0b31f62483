"""Tests of wheelgate's own CAN messages (:mod:`gateway.wire.can`) at their limits: saturation and
wrap, malformed frames, ``encode_twist``'s checks, configured CAN IDs and the twist counter."""

from __future__ import annotations

import math
import struct

import cantools
import pytest
from hypothesis import given
from hypothesis import strategies as st

from gateway.core.errors import ConfigError, DecodeError, EncodeError
from gateway.core.kinematics.odometry import Pose
from gateway.core.types import ConstraintCode, ErrorCode, Frame, GatewayState, Twist
from gateway.wire.can import (
    ID_KEYS,
    NO_TWIST_COUNTER,
    NO_WHEEL,
    POSITION_WRAP_M,
    CanIds,
    CounterKind,
    CounterTracker,
    ErrorReport,
    OdomVelocity,
    StatusFlags,
    StatusReport,
    TwistCommand,
    TwistFlags,
    WgCodec,
    classify_counter,
    unwrap_position_m,
)
from tests.wire.wgproto_helpers import (
    CODEC,
    MESSAGES,
    MM,
    SETTINGS,
    cantools_decode,
    message,
    signals,
)

# ---------------------------------------------------------------------------- saturation and wrap


def _velocity(twist: Twist, slip: float) -> OdomVelocity:
    decoded = CODEC.decode_velocity(CODEC.encode_velocity(twist, slip))
    assert decoded is not None
    return decoded


@pytest.mark.parametrize(
    ("value", "expected", "negated"),
    [(1e9, 32.767, -32.768), (math.inf, 32.767, -32.768), (math.nan, 0.0, 0.0),
     (32.7674, 32.767, -32.767), (32.7684, 32.767, -32.768), (1e308, 32.767, -32.768),
     (-32.7676, -32.768, 32.767)],
)  # fmt: skip
def test_velocity_saturates_instead_of_raising(
    value: float, expected: float, negated: float
) -> None:
    got = _velocity(Twist(value, -value, value), 0.0).twist
    assert (got.vx_m_s, got.vy_m_s, got.wz_rad_s) == (expected, negated, expected)


@pytest.mark.parametrize(
    ("slip", "expected"),
    [(1e9, 65.535), (math.inf, 65.535), (math.nan, 65.535), (65.5356, 65.535), (-1.0, 0.0),
     (-math.inf, 0.0), (65.534, 65.534)],
)  # fmt: skip
def test_slip_saturates_at_least_max(slip: float, expected: float) -> None:
    assert _velocity(Twist(), slip).slip_m_s == pytest.approx(expected)


def _pose(pose: Pose) -> Pose:
    decoded = CODEC.decode_pose(CODEC.encode_pose(pose))
    assert decoded is not None
    return decoded


@pytest.mark.parametrize(
    ("x", "wire"),
    [(8388.607, 8388.607), (8388.608, -8388.608), (10000.0, 10000.0 - 16777.216),
     (-8388.609, 8388.607), (16777.216, 0.0), (-20000.5, -20000.5 + 16777.216),
     (-30000.0, -30000.0 + 2 * 16777.216),
     (1e12, 1e12 - round(1e12 / 16777.216) * 16777.216), (1e308, 0.0), (math.inf, 0.0),
     (math.nan, 0.0)],
)  # fmt: skip
def test_pose_position_wraps_modulo_2_pow_24_without_raising(x: float, wire: float) -> None:
    frame = CODEC.encode_pose(Pose(x, x, 0.0))
    got = _pose(Pose(x, x, 0.0))
    assert got.x_m == pytest.approx(wire, abs=1e-3) and got.y_m == got.x_m
    assert cantools_decode("WG_Odom_Pose", frame.data)["X"] == got.x_m  # cantools reads it so


@SETTINGS
@given(start=st.floats(-1e6, 1e6), step=st.floats(-100.0, 100.0))
def test_receivers_unwrap_the_pose(start: float, step: float) -> None:
    previous = unwrap_position_m(start, _pose(Pose(start, 0.0, 0.0)).x_m)
    assert previous == pytest.approx(start, abs=MM)
    following = unwrap_position_m(previous, _pose(Pose(start + step, 0.0, 0.0)).x_m)
    assert following == pytest.approx(start + step, abs=MM)


def test_unwrap_crosses_the_wrap_both_ways() -> None:
    assert POSITION_WRAP_M == pytest.approx(16777.216)
    assert unwrap_position_m(8388.0, -8388.216) == pytest.approx(8389.0)
    assert unwrap_position_m(-8388.0, 8388.216) == pytest.approx(-8389.0)
    assert unwrap_position_m(0.0, 0.5) == 0.5


@pytest.mark.parametrize(
    ("theta", "expected"),
    [(4.0, 4.0 - 2 * math.pi), (-4.0, 2 * math.pi - 4.0), (3 * math.pi, math.pi),
     (2 * math.pi + 0.25, 0.25), (math.inf, 0.0), (math.nan, 0.0)],
)  # fmt: skip
def test_pose_heading_wraps_to_pi(theta: float, expected: float) -> None:
    assert abs(_pose(Pose(0.0, 0.0, theta)).theta_rad) <= 3.1416
    got = _pose(Pose(0.0, 0.0, theta)).theta_rad
    assert math.remainder(got - expected, 2 * math.pi) == pytest.approx(0.0, abs=1e-4)


def test_status_saturates_wraps_and_folds() -> None:
    report = StatusReport(GatewayState.FAULT, 0x1_05, 300, StatusFlags(0x3F), 70_000, -5)
    got = CODEC.decode_status(CODEC.encode_status(report))
    assert got == StatusReport(GatewayState.FAULT, 0x85, 300 - 256, StatusFlags(0x0F), 0xFFFF, 0)
    assert got.faulted_wheels() == (0, 2, 7)
    assert StatusReport(GatewayState.RUNNING).faulted_wheels() == ()
    folded = CODEC.decode_status(CODEC.encode_status(StatusReport(GatewayState.FAULT, 1 << 9)))
    assert folded is not None and folded.faulted_motors == 0x80
    negative = CODEC.decode_status(CODEC.encode_status(StatusReport(GatewayState.FAULT, -1)))
    assert negative is not None and negative.faulted_motors == 0


def test_error_saturates_and_count_wraps() -> None:
    report = ErrorReport(ErrorCode.MOTOR_FAULT, 300, ConstraintCode.NONE, 256, 1e9, 65_536 + 5)
    got = CODEC.decode_error(CODEC.encode_error(report))
    assert got == ErrorReport(ErrorCode.MOTOR_FAULT, NO_WHEEL, ConstraintCode.NONE,
                              NO_TWIST_COUNTER, 65.535, 5)  # fmt: skip
    for residual, expected in ((math.nan, 65.535), (-0.5, 0.0), (math.inf, 65.535)):
        report = ErrorReport(ErrorCode.INFEASIBLE_TWIST, -1, residual_m_s=residual)
        got = CODEC.decode_error(CODEC.encode_error(report))
        assert got is not None
        assert got.wheel == NO_WHEEL
        assert got.residual_m_s == pytest.approx(expected)


# ---------------------------------------------------------------------------- malformed frames


@pytest.mark.parametrize("length", [0, 1, 6, 7])
@pytest.mark.parametrize("name", list(MESSAGES))
def test_wrong_dlc_is_a_decode_error(name: str, length: int) -> None:
    can_id = getattr(CanIds(), MESSAGES[name])
    with pytest.raises(DecodeError) as err:
        CODEC.decode(Frame(can_id, bytes(length)))
    assert str(err.value) == (
        f"Expected 8 data bytes in {name} (ID {can_id:#x}), but got {length}."
    )


@pytest.mark.parametrize("name", list(MESSAGES))
def test_remote_frame_is_a_decode_error(name: str) -> None:
    can_id = getattr(CanIds(), MESSAGES[name])
    with pytest.raises(DecodeError) as err:
        CODEC.decode(Frame(can_id, is_remote_frame=True, dlc=8))
    assert str(err.value) == (
        f"Expected a data frame for {name} (ID {can_id:#x}), but got a remote frame."
    )


def test_twist_frames_of_the_other_id_type_are_not_ours() -> None:
    data = CODEC.encode_twist(TwistCommand(Twist(1.0), 1)).data
    assert CODEC.decode_twist(Frame(0x100, data, is_extended_id=True)) is None
    assert CODEC.decode_twist(Frame(0x101, data)) is None
    extended = WgCodec(CanIds(extended=True))
    assert extended.decode_twist(Frame(0x100, data)) is None
    got = extended.decode_twist(Frame(0x100, data, is_extended_id=True))
    assert got == TwistCommand(Twist(1.0), 1)
    assert extended.encode_twist(TwistCommand(Twist(1.0), 1)).is_extended_id


@pytest.mark.parametrize("bit", range(3, 8))
def test_twist_reserved_flag_bits_are_a_decode_error(bit: int) -> None:
    data = struct.pack("<hhhBB", 0, 0, 0, 0, 1 << bit | 0x02)
    with pytest.raises(DecodeError) as err:
        CODEC.decode_twist(Frame(0x100, data))
    assert str(err.value) == (
        f"Expected WG_Twist_Cmd (ID 0x100) flags within 0x07, but got {1 << bit | 0x02:#04x} "
        f"(reserved bits {1 << bit:#04x} set)."
    )


@pytest.mark.parametrize(
    ("can_id", "data", "text"),
    [(0x103, bytes([6, 0, 0, 0, 0, 0, 0, 0]), '"State" in WG_Status to be one of 0 (DISABLED)'),
     (0x103, bytes([0, 0, 0, 0x10, 0, 0, 0, 0]), "WG_Status (ID 0x103) flags within 0x0f"),
     (0x104, bytes([max(ErrorCode) + 1, 0, 0, 0, 0, 0, 0, 0]),
      '"Code" in WG_Error to be one of 0 (NONE)'),
     (0x104, bytes([0, 0, 4, 0, 0, 0, 0, 0]), "but got 4.")],
)  # fmt: skip
def test_bad_status_and_error_values_are_decode_errors(can_id: int, data: bytes, text: str) -> None:
    with pytest.raises(DecodeError, match="Expected") as err:
        CODEC.decode(Frame(can_id, data))
    assert text in str(err.value)


# ---------------------------------------------------------------------------- encode_twist checks


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf, 32.768, -32.769, 1e300])
@pytest.mark.parametrize(
    ("component", "signal", "unit"), [(0, "Vx", "m/s"), (1, "Vy", "m/s"), (2, "Wz", "rad/s")]
)
def test_encode_twist_rejects_out_of_range_and_non_finite(
    bad: float, component: int, signal: str, unit: str
) -> None:
    values = [0.0, 0.0, 0.0]
    values[component] = bad
    with pytest.raises(EncodeError) as err:
        CODEC.encode_twist(TwistCommand(Twist(*values), 0))
    assert str(err.value) == (
        f'Expected "{signal}" in WG_Twist_Cmd between -32.768 and 32.767 {unit}, but got {bad!r}.'
    )


def test_encode_twist_rejects_bad_counter_and_flags() -> None:
    for counter in (-1, 256):
        with pytest.raises(EncodeError, match=rf'"Counter" .* but got {counter}\.'):
            CODEC.encode_twist(TwistCommand(Twist(), counter))
    with pytest.raises(EncodeError, match=r"flags within 0x07 .* but got 0x0a\."):
        CODEC.encode_twist(TwistCommand(Twist(), 0, TwistFlags(0x0A)))


@SETTINGS
@given(value=st.floats(-32.78, 32.78))
def test_encode_twist_raises_exactly_when_cantools_does(value: float) -> None:
    values = signals(TwistCommand(Twist(value, 0.0, 0.0), 0))
    try:
        expected = message("WG_Twist_Cmd").encode(values, strict=True)
    except cantools.database.EncodeError:
        with pytest.raises(EncodeError):
            CODEC.encode_twist(TwistCommand(Twist(value, 0.0, 0.0), 0))
    else:
        assert CODEC.encode_twist(TwistCommand(Twist(value, 0.0, 0.0), 0)).data == expected


# ---------------------------------------------------------------------------- CAN IDs


def test_can_ids_defaults_and_from_mapping() -> None:
    assert [getattr(CanIds(), key) for key in ID_KEYS] == [0x100, 0x101, 0x102, 0x103, 0x104]
    ids = CanIds.from_mapping({"twist": 0x200, "extended": True})
    assert (ids.twist, ids.status, ids.extended) == (0x200, 0x103, True)
    with pytest.raises(ConfigError, match=r"gateway\.can_ids: expected keys twist, .*got 'pose'"):
        CanIds.from_mapping({"pose": 1})
    assert CanIds(error=0x7FF).error == 0x7FF
    assert CanIds(status=0x1FFFFFFF, extended=True).status == 0x1FFFFFFF


@pytest.mark.parametrize(
    ("kwargs", "message_"),
    [({"status": 0x800}, "gateway.can_ids.status: expected a 11-bit CAN ID between 0x0 and "
      "0x7ff, got 2048"),
     ({"error": 0x20000000, "extended": True}, "gateway.can_ids.error: expected a 29-bit CAN ID "
      "between 0x0 and 0x1fffffff, got 536870912"),
     ({"twist": -1}, "gateway.can_ids.twist: expected a 11-bit CAN ID between 0x0 and 0x7ff, "
      "got -1"),
     ({"odom_pose": True}, "gateway.can_ids.odom_pose: expected a 11-bit CAN ID between 0x0 and "
      "0x7ff, got True"),
     ({"odom_pose": "0x101"}, "gateway.can_ids.odom_pose: expected a 11-bit CAN ID between 0x0 "
      "and 0x7ff, got '0x101'"),
     ({"error": 0x100}, "gateway.can_ids.error: expected an ID no other message uses, got 0x100 "
      "(also twist)"),
     ({"status": 0x102}, "gateway.can_ids.status: expected an ID no other message uses, got "
      "0x102 (also odom_velocity)"),
     ({"extended": 1}, "gateway.can_ids.extended: expected a bool, got 1")],
)  # fmt: skip
def test_can_ids_validation(kwargs: dict[str, object], message_: str) -> None:
    with pytest.raises(ConfigError) as err:
        CanIds(**kwargs)  # type: ignore[arg-type]
    assert str(err.value) == message_


def test_codec_uses_configured_ids() -> None:
    ids = CanIds(0x300, 0x310, 0x320, 0x330, 0x340)
    codec = WgCodec(ids)
    assert codec.encode_pose(Pose()).arbitration_id == 0x310
    assert codec.encode_velocity(Twist(), 0.0).arbitration_id == 0x320
    assert codec.encode_status(StatusReport(GatewayState.DISABLED)).arbitration_id == 0x330
    assert codec.encode_error(ErrorReport(ErrorCode.ESTOP)).arbitration_id == 0x340
    frame = codec.encode_twist(TwistCommand(Twist(0.1), 3))
    assert frame.arbitration_id == 0x300 and codec.decode(frame) == TwistCommand(Twist(0.1), 3)
    assert codec.decode(Frame(0x100, frame.data)) is None


# ---------------------------------------------------------------------------- counters


def test_classify_counter_exhaustively() -> None:
    for counter in range(256):
        assert classify_counter(None, counter) == (CounterKind.NEW, 0)
    for last in range(256):
        for counter in range(256):
            verdict, lost = classify_counter(last, counter)
            ahead = (counter - last) % 256  # 1: next, 0: repeat, k: k - 1 frames missing
            if ahead == 1:
                assert (verdict, lost) == (CounterKind.NEW, 0)
            elif ahead == 0:
                assert (verdict, lost) == (CounterKind.DUPLICATE, 0)
            else:
                assert (verdict, lost) == (CounterKind.JUMP, ahead - 1)
                assert 1 <= lost <= 254


def test_counter_tracker_sequence() -> None:
    tracker = CounterTracker()
    new, dup, jump = CounterKind.NEW, CounterKind.DUPLICATE, CounterKind.JUMP
    fed = [(254, new, 0), (255, new, 0), (0, new, 0), (0, dup, 0), (0, dup, 0), (1, new, 0),
           (5, jump, 3), (4, jump, 254), (5, new, 0)]  # fmt: skip
    assert [tracker.feed(c) for c, _, _ in fed] == [(k, lost) for _, k, lost in fed]
    assert (tracker.last, tracker.duplicates, tracker.lost_frames) == (5, 2, 3 + 254)
    tracker.reset()
    assert tracker.last is None
    assert tracker.feed(5) == (new, 0)  # after a reset, even a repeat counts as new
    assert tracker.lost_frames == 257
    for bad in (-1, 256):
        with pytest.raises(DecodeError, match=rf"between 0 and 255, but got {bad}\."):
            tracker.feed(bad)
    assert tracker.last == 5
