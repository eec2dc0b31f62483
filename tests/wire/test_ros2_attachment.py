"""rmw_zenoh's sample attachment: the 33-byte layout, the older labelled one, bad inputs.

Literal golden bytes first (the layout of rmw_zenoh's ``docs/design.md``); then the same bytes
from Zenoh's own serializer (``zenoh.ext.z_serialize``, what rmw_zenoh's
``zenoh::ext::Serializer`` writes), skipped when eclipse-zenoh is not installed.
"""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from gateway.core.errors import DecodeError, EncodeError
from gateway.wire.ros2 import (
    ATTACHMENT_SIZE,
    Attachment,
    AttachmentFormat,
    decode_attachment,
    encode_attachment,
)
from gateway.wire.ros2.attachment import LABELLED_ATTACHMENT_SIZE

GID = bytes.fromhex("00112233445566778899aabbccddeeff")
GOLDEN = bytes.fromhex(
    "2a00000000000000"                      # sequence number 42, int64 LE
    "15cd853dfe9c9717"                      # 1700000000123456789 ns, int64 LE
    "10"                                    # GID length 16
    "00112233445566778899aabbccddeeff"      # GID
)
LABELLED = (
    b"\x0fsequence_number" + (42).to_bytes(8, "little")
    + b"\x10source_timestamp" + (1_700_000_000_123_456_789).to_bytes(8, "little")
    + b"\x0asource_gid" + b"\x10" + GID
)
INT64 = st.integers(-(2**63), 2**63 - 1)
GIDS = st.binary(min_size=16, max_size=16)


def test_the_golden_attachment_both_ways() -> None:
    assert len(GOLDEN) == ATTACHMENT_SIZE == 33
    assert encode_attachment(42, 1_700_000_000_123_456_789, GID) == GOLDEN
    assert decode_attachment(GOLDEN) == Attachment(42, 1_700_000_000_123_456_789, GID,
                                                   AttachmentFormat.POSITIONAL)


def test_the_labelled_attachment_of_early_jazzy_both_ways() -> None:
    assert len(LABELLED) == LABELLED_ATTACHMENT_SIZE == 77
    assert encode_attachment(42, 1_700_000_000_123_456_789, GID,
                             AttachmentFormat.LABELLED) == LABELLED
    assert decode_attachment(LABELLED) == Attachment(42, 1_700_000_000_123_456_789, GID,
                                                     AttachmentFormat.LABELLED)


def test_negative_numbers_are_twos_complement() -> None:
    data = encode_attachment(-1, -2, GID)
    assert data[:16] == b"\xff" * 8 + b"\xfe" + b"\xff" * 7
    assert decode_attachment(data).source_timestamp_ns == -2


def test_both_layouts_match_zenohs_serializer() -> None:
    zenoh_ext = pytest.importorskip("zenoh.ext", reason="eclipse-zenoh is not installed: "
                                                        "no Zenoh serializer to compare with")
    positional = zenoh_ext.z_serialize(
        (zenoh_ext.Int64(42), zenoh_ext.Int64(1_700_000_000_123_456_789), GID))
    assert positional.to_bytes() == GOLDEN
    labelled = zenoh_ext.z_serialize((
        "sequence_number", zenoh_ext.Int64(42),
        "source_timestamp", zenoh_ext.Int64(1_700_000_000_123_456_789),
        "source_gid", GID))
    assert labelled.to_bytes() == LABELLED


@given(INT64, INT64, GIDS, st.sampled_from(AttachmentFormat))
def test_any_attachment_survives_a_round_trip(seq: int, stamp: int, gid: bytes,
                                              layout: AttachmentFormat) -> None:
    assert decode_attachment(encode_attachment(seq, stamp, gid, layout)) == Attachment(
        seq, stamp, gid, layout)


@pytest.mark.parametrize(("data", "error"), [
    (GOLDEN[:32], r"expected 33 bytes \(or 77 in the labelled format of Jazzy 0.2.0 to "
                  r"0.2.3\), got 32$"),
    (GOLDEN + b"\x00", r"expected 33 bytes .*got 34$"),
    (b"", r"expected 33 bytes .*got 0$"),
    (GOLDEN[:16] + b"\x0f" + GOLDEN[17:], r"expected a GID length byte of 0x10 at byte 16, "
                                          r"got 0x0f$"),
    (LABELLED.replace(b"source_gid", b"source_GID"), r"expected the labels and GID length "
                                                      r"of the labelled format"),
    (LABELLED[:60] + b"\x11" + LABELLED[61:], r"expected the labels and GID length .*16\), "
                                               r"got .*17\)$"),
    ("00" * 33, r"expected bytes, got str$"),
])
def test_malformed_attachments_are_decode_errors(data: bytes, error: str) -> None:
    with pytest.raises(DecodeError, match=f"^rmw_zenoh attachment: {error}"):
        decode_attachment(data)


def test_views_decode_like_bytes() -> None:
    assert decode_attachment(bytearray(GOLDEN)) == decode_attachment(memoryview(GOLDEN))


@pytest.mark.parametrize(("seq", "stamp", "gid", "error"), [
    (2**63, 0, GID, r"expected the sequence number to be an int64, .*got 9223372036854775808"),
    (0, -(2**63) - 1, GID, r"expected the source timestamp to be an int64"),
    (1.0, 0, GID, r"expected the sequence number to be an int64, .*got 1.0"),
    (True, 0, GID, r"expected the sequence number to be an int64, .*got True"),
    (1, 0, GID[:15], r"expected a GID of 16 bytes, got b'"),
    (1, 0, GID.hex(), r"expected a GID of 16 bytes, got '0011"),
])
def test_the_encoder_refuses_what_does_not_fit(seq: object, stamp: object, gid: object,
                                               error: str) -> None:
    with pytest.raises(EncodeError, match=f"^rmw_zenoh attachment: {error}"):
        encode_attachment(seq, stamp, gid)  # type: ignore[arg-type]
