"""Properties of the ROS 2 CDR codecs: round trips, and decoders that fail only one way.

No other implementation here (``test_ros2_cdr_pycdr2.py`` has those): any message survives
encode then decode, NaN and infinities included, and no input at all, random or a valid
payload damaged, makes a decoder raise anything but :class:`DecodeError`.
"""

from __future__ import annotations

import math
import struct
from typing import TYPE_CHECKING

import pytest
from hypothesis import given
from hypothesis import strategies as st

from gateway.core.errors import DecodeError
from gateway.wire.ros2 import (
    Header,
    Odometry,
    Quaternion,
    TFMessage,
    Time,
    TransformStamped,
    Twist3D,
    TwistStamped,
    Vector3,
    decode_attachment,
    decode_odometry,
    decode_tf_message,
    decode_twist,
    decode_twist_stamped,
    encode_odometry,
    encode_tf_message,
    encode_twist,
    encode_twist_stamped,
)

if TYPE_CHECKING:
    from collections.abc import Callable

FLOATS = st.floats(width=64)  # NaN and infinities too
NAMES = st.text(st.characters(exclude_categories=["Cs"], exclude_characters="\0"),
                max_size=12)
HEADERS = st.builds(Header, st.builds(Time, st.integers(-(2**31), 2**31 - 1),
                                      st.integers(0, 10**9 - 1)), NAMES)
TWISTS = st.builds(Twist3D, FLOATS, FLOATS, FLOATS, FLOATS, FLOATS, FLOATS)
VECTORS = st.builds(Vector3, FLOATS, FLOATS, FLOATS)
QUATERNIONS = st.builds(Quaternion, FLOATS, FLOATS, FLOATS, FLOATS)
COVARIANCES = st.lists(FLOATS, min_size=36, max_size=36).map(tuple)
TRANSFORMS = st.builds(TransformStamped, HEADERS, NAMES, VECTORS, QUATERNIONS)

CODECS: list[tuple[st.SearchStrategy[object], Callable[[object], bytes],
                   Callable[[bytes], object]]] = [
    (TWISTS, encode_twist, decode_twist),  # type: ignore[list-item]
    (st.builds(TwistStamped, HEADERS, TWISTS), encode_twist_stamped,  # type: ignore[list-item]
     decode_twist_stamped),
    (st.builds(Odometry, HEADERS, NAMES, VECTORS, QUATERNIONS, COVARIANCES, TWISTS,  # type: ignore[list-item]
               COVARIANCES), encode_odometry, decode_odometry),
    (st.builds(TFMessage, st.lists(TRANSFORMS, max_size=3).map(tuple)),  # type: ignore[list-item]
     encode_tf_message, decode_tf_message),
]
IDS = ["Twist", "TwistStamped", "Odometry", "TFMessage"]
DECODERS = [decode for _, _, decode in CODECS]


def same(a: object, b: object) -> bool:
    """Equality that holds NaN equal to NaN (compares the encoded bytes of floats)."""
    if isinstance(a, float) and isinstance(b, float):
        return struct.pack("<d", a) == struct.pack("<d", b)
    if isinstance(a, tuple) and isinstance(b, tuple):
        return len(a) == len(b) and all(same(x, y) for x, y in zip(a, b, strict=True))
    slots = getattr(type(a), "__slots__", None)
    if slots is not None and type(a) is type(b):
        return all(same(getattr(a, s), getattr(b, s)) for s in slots)
    return a == b


@pytest.mark.parametrize(("messages", "encode", "decode"), CODECS, ids=IDS)
def test_any_message_survives_a_round_trip(
        messages: st.SearchStrategy[object], encode: Callable[[object], bytes],
        decode: Callable[[bytes], object]) -> None:
    @given(messages)
    def check(message: object) -> None:
        payload = encode(message)
        assert same(decode(payload), message)
        assert encode(decode(payload)) == payload

    check()


def test_same_tells_nan_apart_from_numbers() -> None:
    assert same(Twist3D(math.nan), Twist3D(math.nan))
    assert not same(Twist3D(math.nan), Twist3D(0.0))


def expect_only_decode_errors(decode: Callable[[bytes], object], data: bytes) -> None:
    try:
        decode(data)
    except DecodeError:
        pass


@pytest.mark.parametrize("decode", DECODERS, ids=IDS)
def test_arbitrary_bytes_raise_only_decode_errors(decode: Callable[[bytes], object]) -> None:
    @given(st.one_of(st.binary(max_size=200),
                     st.binary(max_size=200).map(lambda b: b"\x00\x01\x00\x00" + b)))
    def check(data: bytes) -> None:
        expect_only_decode_errors(decode, data)

    check()


@st.composite
def damaged(draw: st.DrawFn, payload: bytes) -> bytes:
    """``payload`` with some bytes overwritten, cut off or added."""
    data = bytearray(payload)
    for _ in range(draw(st.integers(1, 4))):
        kind = draw(st.sampled_from(["set", "cut", "add", "u32"]))
        at = draw(st.integers(0, max(0, len(data) - 1)))
        if kind == "set" and data:
            data[at] = draw(st.integers(0, 255))
        elif kind == "cut":
            del data[at:at + draw(st.integers(1, 8))]
        elif kind == "add":
            data[at:at] = draw(st.binary(min_size=1, max_size=8))
        elif len(data) >= at + 4:  # a plausible or absurd length
            value = draw(st.sampled_from([0, 1, 2, 3, 7, 255, 2**31, 2**32 - 1]))
            data[at:at + 4] = value.to_bytes(4, "little")
    return bytes(data)


@pytest.mark.parametrize(("messages", "encode", "decode"), CODECS, ids=IDS)
def test_damaged_payloads_raise_only_decode_errors(
        messages: st.SearchStrategy[object], encode: Callable[[object], bytes],
        decode: Callable[[bytes], object]) -> None:
    @given(messages.map(encode).flatmap(damaged))
    def check(data: bytes) -> None:
        expect_only_decode_errors(decode, data)

    check()


def test_arbitrary_attachments_raise_only_decode_errors() -> None:
    @given(st.one_of(st.binary(max_size=90), st.binary(min_size=33, max_size=33),
                     st.binary(min_size=77, max_size=77)))
    def check(data: bytes) -> None:
        expect_only_decode_errors(decode_attachment, data)

    check()
