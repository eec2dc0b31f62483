"""The control-socket protocol: JSON lines in, JSON lines out.  Pure: no I/O, no clock.

Every message is one JSON object on one line (UTF-8, ``\\n``-terminated, at most
:data:`MAX_MESSAGE_BYTES` bytes without the newline; a trailing ``\\r`` is tolerated).  Requests::

    {"op": "twist", "vx": 0.1, "vy": 0.0, "wz": 0.2, "id": 7}   -> TwistRequest
    {"op": "stop"} / "estop" / "enable" / "disable" / "status"  -> CommandRequest
    {"op": "unsubscribe"}                                       -> CommandRequest
    {"op": "reset_odometry", "x": 0, "y": 0, "theta": 0}        -> ResetOdometryRequest
    {"op": "subscribe", "topics": ["odometry", "status"]}       -> SubscribeRequest

Any request may carry an ``"id"`` (an integer in the signed 64-bit range, or a string of at
most 64 characters) that the reply echoes.  Anything else -- unknown keys, an unknown op, wrong
types, duplicate keys, non-object JSON, invalid UTF-8 or JSON -- raises :class:`ProtocolError`,
whose message names the field, what was expected and what came, and which keeps the request id
when it could be read.  Replies and events::

    {"ok": true, "id": 7, ...payload}
    {"ok": false, "id": 7, "error": {"code": "infeasible_twist", "message": "...", ...details}}
    {"event": "odometry", ...payload}

Values are made JSON-safe by :func:`to_json`: non-finite floats become ``null``, flag enums a
list of lower-case member names, string enums their value, other enums their lower-case name,
dataclasses an object of their fields, tuples lists.
"""

from __future__ import annotations

import dataclasses
import enum
import json
import math
import numbers
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any, TypeAlias

from gateway.errors import EncodeError, GatewayError
from gateway.kinematics.odometry import Pose
from gateway.types import ErrorCode, Twist

#: Longest accepted message in bytes, newline excluded.
MAX_MESSAGE_BYTES = 4096
#: Longest accepted string request id, in characters.
MAX_ID_CHARS = 64
#: Largest accepted twist component magnitude (m/s or rad/s); larger is surely a mistake.
MAX_TWIST_COMPONENT = 100.0

#: A request id as it appears on the wire.
RequestId: TypeAlias = int | str

_ID_MIN, _ID_MAX = -(2**63), 2**63 - 1
_GOT_MAX_CHARS = 40


class Op(str, enum.Enum):
    """The ``"op"`` of a request."""

    TWIST = "twist"
    STOP = "stop"
    ESTOP = "estop"
    ENABLE = "enable"
    DISABLE = "disable"
    STATUS = "status"
    RESET_ODOMETRY = "reset_odometry"
    SUBSCRIBE = "subscribe"
    UNSUBSCRIBE = "unsubscribe"


class Topic(str, enum.Enum):
    """What a client can subscribe to."""

    ODOMETRY = "odometry"
    STATUS = "status"
    #: Faults and refused commands, as they happen.
    ERROR = "error"


class ProtocolError(GatewayError, ValueError):
    """A control-socket message that is not a valid request.

    :param message: names the field, what was expected and what came.
    :param request_id: the request's id when it could be read, else ``None``.
    """

    def __init__(self, message: str, request_id: RequestId | None = None) -> None:
        super().__init__(message)
        self.request_id = request_id


@dataclass(frozen=True, slots=True)
class TwistRequest:
    """Follow a body twist.

    :param twist: the commanded twist (each component finite, magnitude at most 100).
    :param id: the request id to echo, ``None`` if absent.
    """

    twist: Twist
    id: RequestId | None = None

    @property
    def op(self) -> Op:
        """Always :attr:`Op.TWIST`."""
        return Op.TWIST


@dataclass(frozen=True, slots=True)
class CommandRequest:
    """A request that takes no argument: stop, estop, enable, disable, status, unsubscribe.

    :param op: which one.
    :param id: the request id to echo, ``None`` if absent.
    """

    op: Op
    id: RequestId | None = None


@dataclass(frozen=True, slots=True)
class ResetOdometryRequest:
    """Set the odometry pose.

    :param pose: the new pose (origin by default; heading wrapped to [-pi, pi)).
    :param id: the request id to echo, ``None`` if absent.
    """

    pose: Pose = field(default_factory=Pose)
    id: RequestId | None = None

    @property
    def op(self) -> Op:
        """Always :attr:`Op.RESET_ODOMETRY`."""
        return Op.RESET_ODOMETRY


@dataclass(frozen=True, slots=True)
class SubscribeRequest:
    """Receive events of some topics on this connection.

    :param topics: the topics (at least one).
    :param id: the request id to echo, ``None`` if absent.
    """

    topics: frozenset[Topic]
    id: RequestId | None = None

    @property
    def op(self) -> Op:
        """Always :attr:`Op.SUBSCRIBE`."""
        return Op.SUBSCRIBE


#: Any parsed request.
Request: TypeAlias = TwistRequest | CommandRequest | ResetOdometryRequest | SubscribeRequest

_KEYS: dict[Op, tuple[str, ...]] = {
    Op.TWIST: ("vx", "vy", "wz"),
    Op.RESET_ODOMETRY: ("x", "y", "theta"),
    Op.SUBSCRIBE: ("topics",),
}


def _got(value: object) -> str:
    """A short JSON rendering of a received value for error messages."""
    try:
        text = json.dumps(value, ensure_ascii=False)
    except (TypeError, ValueError):  # not from json.loads; be safe anyway
        text = repr(value)
    return text if len(text) <= _GOT_MAX_CHARS else text[: _GOT_MAX_CHARS - 3] + "..."


def _json_type(value: object) -> str:
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "a boolean"
    if isinstance(value, (int, float)):
        return "a number"
    if isinstance(value, str):
        return "a string"
    if isinstance(value, list):
        return "an array"
    return "an object"


def _quoted(names: Iterable[str]) -> str:
    return ", ".join(f'"{n}"' for n in names)


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
        f"characters, got {_got(value)}"
    )


def _number(
    obj: Mapping[str, object], op: Op, key: str, rid: RequestId | None, limit: float | None
) -> float:
    value = obj.get(key, 0.0)
    where = f"{op.value}.{key}"
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ProtocolError(f"{where}: expected a finite number, got {_got(value)}", rid)
    if isinstance(value, float) and not math.isfinite(value):
        raise ProtocolError(f"{where}: expected a finite number, got {_got(value)}", rid)
    if limit is not None and abs(value) > limit:
        raise ProtocolError(
            f"{where}: expected a number between {-limit:g} and {limit:g}, got {_got(value)}",
            rid,
        )
    try:
        return float(value)
    except OverflowError as err:  # an integer beyond the float range
        raise ProtocolError(f"{where}: expected a finite number, got {_got(value)}", rid) from err


def _topics(obj: Mapping[str, object], rid: RequestId | None) -> frozenset[Topic]:
    names = _quoted(t.value for t in Topic)
    if "topics" not in obj:
        raise ProtocolError(f"subscribe.topics: expected an array of {names}, got nothing", rid)
    value = obj["topics"]
    if not isinstance(value, list) or not value:
        raise ProtocolError(
            f"subscribe.topics: expected a non-empty array of {names}, got {_got(value)}", rid
        )
    topics = set()
    for index, item in enumerate(value):
        try:
            topics.add(Topic(item))
        except ValueError:
            raise ProtocolError(
                f"subscribe.topics[{index}]: expected one of {names}, got {_got(item)}", rid
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
        raise ProtocolError(f"request: expected a JSON object, got {_json_type(obj)}")
    rid = _read_id(obj)
    if "op" not in obj:
        raise ProtocolError(
            f"request.op: expected one of {_quoted(o.value for o in Op)}, got nothing", rid
        )
    raw_op = obj["op"]
    try:
        op = Op(raw_op)
    except ValueError:
        raise ProtocolError(
            f"request.op: expected one of {_quoted(o.value for o in Op)}, got {_got(raw_op)}",
            rid,
        ) from None
    allowed = ("id", "op", *_KEYS.get(op, ()))
    for key in obj:
        if key not in allowed:
            raise ProtocolError(
                f"{op.value}: expected only the keys {_quoted(allowed)}, got {_got(key)}", rid
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


def to_json(value: object) -> Any:
    """``value`` as plain JSON-compatible data (see the module docstring for the rules).

    >>> to_json({"state": ErrorCode.ESTOP, "v": (1.0, float("nan")), "pose": Pose(1.0)})
    {'state': 'estop', 'v': [1.0, None], 'pose': {'x_m': 1.0, 'y_m': 0.0, 'theta_rad': 0.0}}

    :raises EncodeError: for a value with no JSON form (or a non-string, non-enum key).
    """
    if isinstance(value, enum.Flag):
        return [
            m.name.lower()
            for m in type(value)
            if m.name and m.value and m.value & (m.value - 1) == 0 and m in value
        ]
    if isinstance(value, enum.Enum):
        return value.value if isinstance(value, str) else value.name.lower()
    if value is None or isinstance(value, (bool, str)):
        return value
    if isinstance(value, numbers.Integral):
        return int(value)
    if isinstance(value, numbers.Real):
        number = float(value)
        return number if math.isfinite(number) else None
    if isinstance(value, Mapping):
        return {_key(k): to_json(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [to_json(v) for v in value]
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: to_json(getattr(value, f.name)) for f in dataclasses.fields(value)}
    raise EncodeError(f"reply value: expected JSON-compatible data, got {type(value).__name__}")


def _key(key: object) -> str:
    if isinstance(key, str):
        return key.value if isinstance(key, enum.Enum) else key
    if isinstance(key, enum.Enum):
        return key.name.lower()
    raise EncodeError(f"reply key: expected a string, got {type(key).__name__} {key!r}")


def encode_line(obj: Mapping[str, object]) -> bytes:
    """One JSON line (UTF-8, compact, ``\\n``-terminated) for an object.

    :raises EncodeError: for a value with no JSON form.
    """
    value = to_json(obj)
    text = json.dumps(value, ensure_ascii=False, allow_nan=False, separators=(",", ":"))
    try:
        return text.encode("utf-8") + b"\n"
    except UnicodeEncodeError:
        # A lone surrogate (JSON "\ud800") has no UTF-8 form: escape everything instead.
        text = json.dumps(value, ensure_ascii=True, allow_nan=False, separators=(",", ":"))
        return text.encode("ascii") + b"\n"


def _merge(head: dict[str, object], payload: Mapping[str, object], what: str) -> bytes:
    for key in payload:
        if key in head:
            raise EncodeError(f"{what} payload: expected keys other than "
                              f"{_quoted(head)}, got {_got(key)}")
    return encode_line({**head, **payload})


def reply_ok(request_id: RequestId | None, payload: Mapping[str, object] | None = None) -> bytes:
    """A success reply: ``{"ok": true, "id": ..., ...payload}``.

    >>> reply_ok(3, {"state": "running"})
    b'{"ok":true,"id":3,"state":"running"}\\n'

    :raises EncodeError: if the payload has an ``"ok"`` or ``"id"`` key or a non-JSON value.
    """
    return _merge({"ok": True, "id": request_id}, payload or {}, "reply")


def reply_error(
    request_id: RequestId | None, code: ErrorCode | str, message: str, **details: object
) -> bytes:
    """An error reply: ``{"ok": false, "id": ..., "error": {"code": ..., "message": ...}}``.

    >>> reply_error(None, ErrorCode.NOT_ENABLED, "enable first")
    b'{"ok":false,"id":null,"error":{"code":"not_enabled","message":"enable first"}}\\n'

    :param code: an :class:`~gateway.types.ErrorCode` (sent as its lower-case name) or a name.
    :param details: more fields of the error object (e.g. ``nearest=Twist(...)``).
    :raises EncodeError: for a detail value with no JSON form.
    """
    name = code.name.lower() if isinstance(code, ErrorCode) else code.lower()
    error = {"code": name, "message": message, **details}
    return encode_line({"ok": False, "id": request_id, "error": error})


def reply_protocol_error(err: ProtocolError) -> bytes:
    """The error reply to a message that failed to parse (code ``bad_command``)."""
    return reply_error(err.request_id, ErrorCode.BAD_COMMAND, str(err))


def event(topic: Topic | str, payload: Mapping[str, object]) -> bytes:
    """An event line: ``{"event": "odometry", ...payload}``.

    :raises EncodeError: if the payload has an ``"event"`` key or a non-JSON value.
    """
    name = topic.value if isinstance(topic, Topic) else topic
    return _merge({"event": name}, payload, "event")


def parse_message(line: bytes) -> dict[str, Any]:
    """Parse one line from the gateway (a reply or an event) -- the client's side.

    :raises ProtocolError: if it is not one JSON object in UTF-8.
    """
    try:
        obj = json.loads(line.decode("utf-8"))
    except (UnicodeDecodeError, ValueError, RecursionError) as err:
        raise ProtocolError(f"gateway message: expected a JSON object, got {err}") from err
    if not isinstance(obj, dict):
        raise ProtocolError(f"gateway message: expected a JSON object, got {_json_type(obj)}")
    return obj
