"""The ROS 2 CDR codecs on literal golden bytes, and every way a payload can be wrong.

The golden payloads are written out by hand from the XCDR1 rules (header ``00 01 00 00``, each
field aligned to its size from the start of the body, strings with length and NUL), so these
tests need no other implementation; ``test_ros2_cdr_pycdr2.py`` checks against pycdr2.
"""

from __future__ import annotations

import math
import struct
from typing import TYPE_CHECKING

import pytest

from gateway.core.errors import DecodeError, EncodeError
from gateway.wire.ros2 import (
    TWIST_SIZE,
    Header,
    Odometry,
    Quaternion,
    TFMessage,
    Time,
    TransformStamped,
    Twist3D,
    TwistStamped,
    Vector3,
    decode_odometry,
    decode_tf_message,
    decode_twist,
    decode_twist_stamped,
    encode_odometry,
    encode_tf_message,
    encode_twist,
    encode_twist_stamped,
    ns_to_stamp,
    stamp_to_ns,
)
from gateway.wire.ros2.cdr_stream import MAX_STRING_BYTES

if TYPE_CHECKING:
    from collections.abc import Callable

HEADER = "00010000"
TWIST_1_TO_6 = bytes.fromhex(
    HEADER
    + "000000000000f03f" "0000000000000040" "0000000000000840"   # linear 1, 2, 3
    + "0000000000001040" "0000000000001440" "0000000000001840"   # angular 4, 5, 6
)
STAMPED = TwistStamped(Header(Time(1_700_000_000, 123_456_789), "base_link"),
                       Twist3D(linear_x=0.5, angular_z=-0.25))
STAMPED_BYTES = bytes.fromhex(
    HEADER
    + "00f15365" "15cd5b07"                      # sec, nanosec (body 0..7)
    + "0a000000" "626173655f6c696e6b00"          # "base_link" + NUL, length 10 (8..21)
    + "0000"                                     # pad to 24
    + "000000000000e03f" + "0000000000000000" * 4 + "000000000000d0bf"
)
TF = TFMessage((TransformStamped(Header(Time(1, 2), "odom"), "base_link",
                                 Vector3(1.0, 2.0, 0.0), Quaternion()),))
TF_BYTES = bytes.fromhex(
    HEADER
    + "01000000"                                 # one transform (body 0..3)
    + "01000000" "02000000"                      # stamp (4..11)
    + "05000000" "6f646f6d00" "000000"           # "odom" (12..20), pad to 24
    + "0a000000" "626173655f6c696e6b00" "0000"   # "base_link" (24..37), pad to 40
    + "000000000000f03f" "0000000000000040" + "0000000000000000" * 4 + "000000000000f03f"
)
ODOM = Odometry(
    Header(Time(-2, 300_000_000), "odom"), "base_link", Vector3(1.5, -2.0, 0.0),
    Quaternion(0.0, 0.0, 0.6, 0.8), tuple(float(i) for i in range(36)),
    Twist3D(0.25, 0.0, 0.0, 0.0, 0.0, 0.125), tuple(-float(i) for i in range(36)),
)


def odometry_bytes(message: Odometry) -> bytes:
    """Odometry laid out by hand with ``struct``: 3 pad bytes after "odom", 6 after the
    child frame."""
    assert message.header.frame_id == "odom" and message.child_frame_id == "base_link"
    head = bytes.fromhex(HEADER) + struct.pack(
        "<iII5s3xI10s", message.header.stamp.sec, message.header.stamp.nanosec, 5, b"odom\0",
        10, b"base_link\0")
    head += bytes((-(len(head) - 4)) % 8)
    p, q, t = message.position, message.orientation, message.twist
    return head + struct.pack(
        "<7d36d6d36d", p.x, p.y, p.z, q.x, q.y, q.z, q.w, *message.pose_covariance,
        t.linear_x, t.linear_y, t.linear_z, t.angular_x, t.angular_y, t.angular_z,
        *message.twist_covariance)


# ----------------------------------------------------------------------------- golden bytes


def test_twist_golden_bytes_both_ways() -> None:
    twist = Twist3D(1.0, 2.0, 3.0, 4.0, 5.0, 6.0)
    assert encode_twist(twist) == TWIST_1_TO_6
    assert len(TWIST_1_TO_6) == TWIST_SIZE == 52
    assert decode_twist(TWIST_1_TO_6) == twist


def test_twist_stamped_golden_bytes_both_ways() -> None:
    assert encode_twist_stamped(STAMPED) == STAMPED_BYTES
    assert decode_twist_stamped(STAMPED_BYTES) == STAMPED


def test_tf_message_golden_bytes_both_ways() -> None:
    assert encode_tf_message(TF) == TF_BYTES
    assert decode_tf_message(TF_BYTES) == TF
    assert encode_tf_message(TFMessage()) == bytes.fromhex(HEADER + "00000000")
    assert decode_tf_message(bytes.fromhex(HEADER + "00000000")) == TFMessage()


def test_odometry_matches_a_struct_layout_both_ways() -> None:
    expected = odometry_bytes(ODOM)
    assert len(expected) == 4 + 40 + 8 * (7 + 36 + 6 + 36)
    assert encode_odometry(ODOM) == expected
    assert decode_odometry(expected) == ODOM


def test_the_options_bytes_are_ignored() -> None:
    assert decode_twist(b"\x00\x01\xab\xcd" + TWIST_1_TO_6[4:]) == decode_twist(TWIST_1_TO_6)
    assert decode_tf_message(TF_BYTES[:2] + b"\x00\x03" + TF_BYTES[4:]) == TF


def test_padding_bytes_are_not_checked() -> None:
    """Another writer may leave garbage in alignment padding."""
    dirty = bytearray(STAMPED_BYTES)
    dirty[4 + 22:4 + 24] = b"\xee\xee"
    assert decode_twist_stamped(bytes(dirty)) == STAMPED


def test_non_finite_numbers_pass_through() -> None:
    twist = decode_twist(encode_twist(Twist3D(math.nan, math.inf, -math.inf)))
    assert math.isnan(twist.linear_x) and twist.linear_y == math.inf
    assert twist.linear_z == -math.inf


def test_decoders_accept_bytearray_and_memoryview() -> None:
    assert decode_twist(bytearray(TWIST_1_TO_6)) == decode_twist(TWIST_1_TO_6)
    assert decode_tf_message(memoryview(TF_BYTES)) == TF


# ----------------------------------------------------------------------------- bad payloads


DECODERS: list[tuple[str, Callable[[bytes], object], bytes]] = [
    ("geometry_msgs/msg/Twist", decode_twist, TWIST_1_TO_6),
    ("geometry_msgs/msg/TwistStamped", decode_twist_stamped, STAMPED_BYTES),
    ("nav_msgs/msg/Odometry", decode_odometry, odometry_bytes(ODOM)),
    ("tf2_msgs/msg/TFMessage", decode_tf_message, TF_BYTES),
]
DECODER_IDS = [name.rsplit("/", 1)[-1] for name, _, _ in DECODERS]


def test_a_short_twist_names_type_expected_and_got() -> None:
    with pytest.raises(DecodeError, match=r"^geometry_msgs/msg/Twist: expected 52 bytes, "
                                          r"got 12$"):
        decode_twist(TWIST_1_TO_6[:12])


@pytest.mark.parametrize(("name", "decode", "good"), DECODERS, ids=DECODER_IDS)
def test_every_truncation_is_a_decode_error(
        name: str, decode: Callable[[bytes], object], good: bytes) -> None:
    for size in range(len(good)):
        with pytest.raises(DecodeError, match=f"^{name}: expected"):
            decode(good[:size])


@pytest.mark.parametrize(("name", "decode", "good"), DECODERS, ids=DECODER_IDS)
def test_trailing_bytes_beyond_padding_are_refused(
        name: str, decode: Callable[[bytes], object], good: bytes) -> None:
    with pytest.raises(DecodeError, match=f"^{name}: expected {len(good)} bytes, got "
                                          f"{len(good) + 8}"):
        decode(good + bytes(8))


def test_trailing_alignment_padding_is_accepted() -> None:
    """An empty TFMessage has a 4-byte body; a writer may pad it to 8."""
    assert decode_tf_message(bytes.fromhex(HEADER + "00000000" + "00000000")) == TFMessage()
    with pytest.raises(DecodeError, match=r"expected 8 bytes \(\+ up to 4 bytes of padding\), "
                                          r"got 11"):
        decode_tf_message(bytes.fromhex(HEADER + "00000000" + "000000"))


@pytest.mark.parametrize(("name", "decode", "good"), DECODERS, ids=DECODER_IDS)
@pytest.mark.parametrize(("rep", "label"), [("0000", "big-endian CDR"),
                                            ("0007", "little-endian XCDR2"),
                                            ("0101", "unknown")])
def test_only_little_endian_cdr_is_accepted(
        name: str, decode: Callable[[bytes], object], good: bytes, rep: str, label: str) -> None:
    with pytest.raises(DecodeError, match=f"^{name}: expected encapsulation 00 01 "
                                          rf"\(little-endian CDR\), got {rep[:2]} {rep[2:]} "
                                          rf"\({label}\)$"):
        decode(bytes.fromhex(rep) + good[2:])


@pytest.mark.parametrize(("name", "decode", "good"), DECODERS, ids=DECODER_IDS)
def test_a_payload_that_is_not_bytes_is_a_decode_error(
        name: str, decode: Callable[[bytes], object], good: bytes) -> None:
    with pytest.raises(DecodeError, match=f"^{name}: expected a bytes payload, got str"):
        decode(good.hex())  # type: ignore[arg-type]


def stamped_with_frame(raw: bytes, length: int | None = None) -> bytes:
    """A TwistStamped payload whose frame_id is ``raw`` (NUL included by the caller)."""
    n = len(raw) if length is None else length
    body = struct.pack("<iII", 0, 0, n) + raw
    body += bytes((-len(body)) % 8)
    return bytes.fromhex(HEADER) + body + bytes(48)


def test_a_string_frame_decodes() -> None:
    assert decode_twist_stamped(stamped_with_frame(b"map\0")).header.frame_id == "map"
    assert decode_twist_stamped(stamped_with_frame("gyögy\0".encode())).header.frame_id \
        == "gyögy"


@pytest.mark.parametrize(("raw", "length", "message"), [
    (b"map", None, r"expected string header.frame_id to end with a NUL byte, got 0x70"),
    (b"", 0, r"expected a length of at least 1 \(the NUL\) for string header.frame_id, got 0"),
    (b"m\0p\0", None, r"expected no NUL inside string header.frame_id, got one at index 1 of 3"),
    (b"\xff\xfe\0", None, r"expected UTF-8 in string header.frame_id, got byte 0xff at "
                          r"index 0"),
    (b"map\0", 0xFFFF_FFFF, r"expected at most \d+ bytes for string header.frame_id at byte "
                            r"16, got a length of 4294967295"),
    (b"map\0", 60, r"expected at most 52 bytes for string header.frame_id at byte 16, got a "
                   r"length of 60"),
])
def test_bad_strings_are_decode_errors(raw: bytes, length: int | None, message: str) -> None:
    with pytest.raises(DecodeError, match=f"^geometry_msgs/msg/TwistStamped: {message}$"):
        decode_twist_stamped(stamped_with_frame(raw, length))


def test_an_absurd_sequence_length_is_refused_before_reading() -> None:
    payload = bytes.fromhex(HEADER + "ffffffff") + TF_BYTES[8:]
    with pytest.raises(DecodeError, match=r"^tf2_msgs/msg/TFMessage: expected at most 1 "
                                          r"elements in transforms .*got a length of "
                                          r"4294967295$"):
        decode_tf_message(payload)


def test_a_sequence_longer_than_the_bytes_left_is_refused_before_reading() -> None:
    payload = bytes.fromhex(HEADER + "02000000") + TF_BYTES[8:]  # two declared, one there
    with pytest.raises(DecodeError, match=r"^tf2_msgs/msg/TFMessage: expected at most 1 "
                                          r"elements in transforms \(the bytes left hold no "
                                          r"more\), got a length of 2$"):
        decode_tf_message(payload)


def test_a_field_cut_short_is_named_with_its_offset() -> None:
    with pytest.raises(DecodeError, match=r"^nav_msgs/msg/Odometry: expected 288 bytes for "
                                          r"pose.covariance at byte 100, got 20$"):
        decode_odometry(odometry_bytes(ODOM)[:120])


# ----------------------------------------------------------------------------- encoders


@pytest.mark.parametrize(("message", "error"), [
    (TwistStamped(Header(Time(2**31, 0))), r"expected an integer from -2147483648 to "
                                            r"2147483647 for header.stamp.sec, got 2147483648"),
    (TwistStamped(Header(Time(0, 10**9))), r"expected an integer from 0 to 999999999 for "
                                           r"header.stamp.nanosec, got 1000000000"),
    (TwistStamped(Header(Time(0, -1))), r"expected an integer from 0 to 999999999 for "
                                        r"header.stamp.nanosec, got -1"),
    (TwistStamped(Header(frame_id="a\0b")), r"expected no NUL in header.frame_id"),
    (TwistStamped(Header(frame_id="\ud800")), r"expected text UTF-8 can encode"),
    (TwistStamped(Header(frame_id="x" * MAX_STRING_BYTES)), r"expected at most 4095 UTF-8"),
    (TwistStamped(Header(frame_id=5)), r"expected a str for header.frame_id, got 5"),  # type: ignore[arg-type]
    (TwistStamped(twist=Twist3D(linear_x="1")), r"expected a number for twist\[0\], got '1'"),  # type: ignore[arg-type]
    (TwistStamped(twist=Twist3D(angular_z=10**400)), r"expected numbers a float64 can hold"),
    (TwistStamped(twist=(1, 2)), r"expected a Twist3D for twist"),  # type: ignore[arg-type]
])
def test_encoders_refuse_what_cannot_go_on_the_wire(message: TwistStamped, error: str) -> None:
    with pytest.raises(EncodeError, match=f"^geometry_msgs/msg/TwistStamped: {error}"):
        encode_twist_stamped(message)


def test_the_odometry_covariances_must_have_36_numbers() -> None:
    with pytest.raises(EncodeError, match=r"^nav_msgs/msg/Odometry: expected 36 numbers for "
                                          r"pose.covariance, got 35$"):
        encode_odometry(Odometry(pose_covariance=(0.0,) * 35))
    with pytest.raises(EncodeError, match=r"expected 36 numbers for twist.covariance, got "
                                          r"'x'$"):
        encode_odometry(Odometry(twist_covariance="x"))  # type: ignore[arg-type]


def test_encoders_refuse_the_wrong_message_class() -> None:
    for encode in (encode_twist_stamped, encode_odometry, encode_tf_message):
        with pytest.raises(EncodeError, match="expected a"):
            encode(Twist3D())  # type: ignore[arg-type]
    with pytest.raises(EncodeError, match=r"expected a TransformStamped for transforms\[0\]"):
        encode_tf_message(TFMessage((Header(),)))  # type: ignore[arg-type]


# ----------------------------------------------------------------------------- stamps


@pytest.mark.parametrize(("ns", "stamp"), [
    (0, Time(0, 0)),
    (1_700_000_000_123_456_789, Time(1_700_000_000, 123_456_789)),
    (-1_700_000_000, Time(-2, 300_000_000)),
    (-1, Time(-1, 999_999_999)),
])
def test_stamps_convert_both_ways(ns: int, stamp: Time) -> None:
    assert ns_to_stamp(ns) == stamp
    assert stamp_to_ns(stamp) == ns


def test_a_trigger_request_or_response_that_is_not_one_is_refused() -> None:
    from gateway.wire.ros2 import decode_trigger_request, decode_trigger_response

    with pytest.raises(DecodeError, match=r"^std_srvs/srv/Trigger_Request: expected 1 bytes "
                                          r"for structure_needs_at_least_one_member"):
        decode_trigger_request(b"\x00\x01\x00\x00")
    with pytest.raises(DecodeError, match=r"^std_srvs/srv/Trigger_Response: expected 0 or 1 "
                                          r"for success, got 2"):
        decode_trigger_response(b"\x00\x01\x00\x00\x02\x00\x00\x00\x01\x00\x00\x00\x00")
