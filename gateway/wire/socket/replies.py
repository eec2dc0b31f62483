"""The outbound side of the control socket: replies and events as JSON lines.

:func:`to_json` makes values JSON-safe (see :mod:`gateway.wire.socket` for the rules),
:func:`reply_ok`, :func:`reply_error` and :func:`event` build the lines the gateway sends
(:func:`reply_ok_data` for a payload that a format wrote as JSON data already), and
:func:`parse_message` reads them back on the client's side.  Pure: no I/O, no clock.
"""

from __future__ import annotations

import dataclasses
import enum
import json
import math
import numbers
from collections.abc import Mapping
from typing import Any

from gateway.core.errors import EncodeError
from gateway.core.types import ErrorCode
from gateway.wire.socket.messages import (
    ProtocolError,
    RequestId,
    Topic,
    json_type,
    quoted,
    short_json,
)


def to_json(value: object) -> Any:
    """``value`` as plain JSON-compatible data (see the module docstring for the rules).

    >>> from gateway.core.kinematics.odometry import Pose
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


def _data_default(value: object) -> Any:
    """What :func:`encode_data_line` makes of a value ``json`` does not take: numbers of
    other types (NumPy's) as :func:`to_json` makes them."""
    if isinstance(value, numbers.Integral) and not isinstance(value, enum.Enum):
        return int(value)
    if isinstance(value, numbers.Real) and not isinstance(value, enum.Enum):
        number = float(value)
        return number if math.isfinite(number) else None
    raise EncodeError(f"reply value: expected JSON data, got {type(value).__name__}")


def encode_data_line(obj: Mapping[str, object]) -> bytes:
    """:func:`encode_line` for an object that is JSON data already -- dicts with string keys,
    lists, strings, numbers (finite floats), booleans and ``None``, as a format such as
    :func:`gateway.wire.socket.status.status_to_json` writes it: the same line, without
    :func:`to_json`'s walk over every value (a third of the time, for a status reply).

    :raises EncodeError: for a value that is no JSON data.
    """
    try:
        text = json.dumps(obj, ensure_ascii=False, allow_nan=False, separators=(",", ":"),
                          default=_data_default)
        return text.encode("utf-8") + b"\n"
    except UnicodeEncodeError:  # a lone surrogate, as in encode_line
        text = json.dumps(obj, ensure_ascii=True, allow_nan=False, separators=(",", ":"),
                          default=_data_default)
        return text.encode("ascii") + b"\n"
    except (TypeError, ValueError) as err:  # a non-string key; a float that is not finite
        raise EncodeError(f"reply value: expected JSON data, got {err}") from err


def _check_keys(head: Mapping[str, object], payload: Mapping[str, object], what: str) -> None:
    for key in payload:
        if key in head:
            raise EncodeError(f"{what} payload: expected keys other than "
                              f"{quoted(head)}, got {short_json(key)}")


def _merge(head: dict[str, object], payload: Mapping[str, object], what: str) -> bytes:
    _check_keys(head, payload, what)
    return encode_line({**head, **payload})


def reply_ok(request_id: RequestId | None, payload: Mapping[str, object] | None = None) -> bytes:
    """A success reply: ``{"ok": true, "id": ..., ...payload}``.

    >>> reply_ok(3, {"state": "running"})
    b'{"ok":true,"id":3,"state":"running"}\\n'

    :raises EncodeError: if the payload has an ``"ok"`` or ``"id"`` key or a non-JSON value.
    """
    return _merge({"ok": True, "id": request_id}, payload or {}, "reply")


def reply_ok_data(request_id: RequestId | None, payload: Mapping[str, object]) -> bytes:
    """:func:`reply_ok` for a payload that is JSON data already (see :func:`encode_data_line`).

    :raises EncodeError: if the payload has an ``"ok"`` or ``"id"`` key or a value that is no
        JSON data.
    """
    head: dict[str, object] = {"ok": True, "id": request_id}
    _check_keys(head, payload, "reply")
    return encode_data_line({**head, **payload})


def reply_error(
    request_id: RequestId | None, code: ErrorCode | str, message: str, **details: object
) -> bytes:
    """An error reply: ``{"ok": false, "id": ..., "error": {"code": ..., "message": ...}}``.

    >>> reply_error(None, ErrorCode.NOT_ENABLED, "enable first")
    b'{"ok":false,"id":null,"error":{"code":"not_enabled","message":"enable first"}}\\n'

    :param code: an :class:`~gateway.core.types.ErrorCode` (sent as its lower-case name) or a name.
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
        raise ProtocolError(f"gateway message: expected a JSON object, got {json_type(obj)}")
    return obj
