"""The inbound side of the control socket: a byte stream to lines to validated requests.

:class:`LineFramer` splits what a connection sends into bounded lines, and
:func:`parse_request` turns one line into a request or raises :class:`ProtocolError` whose
message names the field, what was expected and what came.  Pure: no I/O, no clock.
"""

from __future__ import annotations

import json
import math
from typing import TYPE_CHECKING, Any

from gateway.kinematics.odometry import Pose
from gateway.protocol.messages import (
    MAX_ID_CHARS,
    MAX_MESSAGE_BYTES,
    MAX_TWIST_COMPONENT,
    CommandRequest,
    Op,
    ProtocolError,
    Request,
    RequestId,
    ResetOdometryRequest,
    SubscribeRequest,
    Topic,
    TwistRequest,
    json_type,
    quoted,
    short_json,
)
from gateway.types import Twist

if TYPE_CHECKING:
    from collections.abc import Mapping

_ID_MIN, _ID_MAX = -(2**63), 2**63 - 1

_KEYS: dict[Op, tuple[str, ...]] = {
    Op.TWIST: ("vx", "vy", "wz"),
    Op.RESET_ODOMETRY: ("x", "y", "theta"),
    Op.SUBSCRIBE: ("topics",),
}


def _reject_duplicates(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    result: dict[str, Any] = {}
    for key, value in pairs:
        if key in result:
            raise ProtocolError(f'request: expected unique keys, got "{key}" twice')
        result[key] = value
    return result


def _decode(line: bytes | str, max_bytes: int) -> object:
    raw = line.encode("utf-8", "surrogatepass") if isinstance(line, str) else line
    raw = raw.removesuffix(b"\n").removesuffix(b"\r")
    if len(raw) > max_bytes:
        raise ProtocolError(
            f"message too long: expected at most {max_bytes} bytes, got {len(raw)}"
        )
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as err:
        raise ProtocolError(
            f"request: expected UTF-8 text, got byte 0x{raw[err.start]:02x} at offset {err.start}"
        ) from err
    if not text.strip():
        raise ProtocolError("request: expected a JSON object, got an empty line")
    try:
        return json.loads(text, object_pairs_hook=_reject_duplicates)
    except ProtocolError:  # from _reject_duplicates
        raise
    except json.JSONDecodeError as err:
        raise ProtocolError(
            f"request: expected valid JSON, got {err.msg[:1].lower()}{err.msg[1:]} "
            f"at offset {err.pos}"
        ) from err
    except RecursionError as err:
        raise ProtocolError(
            "request: expected JSON of modest depth, got nesting too deep to parse"
        ) from err
    except ValueError as err:  # e.g. an integer literal beyond Python's digit limit
        raise ProtocolError(f"request: expected valid JSON, got {err}") from err


def _read_id(obj: Mapping[str, object]) -> RequestId | None:
    if "id" not in obj:
        return None
    value = obj["id"]
    if isinstance(value, str) and len(value) <= MAX_ID_CHARS:
        return value
    if isinstance(value, int) and not isinstance(value, bool) and _ID_MIN <= value <= _ID_MAX:
        return value
    raise ProtocolError(
        f"request.id: expected an integer (64-bit) or a string of at most {MAX_ID_CHARS} "
        f"characters, got {short_json(value)}"
    )


def _number(
    obj: Mapping[str, object], op: Op, key: str, rid: RequestId | None, limit: float | None
) -> float:
    value = obj.get(key, 0.0)
    where = f"{op.value}.{key}"
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ProtocolError(f"{where}: expected a finite number, got {short_json(value)}", rid)
    if isinstance(value, float) and not math.isfinite(value):
        raise ProtocolError(f"{where}: expected a finite number, got {short_json(value)}", rid)
    if limit is not None and abs(value) > limit:
        raise ProtocolError(
            f"{where}: expected a number between {-limit:g} and {limit:g}, got {short_json(value)}",
            rid,
        )
    try:
        return float(value)
    except OverflowError as err:  # an integer beyond the float range
        raise ProtocolError(
            f"{where}: expected a finite number, got {short_json(value)}", rid
        ) from err


def _topics(obj: Mapping[str, object], rid: RequestId | None) -> frozenset[Topic]:
    names = quoted(t.value for t in Topic)
    if "topics" not in obj:
        raise ProtocolError(f"subscribe.topics: expected an array of {names}, got nothing", rid)
    value = obj["topics"]
    if not isinstance(value, list) or not value:
        raise ProtocolError(
            f"subscribe.topics: expected a non-empty array of {names}, got {short_json(value)}", rid
        )
    topics = set()
    for index, item in enumerate(value):
        try:
            topics.add(Topic(item))
        except ValueError:
            raise ProtocolError(
                f"subscribe.topics[{index}]: expected one of {names}, got {short_json(item)}", rid
            ) from None
    return frozenset(topics)


def parse_request(line: bytes | str, max_bytes: int = MAX_MESSAGE_BYTES) -> Request:
    """Parse one request line.

    >>> parse_request(b'{"op": "twist", "vx": 0.5, "id": 3}')
    TwistRequest(twist=Twist(vx_m_s=0.5, vy_m_s=0.0, wz_rad_s=0.0), id=3)

    :param line: one line, with or without its ``\\n`` (and ``\\r``).
    :param max_bytes: longest accepted line in bytes, newline excluded.
    :return: the request.
    :raises ProtocolError: for anything that is not a valid request; never anything else.
    """
    obj = _decode(line, max_bytes)
    if not isinstance(obj, dict):
        raise ProtocolError(f"request: expected a JSON object, got {json_type(obj)}")
    rid = _read_id(obj)
    if "op" not in obj:
        raise ProtocolError(
            f"request.op: expected one of {quoted(o.value for o in Op)}, got nothing", rid
        )
    raw_op = obj["op"]
    try:
        op = Op(raw_op)
    except ValueError:
        raise ProtocolError(
            f"request.op: expected one of {quoted(o.value for o in Op)}, got {short_json(raw_op)}",
            rid,
        ) from None
    allowed = ("id", "op", *_KEYS.get(op, ()))
    for key in obj:
        if key not in allowed:
            raise ProtocolError(
                f"{op.value}: expected only the keys {quoted(allowed)}, got {short_json(key)}", rid
            )
    if op is Op.TWIST:
        vx, vy, wz = (_number(obj, op, k, rid, MAX_TWIST_COMPONENT) for k in _KEYS[op])
        return TwistRequest(Twist(vx, vy, wz), rid)
    if op is Op.RESET_ODOMETRY:
        x, y, theta = (_number(obj, op, k, rid, None) for k in _KEYS[op])
        return ResetOdometryRequest(Pose(x, y, (theta + math.pi) % (2 * math.pi) - math.pi), rid)
    if op is Op.SUBSCRIBE:
        return SubscribeRequest(_topics(obj, rid), rid)
    return CommandRequest(op, rid)


class LineFramer:
    """Splits a byte stream into lines of at most ``max_bytes`` (pure; one per connection).

    A line is what precedes a ``\\n``, without it and without one trailing ``\\r``.  A line
    longer than ``max_bytes`` yields one :class:`ProtocolError` (``"message too long: ..., got
    more"``) -- as soon as the buffered part exceeds the limit, before its newline arrives -- and
    the rest of it is skipped up to its newline, so memory stays bounded by ``max_bytes``.

    >>> framer = LineFramer(8)
    >>> framer.feed(b'{"a":1}\\r\\n{"b"'), framer.feed(b':2}\\n'), framer.pending
    ([b'{"a":1}'], [b'{"b":2}'], 0)

    :param max_bytes: longest accepted line in bytes.
    """

    __slots__ = ("_buf", "_discarding", "max_bytes")

    def __init__(self, max_bytes: int = MAX_MESSAGE_BYTES) -> None:
        self.max_bytes = max_bytes
        self._buf = bytearray()
        self._discarding = False  # inside a too-long line, skipping to its newline

    @property
    def pending(self) -> int:
        """Bytes of an unfinished line held (0 while skipping a too-long one)."""
        return len(self._buf)

    def feed(self, data: bytes) -> list[bytes | ProtocolError]:
        """Take the next bytes of the stream; return the lines they complete, in order."""
        out: list[bytes | ProtocolError] = []
        start = 0
        if self._discarding:
            start = data.find(b"\n") + 1
            if not start:
                return out
            self._discarding = False
        buf = self._buf
        search = len(buf)
        buf += memoryview(data)[start:]
        begin = 0
        while (newline := buf.find(b"\n", search)) >= 0:
            end = newline - 1 if newline > begin and buf[newline - 1] == 0x0D else newline
            out.append(bytes(buf[begin:end]) if end - begin <= self.max_bytes else self._error())
            begin = search = newline + 1
        del buf[:begin]
        if len(buf) > self.max_bytes + 1:  # + 1: room for a "\r" before the "\n"
            buf.clear()
            self._discarding = True
            out.append(self._error())
        return out

    def _error(self) -> ProtocolError:
        return ProtocolError(
            f"message too long: expected at most {self.max_bytes} bytes, got more"
        )
