"""Fuzzing of the gateway's control-socket input.

Structure-aware mutations of valid requests (huge numbers, NaN and infinity literals, deep
nesting, unicode, duplicate and unknown keys, truncation) through ``parse_request``: a request
or ``ProtocolError``, and the reply to either encodes; and end to end, a daemon on simulated
time answers every garbage line with a ``bad_command`` error and changes nothing else (state,
wheel speeds, odometry, counters but the parse errors).
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import math
import shutil
import tempfile
from typing import TYPE_CHECKING

import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from gateway.core.types import GatewayState
from gateway.wire.socket import (
    MAX_TWIST_COMPONENT,
    ProtocolError,
    ResetOdometryRequest,
    TwistRequest,
    parse_request,
    reply_ok,
    reply_protocol_error,
)
from tests.conftest import CONFIG_DIR
from tests.e2e_helpers import Rig, SocketPilot
from tests.wire.fuzz_input_helpers import FUZZ, running

if TYPE_CHECKING:
    from collections.abc import Iterator


@contextlib.contextmanager
def socket_dir() -> Iterator[str]:
    """A short socket path in a private directory (AF_UNIX paths are short)."""
    folder = tempfile.mkdtemp(prefix="wgfz", dir="/tmp")
    try:
        yield f"{folder}/s.sock"
    finally:
        shutil.rmtree(folder, ignore_errors=True)


# =============================================================================== control socket

VALID_REQUESTS: list[dict[str, object]] = [
    {"op": "twist", "vx": 0.1, "vy": 0.0, "wz": 0.2, "id": 7},
    {"op": "stop"},
    {"op": "estop", "id": "e"},
    {"op": "enable"},
    {"op": "disable", "id": -3},
    {"op": "status", "id": 1},
    {"op": "reset_odometry", "x": 1.0, "y": -2.0, "theta": 0.5},
    {"op": "subscribe", "topics": ["odometry", "status"], "id": "s"},
    {"op": "unsubscribe"},
]
#: JSON literals Python's json reads but no request accepts as a number.
RAW_LITERALS = ["NaN", "Infinity", "-Infinity", "1e400", "-1e999", "1" + "0" * 400,
                "-" + "9" * 4000, "1e-400", "123456789012345678901234567890", "true", "null",
                "0x10", "01", "1.", ".5", "+1", "--1", "1e", "\"\\ud83d\\ude00\""]


def unicode_text(surrogates: bool) -> st.SearchStrategy[str]:
    chars = st.characters(exclude_categories=()) if surrogates else st.characters(codec="utf-8")
    odd = ["twist", "\u00f6p", "\u03c4wist", "twist\u0000", "\u202etsiwt", "\U0001f680",
           "\uff54\uff57\uff49\uff53\uff54", "TWIST", " twist"]  # fullwidth "twist"
    return st.text(chars, max_size=12) | st.sampled_from(odd)


@st.composite
def json_fragments(draw: st.DrawFn, surrogates: bool) -> str:
    """A JSON value as text: awkward literals, deep nesting, unicode, or a random value."""
    kind = draw(st.sampled_from(["literal", "nest", "unicode", "value", "number"]))
    if kind == "literal":
        return draw(st.sampled_from(RAW_LITERALS))
    if kind == "nest":
        depth = draw(st.sampled_from([2, 50, 500, 1500]))
        opener, closer = draw(st.sampled_from([("[", "]"), ('{"a":', "}")]))
        return opener * depth + "0" + closer * depth
    if kind == "unicode":
        return json.dumps(draw(unicode_text(surrogates)), ensure_ascii=draw(st.booleans()))
    if kind == "number":
        return json.dumps(draw(st.floats(allow_nan=True) | st.integers(-(2**70), 2**70)))
    value = draw(st.recursive(st.none() | st.booleans() | st.integers() | st.floats()
                              | unicode_text(surrogates),
                              lambda c: st.lists(c, max_size=3)
                              | st.dictionaries(unicode_text(surrogates), c, max_size=3),
                              max_leaves=6))
    return json.dumps(value)


@st.composite
def mutated_requests(draw: st.DrawFn, surrogates: bool = False) -> str:
    """A valid request with 1..3 structural mutations, as JSON text (maybe then cut)."""
    base = draw(st.sampled_from(VALID_REQUESTS))
    items = [(k, json.dumps(v)) for k, v in base.items()]
    for _ in range(draw(st.integers(1, 3))):
        op = draw(st.sampled_from(["value", "value", "delete", "add", "duplicate", "rename"]))
        k = draw(st.integers(0, max(len(items) - 1, 0)))
        if op == "value" and items:
            items[k] = (items[k][0], draw(json_fragments(surrogates)))
        elif op == "delete" and items:
            del items[k]
        elif op == "duplicate" and items:
            items.insert(k, items[k])
        elif op == "rename" and items:
            items[k] = (draw(unicode_text(surrogates)), items[k][1])
        else:
            name = draw(st.sampled_from(["op", "id", "vx", "topics", "x", "extra"])
                        | unicode_text(surrogates))
            items.insert(k, (name, draw(json_fragments(surrogates))))
    text = "{" + ",".join(f"{json.dumps(k)}:{v}" for k, v in items) + "}"
    if draw(st.integers(0, 4)) == 0:
        text = text[: draw(st.integers(0, len(text)))]
    return text


def check_parse_and_reply(line: bytes) -> ProtocolError | None:
    """Parse ``line``; whatever comes out, the reply to it encodes as one JSON line."""
    try:
        request = parse_request(line)
    except ProtocolError as err:
        reply = reply_protocol_error(err)
        body = json.loads(reply.decode("utf-8"))
        assert reply.endswith(b"\n") and reply.count(b"\n") == 1
        assert body["ok"] is False and body["error"]["code"] == "bad_command"
        return err
    if isinstance(request, TwistRequest):
        tw = request.twist
        assert all(math.isfinite(v) and abs(v) <= MAX_TWIST_COMPONENT
                   for v in (tw.vx_m_s, tw.vy_m_s, tw.wz_rad_s))
    if isinstance(request, ResetOdometryRequest):
        pose = request.pose
        assert all(math.isfinite(v) for v in (pose.x_m, pose.y_m, pose.theta_rad))
    json.loads(reply_ok(request.id, {}).decode("utf-8"))
    return None


@settings(FUZZ, max_examples=400)
@given(text=mutated_requests(), as_bytes=st.booleans())
def test_mutated_requests_parse_or_fail_cleanly_and_every_reply_encodes(
    text: str, as_bytes: bool
) -> None:
    check_parse_and_reply(text.encode("utf-8") if as_bytes else text)  # type: ignore[arg-type]


@settings(FUZZ, max_examples=200)
@given(data=st.binary(max_size=300) | st.binary(min_size=4090, max_size=4200))
def test_random_bytes_fail_cleanly_and_every_reply_encodes(data: bytes) -> None:
    check_parse_and_reply(data)


@settings(FUZZ, report_multiple_bugs=False)
@example(text='{"op": "\\ud800"}')
@example(text='{"op": "estop", "id": "\\udc80"}')
@given(text=mutated_requests(surrogates=True))
def test_lone_surrogates_parse_or_fail_cleanly_and_every_reply_encodes(text: str) -> None:
    check_parse_and_reply(text.encode("utf-8"))


garbage_lines = (
    st.binary(min_size=1, max_size=300)
    | mutated_requests().map(lambda s: s.encode("utf-8"))
    | st.sampled_from([b"x" * 5000, b'{"op":"twist","vx":' + b"1" * 5000 + b"}"])
).map(lambda b: b.replace(b"\n", b" ")).filter(lambda b: bool(b.strip()))


def _invalid(line: bytes) -> bool:
    try:
        parse_request(line)
    except ProtocolError:
        return True
    return False


def _snapshot(rig: Rig) -> dict[str, object]:
    gw = rig.gw
    assert rig.daemon is not None
    server = rig.daemon.server.counters
    odom = gw.odometry.state
    return {
        "state": gw.state,
        "gateway": {k: v for k, v in {**dataclasses.asdict(gw.counts),
                                      **dataclasses.asdict(gw.edge.counts)}.items()
                    if k not in ("cycles", "frames_sent", "frames_received")},
        "supervisor": dataclasses.asdict(gw.supervisor.counts),
        "rejected": [dict(drv.rejected) for drv, _ in gw.drives.groups],
        "server": {k: v for k, v in dataclasses.asdict(server).items()
                   if k not in ("malformed", "too_long")},
        "parse_errors": server.malformed + server.too_long,
        "pose": (odom.pose.x_m, odom.pose.y_m, odom.pose.theta_rad, odom.distance_m),
        "target": gw.supervisor.target,
    }


def _replies(rig: Rig, pilot: SocketPilot, expected: int) -> list[dict[str, object]]:
    got: list[dict[str, object]] = []
    for _ in range(200):
        got += pilot.messages()
        if len(got) >= expected:
            break
        rig.advance(rig.period)
    rig.advance(3 * rig.period)
    return got + pilot.messages()


@FUZZ
@given(lines=st.lists(garbage_lines.filter(_invalid), min_size=1, max_size=8))
def test_daemon_answers_every_garbage_line_and_changes_nothing(lines: list[bytes]) -> None:
    with socket_dir() as path, running(CONFIG_DIR / "turtlebot3_burger.yaml", path) as rig:
        pilot = SocketPilot(path)
        try:
            rig.advance(rig.period)
            before = _snapshot(rig)
            speeds: list[tuple[float, ...]] = []
            for line in lines:
                pilot.sock.sendall(line + b"\n")
                rig.advance(rig.period, lambda r: speeds.append(r.gw.prev.wheel_rad_s))
            replies = _replies(rig, pilot, len(lines))
            after = _snapshot(rig)
        finally:
            pilot.close()
    assert len(replies) == len(lines), replies
    for reply in replies:
        assert reply["ok"] is False
        error = reply["error"]
        assert isinstance(error, dict) and error["code"] == "bad_command"
    assert after["parse_errors"] == before["parse_errors"] + len(lines)  # type: ignore[operator]
    before["parse_errors"] = after["parse_errors"]
    assert after == before
    assert all(w == 0.0 for s in speeds for w in s)


@pytest.mark.parametrize("line", [b'{"op": "\\ud800"}', b'{"op": "estop", "id": "\\udc80"}'])
def test_daemon_survives_a_lone_surrogate(line: bytes) -> None:
    with socket_dir() as path, running(CONFIG_DIR / "turtlebot3_burger.yaml", path) as rig:
        pilot = SocketPilot(path)
        try:
            pilot.sock.sendall(line + b"\n")
            replies = _replies(rig, pilot, 1)
        finally:
            pilot.close()
        assert len(replies) == 1
        assert rig.gw.state in (GatewayState.RUNNING, GatewayState.ESTOP)
