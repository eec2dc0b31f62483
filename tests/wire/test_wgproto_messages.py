"""Tests of wheelgate's own CAN messages against ``config/wheelgate.dbc``: the DBC itself, golden
bytes, and the cross-check of :mod:`gateway.wire.can` with cantools.

Golden payloads are packed by hand with ``struct`` (and written out in hex) from the layout in
the DBC; cantools, loading the DBC with ``strict=True``, must produce the same bytes and read
back the same values.  Hypothesis then checks the codec and cantools against each other on
random payloads (our decode, cantools encode) and random physical values (our encode, cantools
decode), which pins every signal's position, length, sign and scale.
"""

from __future__ import annotations

import math
import struct
import warnings

import cantools
import pytest
from hypothesis import given
from hypothesis import strategies as st

from gateway.core.kinematics.odometry import Pose
from gateway.core.types import ConstraintCode, ErrorCode, Frame, GatewayState, Twist
from gateway.wire.can import (
    NO_WHEEL,
    CanIds,
    ErrorReport,
    OdomVelocity,
    StatusFlags,
    StatusReport,
    TwistCommand,
    TwistFlags,
    WgMessage,
)
from tests.wire.wgproto_helpers import (
    CODEC,
    DBC,
    MESSAGES,
    MM,
    SETTINGS,
    cantools_decode,
    message,
    signals,
)


def cross_check(frame: Frame, name: str) -> WgMessage:
    """Decode ``frame`` with the codec; cantools must read the same values and re-encode it."""
    decoded = CODEC.decode(frame)
    assert decoded is not None
    values = signals(decoded)
    msg = message(name)
    assert cantools_decode(name, frame.data) == values
    assert msg.encode(values, strict=True) == frame.data
    return decoded


# ---------------------------------------------------------------------------- the DBC


def test_dbc_loads_strict_without_warnings() -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        db = cantools.database.load_file(DBC, strict=True)
    assert isinstance(db, cantools.database.can.Database)
    assert [n.name for n in db.nodes] == ["WHEELGATE", "CONTROLLER"]
    assert all(n.comment for n in db.nodes)
    assert [m.name for m in db.messages] == list(MESSAGES)
    defaults = CanIds()
    for msg in db.messages:
        assert msg.frame_id == getattr(defaults, MESSAGES[msg.name])
        assert (msg.length, msg.is_extended_frame) == (8, False)
        controller_sends = msg.name == "WG_Twist_Cmd"
        assert msg.senders == (["CONTROLLER"] if controller_sends else ["WHEELGATE"])
        assert msg.comment, msg.name
        for sig in msg.signals:
            assert sig.byte_order == "little_endian"
            assert sig.comment, f"{msg.name}.{sig.name}"
            assert sig.receivers == (["WHEELGATE"] if controller_sends else ["CONTROLLER"])
            if sig.scale != 1:
                assert sig.unit in ("m", "m/s", "rad", "rad/s"), f"{msg.name}.{sig.name}"


@pytest.mark.parametrize(
    ("name", "signal", "expected"),
    [
        ("WG_Status", "State", {m.value: m.name for m in GatewayState}),
        ("WG_Error", "Code", {m.value: m.name for m in ErrorCode}),
        ("WG_Error", "Constraint", {m.value: m.name for m in ConstraintCode}),
        ("WG_Error", "Wheel", {NO_WHEEL: "NONE"}),
    ],
)
def test_dbc_value_tables_match_the_enums(name: str, signal: str, expected: dict[int, str]) -> None:
    choices = message(name).get_signal_by_name(signal).choices
    assert choices is not None
    assert {k: str(v) for k, v in choices.items()} == expected


# ---------------------------------------------------------------------------- golden bytes


GOLDEN: list[tuple[str, WgMessage, bytes, str]] = [
    (
        "WG_Twist_Cmd",
        TwistCommand(Twist(1.0, -0.5, 0.25), 7, TwistFlags.ENABLE),
        struct.pack("<hhhBB", 1000, -500, 250, 7, 0x02),
        "e8030cfefa000702",
    ),
    (
        "WG_Twist_Cmd",
        TwistCommand(Twist(-32.768, 32.767, -0.001), 255, TwistFlags.ESTOP | TwistFlags.STOP),
        struct.pack("<hhhBB", -32768, 32767, -1, 255, 0x05),
        "0080ff7fffffff05",
    ),
    (
        "WG_Odom_Pose",
        Pose(1.0, -2.0, 0.5),
        # x = 1000 mm and y = -2000 mm as 24-bit two's complement, theta = 5000 x 0.1 mrad
        (1000).to_bytes(3, "little") + (2**24 - 2000).to_bytes(3, "little")
        + struct.pack("<h", 5000),
        "e8030030f8ff8813",
    ),
    (
        "WG_Odom_Pose",
        Pose(-8388.608, 8388.607, -3.1415),
        (2**23).to_bytes(3, "little") + (2**23 - 1).to_bytes(3, "little")
        + struct.pack("<h", -31415),
        "000080ffff7f4985",
    ),
    (
        "WG_Odom_Velocity",
        OdomVelocity(Twist(0.3, 0.0, -1.2), 0.045),
        struct.pack("<hhhH", 300, 0, -1200, 45),
        "2c01000050fb2d00",
    ),
    (
        "WG_Status",
        StatusReport(GatewayState.RUNNING, 0b101, 42, StatusFlags.SPEED_LIMITED
                     | StatusFlags.BUS_ERRORS_RECENT, 3, 513),
        struct.pack("<BBBBHH", 2, 0b101, 42, 0x0A, 3, 513),
        "02052a0a03000102",
    ),
    (
        "WG_Error",
        ErrorReport(ErrorCode.INFEASIBLE_TWIST, 2, ConstraintCode.SLIDING, 9, 0.125, 17),
        struct.pack("<BBBBHH", 1, 2, 1, 9, 125, 17),
        "010201097d001100",
    ),
    (
        "WG_Error",
        ErrorReport(ErrorCode.COMMAND_TIMEOUT),
        struct.pack("<BBBBHH", 7, 0xFF, 0, 0xFF, 0, 0),
        "07ff00ff00000000",
    ),
]  # fmt: skip


def encode(value: WgMessage) -> Frame:
    if isinstance(value, TwistCommand):
        return CODEC.encode_twist(value)
    if isinstance(value, Pose):
        return CODEC.encode_pose(value)
    if isinstance(value, OdomVelocity):
        return CODEC.encode_velocity(value.twist, value.slip_m_s)
    if isinstance(value, StatusReport):
        return CODEC.encode_status(value)
    return CODEC.encode_error(value)


@pytest.mark.parametrize(("name", "value", "packed", "hex_"), GOLDEN)
def test_golden_bytes(name: str, value: WgMessage, packed: bytes, hex_: str) -> None:
    assert packed == bytes.fromhex(hex_)
    can_id = getattr(CanIds(), MESSAGES[name])
    frame = encode(value)
    assert frame == Frame(can_id, packed)
    assert message(name).encode(signals(value), strict=True) == packed  # the same via cantools
    assert cross_check(frame, name) == value


def test_decode_dispatches_on_the_id_and_ignores_other_frames() -> None:
    for name, value, packed, _ in GOLDEN:
        assert CODEC.decode(Frame(getattr(CanIds(), MESSAGES[name]), packed)) == value
    assert CODEC.decode(Frame(0x105, bytes(8))) is None
    assert CODEC.decode(Frame(0x100, bytes(8), is_extended_id=True)) is None
    for decoder in (CODEC.decode_pose, CODEC.decode_velocity, CODEC.decode_status):
        assert decoder(Frame(0x104, bytes(8))) is None
    assert CODEC.decode_error(Frame(0x100, bytes(8))) is None


# ---------------------------------------------------------------------------- cantools cross-check


BYTES8 = st.binary(min_size=8, max_size=8)


def _with(data: bytes, **fields: int) -> bytes:
    out = bytearray(data)
    for index, value in fields.items():
        out[int(index[1:])] = value
    return bytes(out)


@SETTINGS
@given(data=BYTES8)
def test_random_payloads_read_the_same_in_cantools(data: bytes) -> None:
    # Reserved bits cleared and enums valid: every such payload is a well-formed message.
    cross_check(Frame(0x100, _with(data, b7=data[7] & 0x07)), "WG_Twist_Cmd")
    cross_check(Frame(0x101, data), "WG_Odom_Pose")
    cross_check(Frame(0x102, data), "WG_Odom_Velocity")
    state = data[0] % len(GatewayState)
    cross_check(Frame(0x103, _with(data, b0=state, b3=data[3] & 0x0F)), "WG_Status")
    code, constraint = data[0] % len(ErrorCode), data[2] % len(ConstraintCode)
    cross_check(Frame(0x104, _with(data, b0=code, b2=constraint)), "WG_Error")


SPEED = st.floats(-32.768, 32.767)
U16 = st.integers(0, 0xFFFF)
U8 = st.integers(0, 0xFF)


def _assert_within_half_lsb(got: dict[str, float], sent: dict[str, float], name: str) -> None:
    for sig in message(name).signals:
        assert abs(got[sig.name] - sent[sig.name]) <= sig.scale / 2 + 1e-9, sig.name


@SETTINGS
@given(vx=SPEED, vy=SPEED, wz=SPEED, counter=U8, flags=st.integers(0, 7))
def test_twist_round_trip_and_cantools(
    vx: float, vy: float, wz: float, counter: int, flags: int
) -> None:
    sent = TwistCommand(Twist(vx, vy, wz), counter, TwistFlags(flags))
    frame = CODEC.encode_twist(sent)
    got = cross_check(frame, "WG_Twist_Cmd")
    _assert_within_half_lsb(signals(got), signals(sent), "WG_Twist_Cmd")
    assert message("WG_Twist_Cmd").encode(signals(sent), strict=True) == frame.data


@SETTINGS
@given(
    x=st.floats(-8388.608, 8388.607),
    y=st.floats(-8388.608, 8388.607),
    theta=st.floats(-math.pi, math.pi),
)
def test_pose_round_trip_and_cantools(x: float, y: float, theta: float) -> None:
    sent = Pose(x, y, theta)
    frame = CODEC.encode_pose(sent)
    got = cross_check(frame, "WG_Odom_Pose")
    _assert_within_half_lsb(signals(got), signals(sent), "WG_Odom_Pose")
    assert message("WG_Odom_Pose").encode(signals(sent), strict=True) == frame.data


@SETTINGS
@given(vx=SPEED, vy=SPEED, wz=SPEED, slip=st.floats(0.0, 65.535))
def test_velocity_round_trip_and_cantools(vx: float, vy: float, wz: float, slip: float) -> None:
    sent = OdomVelocity(Twist(vx, vy, wz), slip)
    frame = CODEC.encode_velocity(sent.twist, slip)
    got = cross_check(frame, "WG_Odom_Velocity")
    _assert_within_half_lsb(signals(got), signals(sent), "WG_Odom_Velocity")
    assert message("WG_Odom_Velocity").encode(signals(sent), strict=True) == frame.data


@SETTINGS
@given(
    state=st.sampled_from(GatewayState),
    mask=U8,
    counter=U8,
    flags=st.integers(0, 15),
    missed=U16,
    infeasible=U16,
)
def test_status_round_trip_and_cantools(
    state: GatewayState, mask: int, counter: int, flags: int, missed: int, infeasible: int
) -> None:
    sent = StatusReport(state, mask, counter, StatusFlags(flags), missed, infeasible)
    frame = CODEC.encode_status(sent)
    assert cross_check(frame, "WG_Status") == sent
    assert message("WG_Status").encode(signals(sent), strict=True) == frame.data


@SETTINGS
@given(
    code=st.sampled_from(ErrorCode),
    wheel=U8,
    constraint=st.sampled_from(ConstraintCode),
    twist_counter=U8,
    residual=st.floats(0.0, 65.535),
    count=U16,
)
def test_error_round_trip_and_cantools(
    code: ErrorCode,
    wheel: int,
    constraint: ConstraintCode,
    twist_counter: int,
    residual: float,
    count: int,
) -> None:
    sent = ErrorReport(code, wheel, constraint, twist_counter, residual, count)
    frame = CODEC.encode_error(sent)
    got = cross_check(frame, "WG_Error")
    assert isinstance(got, ErrorReport)
    assert got == ErrorReport(code, wheel, constraint, twist_counter, got.residual_m_s, count)
    assert abs(got.residual_m_s - residual) <= MM / 2 + 1e-9
    assert message("WG_Error").encode(signals(sent), strict=True) == frame.data
