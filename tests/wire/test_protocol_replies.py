"""The control-socket protocol's framing and replies: the line framer, reply and event encoding,
JSON conversion, and the client's parsing of messages."""

from __future__ import annotations

import json
import math
from typing import TYPE_CHECKING

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gateway.core.errors import EncodeError
from gateway.core.kinematics.odometry import Pose
from gateway.core.types import DriveFault, ErrorCode, GatewayState, Twist
from gateway.wire.socket import (
    LineFramer,
    Op,
    ProtocolError,
    Topic,
    encode_line,
    event,
    parse_message,
    parse_request,
    reply_error,
    reply_ok,
    reply_protocol_error,
    to_json,
)

if TYPE_CHECKING:
    from collections.abc import Callable

pytestmark = pytest.mark.timeout(30)


# -- framing ---------------------------------------------------------------------------------

TOO_LONG = "message too long: expected at most 16 bytes, got more"


def _framed(framer: LineFramer, chunks: list[bytes]) -> list[bytes | str]:
    out: list[bytes | str] = []
    for chunk in chunks:
        out += [str(x) if isinstance(x, ProtocolError) else x for x in framer.feed(chunk)]
    return out


@settings(max_examples=300, deadline=None)
@given(
    st.lists(st.binary(max_size=40).map(lambda b: b.replace(b"\n", b"")), max_size=8),
    st.lists(st.integers(0, 50), max_size=40),
    st.binary(max_size=30).map(lambda b: b.replace(b"\n", b"")),
)
def test_framer_output_does_not_depend_on_chunking(
    lines: list[bytes], cuts: list[int], tail: bytes
) -> None:
    stream = b"".join(line + b"\n" for line in lines) + tail
    expected: list[bytes | str] = []
    for line in lines:
        body = line.removesuffix(b"\r")
        expected.append(body if len(body) <= 16 else TOO_LONG)
    if len(tail) > 17:
        expected.append(TOO_LONG)
    chunks, pos = [], 0
    for cut in [*cuts, len(stream)]:
        chunks.append(stream[pos : pos + cut])
        pos += cut
    framer = LineFramer(16)
    assert _framed(framer, chunks) == expected
    assert framer.pending == (len(tail) if len(tail) <= 17 else 0)


def test_framer_skips_a_too_long_line_with_bounded_memory() -> None:
    framer = LineFramer(16)
    assert _framed(framer, [b"x" * 17]) == []  # could still be 16 bytes + "\r"
    assert _framed(framer, [b"x"]) == [TOO_LONG]  # reported before its newline
    assert framer.pending == 0
    assert _framed(framer, [b"y" * 100_000] * 10) == []  # skipped, not buffered
    assert framer.pending == 0
    assert _framed(framer, [b'y\n{"op":"stop"}\n\n']) == [b'{"op":"stop"}', b""]
    assert _framed(framer, [b"z" * 16 + b"\r\n", b"\r\n"]) == [b"z" * 16, b""]
    assert _framed(LineFramer(), [b"a" * 4097 + b"\n"]) == [
        "message too long: expected at most 4096 bytes, got more"
    ]


# -- replies and events ----------------------------------------------------------------------


def test_reply_ok_puts_ok_and_id_first() -> None:
    line = reply_ok(7, {"state": GatewayState.RUNNING, "twist": Twist(0.5, 0.0, -1.0)})
    assert line == (
        b'{"ok":true,"id":7,"state":"running",'
        b'"twist":{"vx_m_s":0.5,"vy_m_s":0.0,"wz_rad_s":-1.0}}\n'
    )
    assert reply_ok(None) == b'{"ok":true,"id":null}\n'
    assert reply_ok("a", {}) == b'{"ok":true,"id":"a"}\n'


def test_reply_error_uses_lower_case_code_names_and_details() -> None:
    line = reply_error(
        3, ErrorCode.INFEASIBLE_TWIST, "wheel 'fl' slips", wheel="fl", nearest=Twist(0.1)
    )
    assert json.loads(line) == {
        "ok": False,
        "id": 3,
        "error": {
            "code": "infeasible_twist",
            "message": "wheel 'fl' slips",
            "wheel": "fl",
            "nearest": {"vx_m_s": 0.1, "vy_m_s": 0.0, "wz_rad_s": 0.0},
        },
    }
    assert json.loads(reply_error(None, "Busy", "later"))["error"]["code"] == "busy"


def test_reply_protocol_error_keeps_the_request_id() -> None:
    with pytest.raises(ProtocolError) as info:
        parse_request(b'{"op": "twist", "vx": "fast", "id": 12}')
    assert reply_protocol_error(info.value) == (
        b'{"ok":false,"id":12,"error":{"code":"bad_command",'
        b'"message":"twist.vx: expected a finite number, got \\"fast\\""}}\n'
    )


def test_event_line() -> None:
    line = event(Topic.ODOMETRY, {"pose": Pose(1.0, 2.0, 0.5), "t": 1.25})
    assert line == (
        b'{"event":"odometry","pose":{"x_m":1.0,"y_m":2.0,"theta_rad":0.5},"t":1.25}\n'
    )
    assert event("status", {}) == b'{"event":"status"}\n'


def test_json_conversion_of_awkward_values() -> None:
    value = {
        "nan": math.nan,
        "inf": (math.inf, -math.inf, 1.5),
        "code": ErrorCode.ESTOP,
        "op": Op.TWIST,
        "faults": DriveFault.ENCODER | DriveFault.OVER_CURRENT,
        "healthy": DriveFault.NONE,
        Topic.STATUS: [GatewayState.FAULT],
        "nested": {"list": [None, True, "é"]},
    }
    assert to_json(value) == {
        "nan": None,
        "inf": [None, None, 1.5],
        "code": "estop",
        "op": "twist",
        "faults": ["over_current", "encoder"],
        "healthy": [],
        "status": ["fault"],
        "nested": {"list": [None, True, "é"]},
    }
    line = encode_line({"v": math.nan, "s": "é"})
    assert line == '{"v":null,"s":"é"}\n'.encode()


def test_numpy_scalars_are_plain_numbers() -> None:
    np = pytest.importorskip("numpy")
    assert to_json([np.float64(0.5), np.int64(3), np.float32("nan")]) == [0.5, 3, None]


KEYS_OK_ID = 'expected keys other than "ok", "id"'
JSON_DATA = "expected JSON-compatible data"


@pytest.mark.parametrize(
    ("build", "message"),
    [
        (lambda: reply_ok(1, {"ok": False}), f'reply payload: {KEYS_OK_ID}, got "ok"'),
        (lambda: reply_ok(1, {"id": 2}), f'reply payload: {KEYS_OK_ID}, got "id"'),
        (
            lambda: event(Topic.STATUS, {"event": 1}),
            'event payload: expected keys other than "event", got "event"',
        ),
        (lambda: reply_ok(1, {"x": object()}), f"reply value: {JSON_DATA}, got object"),
        (lambda: reply_ok(1, {"x": {1: 2}}), "reply key: expected a string, got int 1"),
        (lambda: encode_line({"s": {1, 2}}), f"reply value: {JSON_DATA}, got set"),
    ],
)
def test_encoding_errors(build: Callable[[], bytes], message: str) -> None:
    with pytest.raises(EncodeError) as info:
        build()
    assert str(info.value) == message


def test_parse_message_for_the_client() -> None:
    assert parse_message(b'{"ok": true, "id": 1}') == {"ok": True, "id": 1}
    with pytest.raises(ProtocolError, match="expected a JSON object, got an array"):
        parse_message(b"[]")
    with pytest.raises(ProtocolError, match="gateway message: expected a JSON object, got "):
        parse_message(b"\xff")
    with pytest.raises(ProtocolError, match="gateway message: expected a JSON object, got "):
        parse_message(b"nope")
