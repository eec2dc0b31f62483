"""XCDR1 little-endian reading and writing: encapsulation header, alignment, numbers, strings.

The layout is plain CDR as OMG DDS-XTypes 1.3 section 7.4 ("XCDR version 1") defines it and as
ROS 2 middlewares put it on the wire (Fast-CDR under rmw_zenoh: ``rmw_zenoh_cpp/src/detail/cdr.hpp``
in the public repository ros2/rmw_zenoh):

* a 4-byte encapsulation header: the representation identifier ``00 01`` (``CDR_LE``) and two
  option bytes, which a reader ignores (DDS uses them for the count of trailing padding bytes);
* then the body, every primitive aligned to its own size **relative to the start of the body**;
  padding bytes are written as zeros and never checked when read;
* a string is a ``uint32`` length that counts the terminating NUL, the UTF-8 bytes, the NUL;
* a sequence is a ``uint32`` element count, then the elements; a fixed array is just the
  elements.

:class:`CdrReader` raises :class:`~gateway.core.errors.DecodeError` and nothing else;
:class:`CdrWriter` raises :class:`~gateway.core.errors.EncodeError` and nothing else.  Every
message names the ROS type, the field, what was expected and what came.  Pure: no I/O.
"""

from __future__ import annotations

import struct
from typing import TYPE_CHECKING, TypeAlias

from gateway.core.errors import DecodeError, EncodeError

if TYPE_CHECKING:
    from collections.abc import Iterable

#: What a decoder takes: the payload as Zenoh hands it over (``ZBytes.to_bytes()``) or a view.
Payload: TypeAlias = bytes | bytearray | memoryview
#: Representation identifier of little-endian plain CDR (XCDR1), the first two header bytes.
CDR_LE = b"\x00\x01"
#: The header this codec writes: ``CDR_LE`` and zero options.
ENCAPSULATION_HEADER = b"\x00\x01\x00\x00"
#: Size of the encapsulation header, bytes.
HEADER_SIZE = 4
#: Longest string accepted or written, in bytes, terminating NUL included.
MAX_STRING_BYTES = 4096
#: Most elements a decoded sequence may declare.
MAX_SEQUENCE_LENGTH = 10_000

_REPRESENTATIONS = {
    b"\x00\x00": "big-endian CDR",
    b"\x00\x02": "big-endian PL_CDR",
    b"\x00\x03": "little-endian PL_CDR",
    b"\x00\x06": "big-endian XCDR2",
    b"\x00\x07": "little-endian XCDR2",
}
_I32 = struct.Struct("<i")
_U32 = struct.Struct("<I")
_F64 = struct.Struct("<d")
_I32_MIN, _I32_MAX = -(2**31), 2**31 - 1
_U32_MAX = 2**32 - 1


def check_header(type_name: str, data: bytes) -> None:
    """Raise unless ``data`` starts with a little-endian plain CDR encapsulation header.

    :raises DecodeError: fewer than 4 bytes, or another representation (big endian, XCDR2...).
    """
    if len(data) < HEADER_SIZE:
        raise DecodeError(
            f"{type_name}: expected at least the {HEADER_SIZE}-byte encapsulation header, "
            f"got {len(data)} bytes"
        )
    rep = data[:2]
    if rep != CDR_LE:
        known = _REPRESENTATIONS.get(rep, "unknown")
        raise DecodeError(
            f"{type_name}: expected encapsulation 00 01 (little-endian CDR), "
            f"got {rep.hex(' ')} ({known})"
        )


def as_bytes(type_name: str, payload: object) -> bytes:
    """``payload`` as :class:`bytes` (from bytes, bytearray or memoryview).

    :raises DecodeError: for anything else.
    """
    if isinstance(payload, bytes):
        return payload
    if isinstance(payload, (bytearray, memoryview)):
        return bytes(payload)
    raise DecodeError(f"{type_name}: expected a bytes payload, got {type(payload).__name__}")


class CdrReader:
    """Reads the body of one CDR payload, field by field, with bounds checks.

    :param type_name: the ROS type, for error messages (``geometry_msgs/msg/Twist``).
    :param payload: the whole payload, encapsulation header included.
    :raises DecodeError: see :func:`check_header`.
    """

    __slots__ = ("_data", "_pos", "type_name")

    def __init__(self, type_name: str, payload: object) -> None:
        self.type_name = type_name
        self._data = as_bytes(type_name, payload)
        check_header(type_name, self._data)
        self._pos = HEADER_SIZE

    @property
    def remaining(self) -> int:
        """Bytes not read yet."""
        return len(self._data) - self._pos

    def _take(self, size: int, align: int, field: str) -> int:
        """Align to ``align``, check ``size`` bytes are there, return their offset."""
        pos = self._pos + (-(self._pos - HEADER_SIZE)) % align
        if pos + size > len(self._data):
            got = max(0, len(self._data) - pos)
            raise DecodeError(
                f"{self.type_name}: expected {size} bytes for {field} at byte {pos}, got {got}"
            )
        self._pos = pos + size
        return pos

    def octet(self, field: str) -> int:
        """One ``uint8`` (or ``bool``, 0 or 1 on the wire)."""
        return self._data[self._take(1, 1, field)]

    def int32(self, field: str) -> int:
        """One ``int32``."""
        return int(_I32.unpack_from(self._data, self._take(4, 4, field))[0])

    def uint32(self, field: str) -> int:
        """One ``uint32``."""
        return int(_U32.unpack_from(self._data, self._take(4, 4, field))[0])

    def float64(self, field: str) -> float:
        """One ``float64`` (NaN and infinities are returned as they are)."""
        return float(_F64.unpack_from(self._data, self._take(8, 8, field))[0])

    def float64s(self, layout: struct.Struct, field: str) -> tuple[float, ...]:
        """Consecutive ``float64`` values laid out by ``layout`` (``"<Nd"``)."""
        return tuple(layout.unpack_from(self._data, self._take(layout.size, 8, field)))

    def string(self, field: str) -> str:
        """One string: length with NUL, UTF-8 bytes, NUL."""
        length = self.uint32(f"the length of {field}")
        if length == 0:
            raise DecodeError(
                f"{self.type_name}: expected a length of at least 1 (the NUL) for string "
                f"{field}, got 0"
            )
        if length > MAX_STRING_BYTES or length > self.remaining:
            raise DecodeError(
                f"{self.type_name}: expected at most {min(MAX_STRING_BYTES, self.remaining)} "
                f"bytes for string {field} at byte {self._pos}, got a length of {length}"
            )
        start = self._pos
        raw = self._data[start:start + length]
        self._pos = start + length
        if raw[-1] != 0:
            raise DecodeError(
                f"{self.type_name}: expected string {field} to end with a NUL byte, "
                f"got 0x{raw[-1]:02x}"
            )
        text = raw[:-1]
        inner = text.find(0)
        if inner >= 0:
            raise DecodeError(
                f"{self.type_name}: expected no NUL inside string {field}, got one at "
                f"index {inner} of {length - 1}"
            )
        try:
            return text.decode("utf-8")
        except UnicodeDecodeError as err:
            raise DecodeError(
                f"{self.type_name}: expected UTF-8 in string {field}, got byte "
                f"0x{text[err.start]:02x} at index {err.start}"
            ) from None

    def sequence_length(self, field: str, min_element_size: int) -> int:
        """The element count of a sequence, checked against what the payload can hold.

        :param min_element_size: the fewest bytes one element takes, for the plausibility check.
        """
        count = self.uint32(f"the length of {field}")
        limit = min(MAX_SEQUENCE_LENGTH, self.remaining // min_element_size)
        if count > limit:
            raise DecodeError(
                f"{self.type_name}: expected at most {limit} elements in {field} (the bytes "
                f"left hold no more), got a length of {count}"
            )
        return count

    def finish(self) -> None:
        """Raise unless every byte was read, but for padding up to a 4- or 8-byte boundary."""
        body = self._pos - HEADER_SIZE
        trailing = len(self._data) - self._pos
        if trailing in (0, (-body) % 4, (-body) % 8):
            return
        padding = (-body) % 8
        allowed = f" (+ up to {padding} bytes of padding)" if padding else ""
        raise DecodeError(
            f"{self.type_name}: expected {self._pos} bytes{allowed}, got {len(self._data)}"
        )


class CdrWriter:
    """Builds one CDR payload, encapsulation header first.

    :param type_name: the ROS type, for error messages.
    """

    __slots__ = ("_buf", "type_name")

    def __init__(self, type_name: str) -> None:
        self.type_name = type_name
        self._buf = bytearray(ENCAPSULATION_HEADER)

    def _align(self, size: int) -> None:
        pad = (-(len(self._buf) - HEADER_SIZE)) % size
        if pad:
            self._buf += bytes(pad)

    def _check_int(self, value: object, lo: int, hi: int, field: str) -> int:
        if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
            raise EncodeError(
                f"{self.type_name}: expected an integer from {lo} to {hi} for {field}, "
                f"got {value!r}"
            )
        return value

    def octet(self, value: object, field: str) -> None:
        """One ``uint8`` (a ``bool`` is 0 or 1)."""
        self._buf.append(self._check_int(int(value) if isinstance(value, bool) else value,
                                         0, 255, field))

    def int32(self, value: object, field: str) -> None:
        """One ``int32``."""
        self._align(4)
        self._buf += _I32.pack(self._check_int(value, _I32_MIN, _I32_MAX, field))

    def uint32(self, value: object, field: str, hi: int = _U32_MAX) -> None:
        """One ``uint32``, at most ``hi``."""
        self._align(4)
        self._buf += _U32.pack(self._check_int(value, 0, hi, field))

    def float64s(self, layout: struct.Struct, values: Iterable[object], field: str) -> None:
        """Consecutive ``float64`` values laid out by ``layout`` (``"<Nd"``).

        Any real number goes (NaN and infinities too: the receiver validates).
        """
        items = tuple(values)
        count = layout.size // 8
        if len(items) != count:
            raise EncodeError(
                f"{self.type_name}: expected {count} numbers for {field}, got {len(items)}"
            )
        for index, item in enumerate(items):
            if isinstance(item, bool) or not isinstance(item, (int, float)):
                where = f"{field}[{index}]" if count > 1 else field
                raise EncodeError(
                    f"{self.type_name}: expected a number for {where}, got {item!r}"
                )
        self._align(8)
        try:
            self._buf += layout.pack(*items)
        except (OverflowError, struct.error) as err:  # an int too large for a double
            raise EncodeError(
                f"{self.type_name}: expected numbers a float64 can hold for {field}, "
                f"got {items!r} ({err})"
            ) from None

    def string(self, value: object, field: str) -> None:
        """One string (UTF-8, no NUL inside)."""
        if not isinstance(value, str):
            raise EncodeError(f"{self.type_name}: expected a str for {field}, got {value!r}")
        try:
            raw = value.encode("utf-8")
        except UnicodeEncodeError as err:
            raise EncodeError(
                f"{self.type_name}: expected text UTF-8 can encode for {field}, got "
                f"{value!r} ({err.reason} at index {err.start})"
            ) from None
        if b"\x00" in raw:
            raise EncodeError(f"{self.type_name}: expected no NUL in {field}, got {value!r}")
        if len(raw) + 1 > MAX_STRING_BYTES:
            raise EncodeError(
                f"{self.type_name}: expected at most {MAX_STRING_BYTES - 1} UTF-8 bytes for "
                f"{field}, got {len(raw)}"
            )
        self.uint32(len(raw) + 1, f"the length of {field}")
        self._buf += raw
        self._buf += b"\x00"

    def sequence_length(self, count: int, field: str) -> None:
        """The element count of a sequence (at most :data:`MAX_SEQUENCE_LENGTH`)."""
        self.uint32(count, f"the length of {field}", MAX_SEQUENCE_LENGTH)

    def payload(self) -> bytes:
        """The payload written so far."""
        return bytes(self._buf)
