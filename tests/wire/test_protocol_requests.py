"""The control-socket protocol's requests: parsing every request, exact error messages, and
fuzzing of the parser."""

from __future__ import annotations

import json
import math
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gateway.core.errors import GatewayError
from gateway.core.kinematics.odometry import Pose
from gateway.core.types import Twist
from gateway.wire.can import POSITION_WRAP_M
from gateway.wire.socket import (
    MAX_MESSAGE_BYTES,
    CommandRequest,
    Op,
    ProtocolError,
    Request,
    ResetOdometryRequest,
    SubscribeRequest,
    Topic,
    TwistRequest,
    parse_request,
)

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


@pytest.mark.parametrize(
    ("line", "message"),
    [
        (b'{"op": "reset_odometry", "x": 1e308, "id": 1}',
         "reset_odometry.x: expected a number between -8388.608 and 8388.608, got 1e+308"),
        (b'{"op": "reset_odometry", "y": -8388.609, "id": 1}',
         "reset_odometry.y: expected a number between -8388.608 and 8388.608, got -8388.609"),
        (b'{"op": "reset_odometry", "theta": 1e308, "id": 1}',
         "reset_odometry.theta: expected a number between -6283.185307 and 6283.185307, got "
         "1e+308"),
    ],
)
def test_reset_odometry_is_bounded_by_what_can_carries(line: bytes, message: str) -> None:
    """Before, any finite value was taken: {"op":"reset_odometry","x":1e308} left the pose
    stuck (no odometry step changes 1e308) and beyond what WG_Odom_Pose carries."""
    with pytest.raises(ProtocolError) as info:
        parse_request(line)
    assert (str(info.value), info.value.request_id) == (message, 1)
    # The bounds themselves are taken: WG_Odom_Pose's range (i24 mm) and a thousand turns.
    edge = parse_request(b'{"op": "reset_odometry", "x": -8388.608, "y": 8388.608, '
                         b'"theta": -6283.185307}')
    assert isinstance(edge, ResetOdometryRequest)
    assert (edge.pose.x_m, edge.pose.y_m) == (-POSITION_WRAP_M / 2, POSITION_WRAP_M / 2)
    assert -math.pi <= edge.pose.theta_rad < math.pi


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
