"""The attachment rmw_zenoh puts on every published sample: sequence number, time, GID.

rmw_zenoh drops a sample that has no attachment it can read, and counts a gap in one
publisher's sequence numbers as lost messages.  The layout is the Zenoh serialization
(``zenoh::ext::Serializer``) of ``AttachmentData`` in ``rmw_zenoh_cpp/src/detail/
attachment_helpers.cpp`` of the public repository ros2/rmw_zenoh, and is written out in its
``docs/design.md`` ("Publishers"):

==========  =====  ===========================================================
bytes       size   field
==========  =====  ===========================================================
0..7        8      sequence number, ``int64`` little endian (1 for the first)
8..15       8      source timestamp, ``int64`` little endian, ns since the Unix epoch
16          1      length of the GID, always ``0x10`` (a LEB128 count: 16)
17..32      16     the publisher's GID
==========  =====  ===========================================================

That is :attr:`AttachmentFormat.POSITIONAL`, 33 bytes, since rmw_zenoh 0.6.0 (Rolling, Kilted)
and 0.2.4 (Jazzy, April 2025; pull requests #601 and #605).  Jazzy's 0.2.0 to 0.2.3 (and Rolling
0.3 to 0.5) wrote each field after its name, as Zenoh strings: ``"sequence_number"``, the
``int64``, ``"source_timestamp"``, the ``int64``, ``"source_gid"``, the 16 bytes with their
length (77 bytes): :attr:`AttachmentFormat.LABELLED`.  The two do not interoperate; the decoder
reads both, the encoder writes either.  Pure: no I/O, no clock.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

from gateway.core.bridge_settings import AttachmentFormat
from gateway.core.errors import DecodeError, EncodeError

#: Size of a publisher GID (``RMW_GID_STORAGE_SIZE``), bytes.
GID_SIZE = 16
#: Size of a :attr:`AttachmentFormat.POSITIONAL` attachment, bytes.
ATTACHMENT_SIZE = 33

_ENTITY = "rmw_zenoh attachment"
_POSITIONAL = struct.Struct("<qqB16s")
_I64_MIN, _I64_MAX = -(2**63), 2**63 - 1


def _label(name: str) -> bytes:
    """A Zenoh-serialized string shorter than 128 bytes: one-byte LEB128 length, the bytes."""
    return bytes([len(name)]) + name.encode("ascii")


_SEQ_LABEL = _label("sequence_number")
_TIME_LABEL = _label("source_timestamp")
_GID_LABEL = _label("source_gid")
_LABELLED = struct.Struct(f"<{len(_SEQ_LABEL)}sq{len(_TIME_LABEL)}sq{len(_GID_LABEL)}sB16s")
#: Size of a :attr:`AttachmentFormat.LABELLED` attachment, bytes.
LABELLED_ATTACHMENT_SIZE = _LABELLED.size


@dataclass(frozen=True, slots=True)
class Attachment:
    """One decoded attachment.

    :param sequence_number: the publisher's count of samples, from 1.
    :param source_timestamp_ns: when it was published, ns since the Unix epoch.
    :param gid: the publisher's 16-byte GID (see :func:`gateway.wire.ros2.keys.gid_of`).
    :param layout: the format it came in.
    """

    sequence_number: int
    source_timestamp_ns: int
    gid: bytes
    layout: AttachmentFormat = AttachmentFormat.POSITIONAL


def _int64(value: object, name: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not _I64_MIN <= value <= _I64_MAX:
        raise EncodeError(
            f"{_ENTITY}: expected {name} to be an int64, from {_I64_MIN} to {_I64_MAX}, "
            f"got {value!r}"
        )
    return value


def encode_attachment(sequence_number: int, timestamp_ns: int, gid: bytes,
                      layout: AttachmentFormat = AttachmentFormat.POSITIONAL) -> bytes:
    """The attachment of one sample.

    :param sequence_number: the publisher's sample count (start at 1, add 1 per sample).
    :param timestamp_ns: the publication time, ns since the Unix epoch.
    :param gid: the publisher's GID, exactly 16 bytes.
    :param layout: the format; the current one unless talking to Jazzy 0.2.0 to 0.2.3.
    :raises EncodeError: a number outside ``int64``, a GID of another size or type.

    >>> encode_attachment(1, 2, bytes(range(16))).hex()
    '0100000000000000020000000000000010000102030405060708090a0b0c0d0e0f'
    """
    seq = _int64(sequence_number, "the sequence number")
    stamp = _int64(timestamp_ns, "the source timestamp")
    if not isinstance(gid, (bytes, bytearray)) or len(gid) != GID_SIZE:
        raise EncodeError(f"{_ENTITY}: expected a GID of {GID_SIZE} bytes, got {gid!r}")
    if layout is AttachmentFormat.LABELLED:
        return _LABELLED.pack(_SEQ_LABEL, seq, _TIME_LABEL, stamp, _GID_LABEL, GID_SIZE,
                              bytes(gid))
    return _POSITIONAL.pack(seq, stamp, GID_SIZE, bytes(gid))


def decode_attachment(data: bytes | bytearray | memoryview) -> Attachment:
    """The :class:`Attachment` in ``data``, in either format.

    :raises DecodeError: anything but a 33-byte positional or a 77-byte labelled attachment
        with a 16-byte GID.
    """
    if not isinstance(data, (bytes, bytearray, memoryview)):
        raise DecodeError(f"{_ENTITY}: expected bytes, got {type(data).__name__}")
    raw = bytes(data)
    if len(raw) == ATTACHMENT_SIZE:
        seq, stamp, gid_len, gid = _POSITIONAL.unpack(raw)
        if gid_len != GID_SIZE:
            raise DecodeError(
                f"{_ENTITY}: expected a GID length byte of 0x{GID_SIZE:02x} at byte 16, "
                f"got 0x{gid_len:02x}"
            )
        return Attachment(seq, stamp, gid, AttachmentFormat.POSITIONAL)
    if len(raw) == LABELLED_ATTACHMENT_SIZE:
        seq_label, seq, time_label, stamp, gid_label, gid_len, gid = _LABELLED.unpack(raw)
        expected = (_SEQ_LABEL, _TIME_LABEL, _GID_LABEL, GID_SIZE)
        got = (seq_label, time_label, gid_label, gid_len)
        if got != expected:
            raise DecodeError(
                f"{_ENTITY}: expected the labels and GID length of the labelled format "
                f"{expected!r}, got {got!r}"
            )
        return Attachment(seq, stamp, gid, AttachmentFormat.LABELLED)
    raise DecodeError(
        f"{_ENTITY}: expected {ATTACHMENT_SIZE} bytes (or {LABELLED_ATTACHMENT_SIZE} in the "
        f"labelled format of Jazzy 0.2.0 to 0.2.3), got {len(raw)}"
    )
