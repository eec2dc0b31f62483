"""Tests of the VESC codec (drivers/vesc/codec.py); the driver in ``test_drivers_vesc``.

Golden vectors: worked examples (VESC ID 23 = 0x17) built from vedderb/bldc ``comm/comm_can.c`` at
b9d287b3;
SET_CURRENT 51 A matches the example in the firmware's ``documentation/comm_can.md``.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import pytest
from hypothesis import given
from hypothesis import strategies as st

from drivers.vesc.codec import (
    COMMANDS,
    CanPacketId,
    HwType,
    VescCommand,
    VescPing,
    VescPong,
    VescStatus,
    VescStatus5,
    decode,
    decode_command,
    make_command,
    make_ping,
    make_pong,
    make_set_current,
    make_set_current_brake,
    make_set_rpm,
    make_status,
    make_status5,
    wrap_int32,
)
from gateway.core.errors import DecodeError, EncodeError
from gateway.core.types import Frame

if TYPE_CHECKING:
    from collections.abc import Callable

I32 = st.integers(-(2**31), 2**31 - 1)


def ext(eid: int, hexdata: str) -> Frame:
    return Frame(eid, bytes.fromhex(hexdata), is_extended_id=True)


# ============================================================================ codec: golden


@pytest.mark.parametrize(
    ("frame", "cansend"),
    [
        (make_set_rpm(23, 700), "00000317#000002BC"),  # 100 rpm at 7 pole pairs
        (make_set_rpm(23, -700), "00000317#FFFFFD44"),
        (make_set_current(23, 51.0), "00000117#0000C738"),  # comm_can.md example
        (make_set_current_brake(23, 10.0), "00000217#00002710"),
        (make_ping(23, 1), "00001117#01"),
        (make_status(23, 700, 12.3, 0.5), "00000917#000002BC007B01F4"),
        (make_status5(23, 4200, 24.5), "00001B17#0000106800F50000"),  # 100 revs at 7 pp
    ],
)
def test_golden_frames(frame: Frame, cansend: str) -> None:
    assert frame.is_extended_id
    assert frame.to_cansend() == cansend


def test_golden_decode() -> None:
    assert decode(ext(0x917, "000002BC007B01F4")) == VescStatus(23, 700, 12.3, 0.5)
    assert decode(ext(0x1B17, "0000106800F50000")) == VescStatus5(23, 4200, 24.5)
    assert decode_command(ext(0x317, "FFFFFD44")) == VescCommand(23, CanPacketId.SET_RPM, -700)
    assert decode_command(ext(0x117, "0000C738")) == VescCommand(23, CanPacketId.SET_CURRENT, 51.0)
    assert decode_command(ext(0x1117, "01")) == VescPing(23, 1)


def test_pong_goes_to_the_pinger() -> None:
    # decode_msg(): PONG to (18 << 8) | data[0] of the PING, payload [responder, HW_TYPE].
    assert make_pong(1, 23) == ext(0x1201, "1700")
    assert decode(ext(0x1201, "1700")) == VescPong(23, 1, HwType.VESC)
    assert decode(ext(0x1201, "17")) == VescPong(23, 1, HwType.VESC)  # 1 byte: HW_TYPE_VESC
    assert decode(ext(0x1201, "1702")) == VescPong(23, 1, HwType.CUSTOM_MODULE)


@given(node_id=st.integers(0, 255), erpm=I32)
def test_set_rpm_of_an_int_is_the_command_of_its_value(node_id: int, erpm: int) -> None:
    # make_set_rpm builds the frame of an int speed at once (every cycle): the same frame.
    assert make_set_rpm(node_id, erpm) == make_command(CanPacketId.SET_RPM, node_id, erpm * 1.0)


def test_wrap_int32() -> None:
    assert wrap_int32(2**31 - 1) == 2**31 - 1
    assert wrap_int32(2**31) == -(2**31)
    assert wrap_int32(-(2**31) - 1) == 2**31 - 1
    assert wrap_int32(-(2**31) - (2**31 - 1)) == 1  # 0x80000000 - 0x7FFFFFFF = +1 step


# ============================================================================ codec: round trips


@given(
    packet=st.sampled_from(sorted(COMMANDS)),
    node_id=st.integers(0, 255),
    fraction=st.floats(-1.0, 1.0),
)
def test_command_round_trip(packet: CanPacketId, node_id: int, fraction: float) -> None:
    field = COMMANDS[packet]
    value = fraction * (field.maximum if fraction > 0 else -field.minimum)
    got = decode_command(make_command(packet, node_id, value))
    assert isinstance(got, VescCommand)
    assert (got.node_id, got.packet) == (node_id, packet)
    assert abs(got.value - value) <= 0.5 / field.scale + abs(value) * 1e-15


@given(
    node_id=st.integers(0, 255),
    erpm=I32,
    current_a=st.floats(-3276.8, 3276.7),
    duty=st.floats(-32.768, 32.767),
)
def test_status_round_trip(node_id: int, erpm: int, current_a: float, duty: float) -> None:
    got = decode(make_status(node_id, erpm, current_a, duty))
    assert isinstance(got, VescStatus)
    assert (got.node_id, got.erpm) == (node_id, erpm)
    # Truncated toward zero, as the firmware's (int16_t) casts.
    assert round(got.current_a * 10) == math.trunc(current_a * 10)
    assert round(got.duty * 1000) == math.trunc(duty * 1000)


@given(node_id=st.integers(0, 255), tacho=I32, v_in=st.floats(-3276.8, 3276.7))
def test_status5_round_trip(node_id: int, tacho: int, v_in: float) -> None:
    got = decode(make_status5(node_id, tacho, v_in))
    assert isinstance(got, VescStatus5)
    assert (got.node_id, got.tachometer) == (node_id, tacho)
    assert round(got.v_in_v * 10) == math.trunc(v_in * 10)


def test_device_side_truncates_like_the_firmware() -> None:
    # comm_can_send_status1/5 (vedderb/bldc comm/comm_can.c) cast with (int32_t) and
    # (int16_t): toward zero, where rounding would give one LSB more (701, -13, 500, 246).
    assert make_status(23, 700.9, -1.29, 0.4999) == ext(0x917, "000002BCFFF401F3")
    assert make_status5(23, 0, 24.59) == ext(0x1B17, "0000000000F50000")


@given(to_id=st.integers(0, 255), node_id=st.integers(0, 255), hw=st.sampled_from(HwType))
def test_ping_pong_round_trip(to_id: int, node_id: int, hw: HwType) -> None:
    assert decode_command(make_ping(node_id, to_id)) == VescPing(node_id, to_id)
    assert decode(make_pong(to_id, node_id, hw)) == VescPong(node_id, to_id, hw)


# ============================================================================ codec: errors


def test_encode_error_message_names_entity_range_and_value() -> None:
    with pytest.raises(EncodeError) as err:
        make_set_rpm(23, math.nan)
    assert str(err.value) == (
        "Expected speed for VESC 23 between -2147483648 and 2147483647 eRPM, but got nan."
    )


@pytest.mark.parametrize(
    "call",
    [
        lambda: make_set_rpm(23, math.inf),
        lambda: make_set_rpm(23, -math.inf),
        lambda: make_set_rpm(23, 2.0**31),
        lambda: make_set_rpm(23, -(2.0**31) - 1),
        lambda: make_set_current(23, 2147484.0),
        lambda: make_set_current_brake(23, math.nan),
        lambda: make_set_rpm(256, 0.0),
        lambda: make_set_rpm(-1, 0.0),
        lambda: make_command(CanPacketId.SET_DUTY, 23, 0.5),  # not in the field table
        lambda: make_ping(23, 256),
        lambda: make_status(23, 0, 3300.0, 0.0),
        lambda: make_status(23, 2**31, 0.0, 0.0),
        lambda: make_status5(23, 0, math.nan),
        lambda: make_pong(300, 23),
    ],
)
def test_encode_rejects(call: Callable[[], Frame]) -> None:
    with pytest.raises(EncodeError):
        call()


@pytest.mark.parametrize(
    "frame",
    [
        ext(0x917, "000002BC007B01"),  # STATUS, DLC 7
        ext(0x917, ""),
        ext(0x1B17, "0000106800F5000000"),  # STATUS_5, DLC 9
        Frame(0x917, is_extended_id=True, is_remote_frame=True, dlc=8),  # no RTR in VESC
        Frame(0x1B17, is_extended_id=True, is_remote_frame=True, dlc=8),
        ext(0x1201, ""),  # PONG without payload
        ext(0x1201, "170000"),
    ],
)
def test_decode_rejects_malformed(frame: Frame) -> None:
    with pytest.raises(DecodeError):
        decode(frame)


@pytest.mark.parametrize(
    "frame",
    [
        ext(0x117, "00000000C738"),  # the inconsistent 6-byte SET_CURRENT form
        ext(0x317, "02BC"),
        Frame(0x317, is_extended_id=True, is_remote_frame=True, dlc=4),
        ext(0x1117, ""),
    ],
)
def test_decode_command_rejects_malformed(frame: Frame) -> None:
    with pytest.raises(DecodeError):
        decode_command(frame)


@pytest.mark.parametrize(
    ("parse", "frame"),
    [
        (decode, Frame(0x917, bytes(8))),  # standard IDs are never VESC frames
        (decode, ext(0x10917, "000002BC007B01F4")),  # bits above 15: packet 0x109 unknown
        (decode, ext(0x1017, "0000000000000000")),  # STATUS_4: not decoded
        (decode, ext(0x317, "000002BC")),  # a command, host to device
        (decode_command, Frame(0x317, bytes.fromhex("000002BC"))),
        (decode_command, ext(0x917, "000002BC007B01F4")),  # status, device to host
        (decode_command, ext(0x017, "00007A12")),  # SET_DUTY: not spoken here
    ],
)
def test_decode_ignores_foreign_frames(parse: Callable[[Frame], object], frame: Frame) -> None:
    assert parse(frame) is None
