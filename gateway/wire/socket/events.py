"""The JSON form of the gateway's events (:mod:`gateway.core.events`): what the control
socket's subscribers read.  Pure: no I/O, no clock.

Each event is one line, its topic under ``"event"`` and its payload beside it::

    {"event": "error", "code": <lower-case ErrorCode name>, "message": "..."}
    {"event": "odometry", "x", "y", "theta", "vx", "vy", "wz", "slip", "distance", "t"}
    {"event": "status", "state": <lower-case GatewayState name>, "reason": "..."}

The odometry's keys are those of the status's ``odometry``
(:func:`gateway.wire.socket.status.odometry_to_json`); a float that is not finite is written
``null``, as everywhere in the protocol (:mod:`gateway.wire.socket`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from gateway.core.events import OdometryEvent, StatusEvent
from gateway.core.status import LastError, state_name
from gateway.wire.socket.messages import Topic
from gateway.wire.socket.replies import event as topic_line
from gateway.wire.socket.status_write import odometry_to_json

if TYPE_CHECKING:
    from gateway.core.events import OutboxEvent

__all__ = ["event_line", "event_to_json", "event_topic"]

_TOPICS: dict[type[OutboxEvent], Topic] = {
    LastError: Topic.ERROR,
    OdometryEvent: Topic.ODOMETRY,
    StatusEvent: Topic.STATUS,
}


def event_topic(event: OutboxEvent) -> Topic:
    """The topic whose subscribers get ``event``."""
    return _TOPICS[type(event)]


def event_to_json(event: OutboxEvent) -> dict[str, object]:
    """The event's payload as JSON data (the line adds ``"event"``: :func:`event_line`)."""
    if isinstance(event, OdometryEvent):
        return odometry_to_json(event.state)
    if isinstance(event, StatusEvent):
        return {"state": state_name(event.state), "reason": event.reason}
    return {"code": state_name(event.code), "message": event.message}


def event_line(event: OutboxEvent) -> bytes:
    """The line subscribers read: ``{"event": <topic>, ...payload}``, compact JSON, UTF-8,
    ``\\n``-terminated (:func:`gateway.wire.socket.replies.event`).

    >>> from gateway.core.types import GatewayState
    >>> event_line(StatusEvent(GatewayState.ESTOP, "e-stop requested"))
    b'{"event":"status","state":"estop","reason":"e-stop requested"}\\n'
    """
    return topic_line(event_topic(event), event_to_json(event))
