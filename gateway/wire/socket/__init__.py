"""The control-socket protocol: JSON lines in, JSON lines out.  Pure: no I/O, no clock.

Every message is one JSON object on one line (UTF-8, ``\\n``-terminated, at most
:data:`MAX_MESSAGE_BYTES` bytes without the newline -- the control server takes at most
:data:`MAX_REQUEST_BYTES` by default; a trailing ``\\r`` is tolerated).  Requests::

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

* :mod:`gateway.wire.socket.messages`: the ops, topics, request types and :class:`ProtocolError`.
* :mod:`gateway.wire.socket.parsing`: :class:`LineFramer` and :func:`parse_request` (inbound).
* :mod:`gateway.wire.socket.replies`: :func:`to_json`, the reply and event lines, and
  :func:`parse_message` for clients (outbound).
* :mod:`gateway.wire.socket.status`: the ``status`` reply's payload, the JSON form of
  :class:`gateway.core.status.GatewayStatus` (:func:`status_to_json` in
  :mod:`~gateway.wire.socket.status_write`, :func:`status_from_json` in
  :mod:`~gateway.wire.socket.status_read`).
* :mod:`gateway.wire.socket.events`: the events' lines, the JSON form of
  :mod:`gateway.core.events` (:func:`event_line`).
"""

from __future__ import annotations

from gateway.core.types import MAX_TWIST_COMPONENT
from gateway.wire.socket.events import event_line, event_to_json, event_topic
from gateway.wire.socket.messages import (
    MAX_ID_CHARS,
    MAX_MESSAGE_BYTES,
    MAX_REQUEST_BYTES,
    CommandRequest,
    Op,
    ProtocolError,
    Request,
    RequestId,
    ResetOdometryRequest,
    SubscribeRequest,
    Topic,
    TwistRequest,
)
from gateway.wire.socket.parsing import LineFramer, parse_request
from gateway.wire.socket.replies import (
    encode_data_line,
    encode_line,
    event,
    parse_message,
    reply_error,
    reply_ok,
    reply_ok_data,
    reply_protocol_error,
    to_json,
)
from gateway.wire.socket.status import odometry_to_json, status_from_json, status_to_json

__all__ = [
    "MAX_ID_CHARS",
    "MAX_MESSAGE_BYTES",
    "MAX_REQUEST_BYTES",
    "MAX_TWIST_COMPONENT",
    "CommandRequest",
    "LineFramer",
    "Op",
    "ProtocolError",
    "Request",
    "RequestId",
    "ResetOdometryRequest",
    "SubscribeRequest",
    "Topic",
    "TwistRequest",
    "encode_data_line",
    "encode_line",
    "event",
    "event_line",
    "event_to_json",
    "event_topic",
    "odometry_to_json",
    "parse_message",
    "parse_request",
    "reply_error",
    "reply_ok",
    "reply_ok_data",
    "reply_protocol_error",
    "status_from_json",
    "status_to_json",
    "to_json",
]
