"""The inbound side of the control socket: a byte stream to lines to validated requests.

:class:`LineFramer` splits what a connection sends into bounded lines, and
:func:`parse_request` turns one line into a request or raises :class:`ProtocolError` whose
message names the field, what was expected and what came.  Pure: no I/O, no clock.
"""

from __future__ import annotations

import json
import math
from collections import deque
from typing import TYPE_CHECKING, Any

from gateway.core.kinematics.odometry import Pose
from gateway.core.types import MAX_TWIST_COMPONENT, Twist
from gateway.wire.can import POSITION_WRAP_M
from gateway.wire.socket.messages import (
    MAX_ID_CHARS,
    MAX_MESSAGE_BYTES,
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

if TYPE_CHECKING:
    from collections.abc import Mapping

_ID_MIN, _ID_MAX = -(2**63), 2**63 - 1

#: Largest ``reset_odometry`` x and y, m: what ``WG_Odom_Pose`` carries (i24 mm, +-8388.608 m)
#: before it wraps.  Beyond that a pose is meaningless on CAN, and far beyond it stuck: at
#: 1e308 m no step of the odometry changes it (float precision).
MAX_RESET_POSITION_M = POSITION_WRAP_M / 2
#: Largest ``reset_odometry`` theta, rad: a heading may come unwrapped from another source
#: (turns counted); a thousand turns either way wrap to [-pi, pi) within about 1e-12 rad.
MAX_RESET_HEADING_RAD = 1000 * math.tau

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
            f"{where}: expected a number between {-limit:.10g} and {limit:.10g}, got "
            f"{short_json(value)}",
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
        x, y = (_number(obj, op, k, rid, MAX_RESET_POSITION_M) for k in ("x", "y"))
        theta = _number(obj, op, "theta", rid, MAX_RESET_HEADING_RAD)
        return ResetOdometryRequest(Pose(x, y, (theta + math.pi) % (2 * math.pi) - math.pi), rid)
    if op is Op.SUBSCRIBE:
        return SubscribeRequest(_topics(obj, rid), rid)
    return CommandRequest(op, rid)


class LineFramer:
    """Splits a byte stream into lines of at most ``max_bytes`` (pure; one per connection).

    A line is what precedes a ``\\n``, without it and without one trailing ``\\r``.  A line
    longer than ``max_bytes`` yields one :class:`ProtocolError` (``"message too long: ..., got
    more"``) -- as soon as its unfinished part exceeds the limit, before its newline arrives --
    and is never held whole: what of it was buffered is dropped at once and the rest skipped up
    to its newline.  So the framer holds at most ``max_bytes + 1`` bytes of an unfinished line
    plus the complete lines not yet taken: no more than one :meth:`push` brought, for a reader
    that pushes only once :meth:`pop` has returned ``None``.

    Lines are taken one at a time -- :meth:`push` what was received, then :meth:`pop` until it
    returns ``None`` -- so that a reader can leave some for later and receive nothing more
    meanwhile; :meth:`feed` does both at once.

    >>> framer = LineFramer(8)
    >>> framer.feed(b'{"a":1}\\r\\n{"b"'), framer.feed(b':2}\\n'), framer.pending
    ([b'{"a":1}'], [b'{"b":2}'], 0)

    :param max_bytes: longest accepted line in bytes.
    """

    __slots__ = ("_buf", "_discarding", "_errors", "_made", "_tail", "_taken", "max_bytes")

    def __init__(self, max_bytes: int = MAX_MESSAGE_BYTES) -> None:
        self.max_bytes = max_bytes
        #: Complete lines not yet taken (each with its newline), then the unfinished one.
        self._buf = bytearray()
        self._tail = 0  # where the unfinished line starts in _buf
        self._discarding = False  # inside a too-long line, skipping to its newline
        #: The sequence numbers of the too-long lines not yet reported.
        self._errors: deque[int] = deque()
        self._made = 0  # lines (too-long ones included) completed so far
        self._taken = 0  # ... and handed out by pop()

    @property
    def pending(self) -> int:
        """Bytes of an unfinished line held (0 while skipping a too-long one)."""
        return len(self._buf) - self._tail

    @property
    def in_line(self) -> bool:
        """Whether the stream stopped in the middle of a line (held, or being skipped)."""
        return self._discarding or len(self._buf) > self._tail

    @property
    def ready(self) -> bool:
        """Whether :meth:`pop` has a line (or a too-long error) to give."""
        return self._made > self._taken

    def push(self, data: bytes) -> None:
        """Take the next bytes of the stream (their complete lines wait for :meth:`pop`)."""
        size_in = len(data)
        pos = 0
        if size_in and (self._discarding or len(self._buf) > self._tail):
            pos = self._step(data, 0)  # finish the line in progress first
        if pos >= size_in:
            return
        rest = data[pos:] if pos else data
        if max(map(len, rest.split(b"\n"))) <= self.max_bytes:
            # No line in it is too long (the common case): take it whole, at C speed.
            last = rest.rfind(b"\n") + 1
            buf = self._buf
            if last:
                buf += rest[:last]
                self._made += rest.count(b"\n", 0, last)
                self._tail = len(buf)
            buf += rest[last:]
            return
        while pos < size_in:
            pos = self._step(data, pos)

    def _step(self, data: bytes, pos: int) -> int:
        """Take ``data`` from ``pos`` up to its next newline included (or to its end); return
        where the rest starts."""
        newline = data.find(b"\n", pos)
        if self._discarding:
            if newline < 0:
                return len(data)
            self._discarding = False
            return newline + 1
        buf = self._buf
        limit = self.max_bytes + 1  # + 1: room for a "\\r" before the "\\n"
        end = len(data) if newline < 0 else newline
        size = len(buf) - self._tail + end - pos
        if size > limit or (
            size == limit and newline >= 0 and (data[end - 1] if end > pos else buf[-1]) != 0x0D
        ):
            del buf[self._tail :]  # never held whole: what was buffered of it goes now
            self._errors.append(self._made)
            self._made += 1
            if newline < 0:
                self._discarding = True
                return len(data)
            return newline + 1
        if newline < 0:
            buf += memoryview(data)[pos:]
            return len(data)
        buf += memoryview(data)[pos : newline + 1]
        self._tail = len(buf)
        self._made += 1
        return newline + 1

    def pop(self) -> bytes | ProtocolError | None:
        """The next complete line (or the error that stands for a too-long one), in stream
        order; ``None`` when every complete line has been taken."""
        if self._errors and self._errors[0] == self._taken:
            self._errors.popleft()
            self._taken += 1
            return self._error()
        if not self._tail:
            return None
        buf = self._buf
        newline = buf.find(b"\n", 0, self._tail)
        end = newline - 1 if newline > 0 and buf[newline - 1] == 0x0D else newline
        line = bytes(buf[:end])
        del buf[: newline + 1]
        self._tail -= newline + 1
        self._taken += 1
        return line

    def feed(self, data: bytes) -> list[bytes | ProtocolError]:
        """:meth:`push` the next bytes of the stream; return every line now complete, in order."""
        self.push(data)
        out: list[bytes | ProtocolError] = []
        while (item := self.pop()) is not None:
            out.append(item)
        return out

    def _error(self) -> ProtocolError:
        return ProtocolError(
            f"message too long: expected at most {self.max_bytes} bytes, got more"
        )
