"""The control-socket protocol: request parsing, exact error messages, reply encoding, fuzzing."""

from __future__ import annotations

import json
import math
from typing import TYPE_CHECKING, Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gateway.core.errors import EncodeError, GatewayError
from gateway.core.kinematics.odometry import Pose
from gateway.core.types import DriveFault, ErrorCode, GatewayState, Twist
from gateway.wire.socket import (
    MAX_MESSAGE_BYTES,
    CommandRequest,
    LineFramer,
    Op,
    ProtocolError,
    Request,
    ResetOdometryRequest,
    SubscribeRequest,
    Topic,
    TwistRequest,
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

OPS = (
    '"twist", "stop", "estop", "enable", "disable", "status", "reset_odometry", "subscribe", '
    '"unsubscribe"'
)


# -- requests --------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("line", "expected"),
    [
        (b'{"op": "twist", "vx": 0.1, "vy": -0.2, "wz": 0.3}', TwistRequest(Twist(0.1, -0.2, 0.3))),
        (b'{"op": "twist", "wz": 1}', TwistRequest(Twist(0.0, 0.0, 1.0))),
        (b'{"op": "twist"}', TwistRequest(Twist())),
        (b'{"op": "twist", "vx": -100, "id": 7}', TwistRequest(Twist(-100.0), 7)),
        (b'{"id": "abc", "op": "twist", "vy": 100.0}', TwistRequest(Twist(0.0, 100.0), "abc")),
        (b'{"op": "stop"}', CommandRequest(Op.STOP)),
        (b'{"op": "estop", "id": -1}', CommandRequest(Op.ESTOP, -1)),
        (b'{"op": "enable", "id": ""}', CommandRequest(Op.ENABLE, "")),
        (b'{"op": "disable"}', CommandRequest(Op.DISABLE)),
        (b'{"op": "status", "id": 9223372036854775807}', CommandRequest(Op.STATUS, 2**63 - 1)),
        (b'{"op": "unsubscribe"}', CommandRequest(Op.UNSUBSCRIBE)),
        (b'{"op": "reset_odometry"}', ResetOdometryRequest(Pose())),
        (
            b'{"op": "reset_odometry", "x": 1.5, "y": -2, "theta": 0.5, "id": 3}',
            ResetOdometryRequest(Pose(1.5, -2.0, 0.5), 3),
        ),
        (
            b'{"op": "subscribe", "topics": ["odometry", "status", "odometry"]}',
            SubscribeRequest(frozenset({Topic.ODOMETRY, Topic.STATUS})),
        ),
        (
            b'{"op":"subscribe","topics":["status"],"id":1}',
            SubscribeRequest(frozenset({Topic.STATUS}), 1),
        ),
    ],
)
def test_parse_every_request_type(line: bytes, expected: Request) -> None:
    assert parse_request(line) == expected
    assert parse_request(line + b"\n") == expected
    assert parse_request(line + b"\r\n") == expected
    assert parse_request(line.decode() + "\n") == expected
    assert parse_request(line).op == expected.op


def test_request_op_properties() -> None:
    assert TwistRequest(Twist()).op is Op.TWIST
    assert ResetOdometryRequest().op is Op.RESET_ODOMETRY
    assert SubscribeRequest(frozenset()).op is Op.SUBSCRIBE
    assert isinstance(Op.TWIST, str)
    assert Op.TWIST.value == "twist"
    assert Op("reset_odometry") is Op.RESET_ODOMETRY


def test_reset_odometry_wraps_heading() -> None:
    request = parse_request(b'{"op": "reset_odometry", "theta": 7}')
    assert isinstance(request, ResetOdometryRequest)
    assert request.pose.theta_rad == pytest.approx(7 - 2 * math.pi)
    request = parse_request(b'{"op": "reset_odometry", "theta": 3.141592653589793}')
    assert isinstance(request, ResetOdometryRequest)
    assert request.pose.theta_rad == pytest.approx(-math.pi)


FINITE_X = "twist.vx: expected a finite number, got "
LONG_ID = "x" * 65
ID_ERROR = "request.id: expected an integer (64-bit) or a string of at most 64 characters, got "


@pytest.mark.parametrize(
    ("line", "message", "request_id"),
    [
        (b'{"op": "twist", "vx": "fast"}', f'{FINITE_X}"fast"', None),
        (
            b'{"op": "twist", "vy": true, "id": 4}',
            "twist.vy: expected a finite number, got true",
            4,
        ),
        (b'{"op": "twist", "wz": null}', "twist.wz: expected a finite number, got null", None),
        (b'{"op": "twist", "vx": [1]}', f"{FINITE_X}[1]", None),
        (b'{"op": "twist", "vx": NaN, "id": "a"}', f"{FINITE_X}NaN", "a"),
        (b'{"op": "twist", "vx": -Infinity}', f"{FINITE_X}-Infinity", None),
        (b'{"op": "twist", "vx": 1e400}', f"{FINITE_X}Infinity", None),
        (
            b'{"op": "twist", "wz": 100.5}',
            "twist.wz: expected a number between -100 and 100, got 100.5",
            None,
        ),
        (
            b'{"op": "twist", "vx": ' + b"9" * 400 + b"}",
            "twist.vx: expected a number between -100 and 100, got "
            + "9" * 37 + "...",
            None,
        ),
        (
            b'{"op": "twist", "vz": 1, "id": 2}',
            'twist: expected only the keys "id", "op", "vx", "vy", "wz", got "vz"',
            2,
        ),
        (b'{"op": "stop", "vx": 1}', 'stop: expected only the keys "id", "op", got "vx"', None),
        (
            b'{"op": "reset_odometry", "x": "0"}',
            'reset_odometry.x: expected a finite number, got "0"',
            None,
        ),
        (
            b'{"op": "reset_odometry", "z": 0}',
            'reset_odometry: expected only the keys "id", "op", "x", "y", "theta", got "z"',
            None,
        ),
        (b'{"op": "fly", "id": 1}', f'request.op: expected one of {OPS}, got "fly"', 1),
        (b'{"op": "TWIST"}', f'request.op: expected one of {OPS}, got "TWIST"', None),
        (b'{"op": 3}', f"request.op: expected one of {OPS}, got 3", None),
        (b'{"id": 5}', f"request.op: expected one of {OPS}, got nothing", 5),
        (b'{"op": "stop", "id": 1.5}', ID_ERROR + "1.5", None),
        (b'{"op": "stop", "id": true}', ID_ERROR + "true", None),
        (b'{"op": "stop", "id": 9223372036854775808}', ID_ERROR + "9223372036854775808", None),
        (f'{{"op": "stop", "id": "{LONG_ID}"}}'.encode(), ID_ERROR + '"' + "x" * 36 + "...", None),
        (
            b'{"op": "subscribe"}',
            'subscribe.topics: expected an array of "odometry", "status", "error", got nothing',
            None,
        ),
        (
            b'{"op": "subscribe", "topics": "status"}',
            'subscribe.topics: expected a non-empty array of "odometry", "status", "error", '
            'got "status"',
            None,
        ),
        (
            b'{"op": "subscribe", "topics": []}',
            'subscribe.topics: expected a non-empty array of "odometry", "status", "error", got []',
            None,
        ),
        (
            b'{"op": "subscribe", "topics": ["status", "gps"], "id": "s"}',
            'subscribe.topics[1]: expected one of "odometry", "status", "error", got "gps"',
            "s",
        ),
        (
            b'{"op": "subscribe", "topics": [{}]}',
            'subscribe.topics[0]: expected one of "odometry", "status", "error", got {}',
            None,
        ),
        (b"[1, 2]", "request: expected a JSON object, got an array", None),
        (b'"stop"', "request: expected a JSON object, got a string", None),
        (b"42", "request: expected a JSON object, got a number", None),
        (b"null", "request: expected a JSON object, got null", None),
        (b"true", "request: expected a JSON object, got a boolean", None),
        (b"", "request: expected a JSON object, got an empty line", None),
        (b" \t\r\n", "request: expected a JSON object, got an empty line", None),
        (
            b'{"op": "stop"',
            "request: expected valid JSON, got expecting ',' delimiter at offset 13",
            None,
        ),
        (
            b"{op: stop}",
            "request: expected valid JSON, got expecting property name enclosed in double "
            "quotes at offset 1",
            None,
        ),
        (b'{"op": "stop"} x', "request: expected valid JSON, got extra data at offset 15", None),
        (b'{"op": "stop", "op": "stop"}', 'request: expected unique keys, got "op" twice', None),
        (b'\xff{"op": "stop"}', "request: expected UTF-8 text, got byte 0xff at offset 0", None),
        (b'{"op": "\xc3("}', "request: expected UTF-8 text, got byte 0xc3 at offset 8", None),
        (
            b"[" * 3000,
            "request: expected JSON of modest depth, got nesting too deep to parse",
            None,
        ),
    ],
)
def test_parse_errors_have_exact_messages(
    line: bytes, message: str, request_id: int | str | None
) -> None:
    with pytest.raises(ProtocolError) as info:
        parse_request(line)
    assert str(info.value) == message
    assert info.value.request_id == request_id
    assert isinstance(info.value, GatewayError)
    assert isinstance(info.value, ValueError)


def test_message_length_limit_counts_bytes_without_the_line_ending() -> None:
    padded = b'{"op": "stop"}'.ljust(MAX_MESSAGE_BYTES)
    assert parse_request(padded) == CommandRequest(Op.STOP)
    assert parse_request(padded + b"\r\n") == CommandRequest(Op.STOP)
    with pytest.raises(ProtocolError) as info:
        parse_request(padded + b" ")
    assert str(info.value) == "message too long: expected at most 4096 bytes, got 4097"
    with pytest.raises(ProtocolError, match="expected at most 10 bytes, got 15"):
        parse_request('{"op":"stop"}é', max_bytes=10)  # counted in UTF-8 bytes


def test_huge_integer_literal_is_a_protocol_error() -> None:
    line = b'{"op": "twist", "vx": ' + b"1" * 4500 + b"}"
    with pytest.raises(ProtocolError, match="request: expected valid JSON, got"):
        parse_request(line, max_bytes=10_000)


# -- fuzzing ---------------------------------------------------------------------------------


def _parse_or_protocol_error(line: bytes | str) -> None:
    try:
        request = parse_request(line)
    except ProtocolError as err:
        assert str(err)
    else:
        assert isinstance(request, (TwistRequest, CommandRequest, ResetOdometryRequest,
                                    SubscribeRequest))


json_values = st.recursive(
    st.none()
    | st.booleans()
    | st.integers()
    | st.floats()
    | st.text(max_size=20)
    | st.sampled_from([op.value for op in Op] + [t.value for t in Topic]),
    lambda children: st.lists(children, max_size=4)
    | st.dictionaries(
        st.sampled_from(["op", "id", "vx", "vy", "wz", "x", "y", "theta", "topics", "k"])
        | st.text(max_size=5),
        children,
        max_size=5,
    ),
    max_leaves=12,
)


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=200))
def test_fuzz_arbitrary_bytes_raise_only_protocol_error(data: bytes) -> None:
    _parse_or_protocol_error(data)


@settings(max_examples=300, deadline=None)
@given(json_values)
def test_fuzz_arbitrary_json_raises_only_protocol_error(value: Any) -> None:
    _parse_or_protocol_error(json.dumps(value))


@settings(max_examples=300, deadline=None)
@given(
    st.sampled_from(list(Op)),
    st.dictionaries(
        st.sampled_from(["id", "vx", "vy", "wz", "x", "y", "theta", "topics"]), json_values
    ),
)
def test_fuzz_valid_ops_with_arbitrary_fields(op: Op, fields: dict[str, Any]) -> None:
    _parse_or_protocol_error(json.dumps({"op": op.value, **fields}))


finite = st.floats(min_value=-100.0, max_value=100.0, allow_nan=False)


@settings(max_examples=200, deadline=None)
@given(finite, finite, finite, st.integers(-(2**63), 2**63 - 1) | st.text(max_size=64))
def test_fuzz_valid_twists_round_trip(vx: float, vy: float, wz: float, rid: int | str) -> None:
    line = json.dumps({"op": "twist", "vx": vx, "vy": vy, "wz": wz, "id": rid})
    assert parse_request(line) == TwistRequest(Twist(vx, vy, wz), rid)


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
