"""The events' JSON form (:mod:`gateway.wire.socket.events`): each event's line, key by key,
and the same line the daemon wrote before the outbox was typed (issue 15), when it put
``(topic, dict)`` pairs in its outbox and sent ``event(topic, payload)``."""

from __future__ import annotations

import json
import math
from typing import TYPE_CHECKING

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gateway.core.events import OdometryEvent, StatusEvent
from gateway.core.kinematics.odometry import OdometryState, Pose
from gateway.core.status import LastError
from gateway.core.types import ErrorCode, GatewayState, Twist
from gateway.wire.socket import Topic, event, event_line, event_to_json, event_topic

if TYPE_CHECKING:
    from gateway.core.events import OutboxEvent

NAN, INF = math.nan, math.inf


def legacy_line(ev: OutboxEvent) -> bytes:
    """The event's line as the daemon sent it before the outbox was typed: the publisher's
    dictionaries (``gateway/runtime/publish.py`` before issue 15) through :func:`event`."""
    if isinstance(ev, LastError):
        return event("error", {"code": ev.code.name.lower(), "message": ev.message})
    if isinstance(ev, StatusEvent):
        return event("status", {"state": ev.state, "reason": ev.reason})
    st_ = ev.state
    return event("odometry", {
        "x": st_.pose.x_m, "y": st_.pose.y_m, "theta": st_.pose.theta_rad,
        "vx": st_.twist.vx_m_s, "vy": st_.twist.vy_m_s, "wz": st_.twist.wz_rad_s,
        "slip": st_.slip_m_s, "distance": st_.distance_m, "t": st_.timestamp_s,
    })


def _odometry(*values: float) -> OdometryEvent:
    x, y, theta, vx, vy, wz, slip, distance, t = values
    return OdometryEvent(OdometryState(Pose(x, y, theta), Twist(vx, vy, wz), slip, distance, t))


@pytest.mark.parametrize(("ev", "topic", "line"), [
    (LastError(ErrorCode.FEEDBACK_TIMEOUT, "motor 'right' (node 2) stopped answering"),
     Topic.ERROR,
     b'{"event":"error","code":"feedback_timeout",'
     b'"message":"motor \'right\' (node 2) stopped answering"}\n'),
    (StatusEvent(GatewayState.RUNNING, ""), Topic.STATUS,
     b'{"event":"status","state":"running","reason":""}\n'),
    (StatusEvent(GatewayState.ESTOP, "e-stop requested on CAN"), Topic.STATUS,
     b'{"event":"status","state":"estop","reason":"e-stop requested on CAN"}\n'),
    (_odometry(1.5, -2.25, 0.5, 0.1, 0.0, -0.25, 0.001, 3.0, 12.5), Topic.ODOMETRY,
     b'{"event":"odometry","x":1.5,"y":-2.25,"theta":0.5,"vx":0.1,"vy":0.0,"wz":-0.25,'
     b'"slip":0.001,"distance":3.0,"t":12.5}\n'),
    # A float that is not finite is null, as everywhere in the protocol.
    (_odometry(NAN, INF, -INF, 0.0, 0.0, 0.0, NAN, 1.0, 2.0), Topic.ODOMETRY,
     b'{"event":"odometry","x":null,"y":null,"theta":null,"vx":0.0,"vy":0.0,"wz":0.0,'
     b'"slip":null,"distance":1.0,"t":2.0}\n'),
    # Not ASCII, and a lone surrogate (which has no UTF-8 form: the line is escaped ASCII).
    (LastError(ErrorCode.BAD_COMMAND, "vitesse \u00e9lev\u00e9e"), Topic.ERROR,
     '{"event":"error","code":"bad_command","message":"vitesse \u00e9lev\u00e9e"}\n'
     .encode()),
    (LastError(ErrorCode.BAD_COMMAND, "\ud800"), Topic.ERROR,
     b'{"event":"error","code":"bad_command","message":"\\ud800"}\n'),
])
def test_each_event_is_one_line_of_its_topic(ev: OutboxEvent, topic: Topic, line: bytes) -> None:
    assert event_topic(ev) is topic
    assert event_line(ev) == line
    assert line == legacy_line(ev)
    assert json.loads(line) == {"event": topic.value, **event_to_json(ev)}


_floats = st.floats(allow_nan=True, allow_infinity=True)
_text = st.text(max_size=20)
_events = st.one_of(
    st.builds(LastError, st.sampled_from(list(ErrorCode)), _text),
    st.builds(StatusEvent, st.sampled_from(list(GatewayState)), _text),
    st.builds(_odometry, *[_floats] * 9),
)


@settings(max_examples=300, deadline=None)
@given(ev=_events)
def test_every_event_is_the_line_the_daemon_sent_before(ev: OutboxEvent) -> None:
    assert event_line(ev) == legacy_line(ev)
