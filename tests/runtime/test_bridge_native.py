"""wheelgate's own Zenoh keys: names, the commander attachment, and the socket's validation for
twists and queries (pure: no Zenoh)."""

from __future__ import annotations

import collections
import json
from types import SimpleNamespace

import pytest

from gateway.core.bridge_settings import ZenohMode, ZenohSettings
from gateway.core.types import Twist
from gateway.runtime.bridge.bridge import INBOX_MAX, Bridge, _native_twist
from gateway.runtime.bridge.inbox import NO_REPLY, CommanderEvent, Inbound, TwistSource
from gateway.runtime.bridge.native import (
    COMMANDER_MAX_CHARS,
    RPC_OPS,
    NativeKeys,
    commander_of,
    parse_query,
    parse_twist_sample,
)
from gateway.runtime.bridge.session import session_config
from gateway.runtime.mailbox import Mailbox
from gateway.wire.socket import (
    CommandRequest,
    Op,
    ProtocolError,
    ResetOdometryRequest,
    TwistRequest,
    parse_request,
)

KEYS = NativeKeys.of("robot1")


def test_the_keys() -> None:
    assert KEYS.twist == "wheelgate/robot1/cmd/twist"
    assert [KEYS.rpc(op) for op in RPC_OPS] == [
        f"wheelgate/robot1/rpc/{op}" for op in
        ("status", "stop", "estop", "enable", "disable", "reset_odometry", "twist")]
    assert (KEYS.odom, KEYS.status, KEYS.error) == (
        "wheelgate/robot1/odom", "wheelgate/robot1/status", "wheelgate/robot1/error")
    assert KEYS.gateway_token == "wheelgate/robot1/gateway"
    assert KEYS.commander_token("teleop1") == "wheelgate/robot1/commander/teleop1"
    assert KEYS.commanders == "wheelgate/robot1/commander/*"


def test_a_twist_sample_is_validated_as_the_socket_validates_it() -> None:
    line = b'{"op": "twist", "vx": 0.5, "wz": 0.1, "id": 3}'
    assert parse_twist_sample(line, KEYS.twist) == parse_request(line)
    assert parse_twist_sample(line, KEYS.twist) == TwistRequest(Twist(0.5, 0.0, 0.1), 3)
    for bad in (b'{"op": "twist", "vx": "fast"}', b'{"op": "twist", "vx": 1e9}', b"[]",
                b'{"op": "twist", "vx": NaN}', b"\xff", b'{"op": "twist", "speed": 1}'):
        with pytest.raises(ProtocolError) as socket_err:
            parse_request(bad)
        with pytest.raises(ProtocolError) as bridge_err:
            parse_twist_sample(bad, KEYS.twist)
        assert str(bridge_err.value) == str(socket_err.value)
    with pytest.raises(ProtocolError, match=r"^wheelgate/robot1/cmd/twist: expected op 'twist', "
                                            r"got 'estop'$"):
        parse_twist_sample(b'{"op": "estop"}', KEYS.twist)


def test_a_query_is_its_op_or_the_socket_request_of_that_op() -> None:
    assert parse_query(Op.STATUS, None, KEYS.rpc(Op.STATUS)) == CommandRequest(Op.STATUS)
    assert parse_query(Op.STOP, b"", KEYS.rpc(Op.STOP)) == CommandRequest(Op.STOP)
    got = parse_query(Op.RESET_ODOMETRY, json.dumps(
        {"op": "reset_odometry", "x": 1, "y": 2, "theta": 0, "id": "a"}).encode(), "k")
    assert isinstance(got, ResetOdometryRequest) and got.id == "a" and got.pose.x_m == 1.0
    with pytest.raises(ProtocolError, match=r"^k: expected op 'stop', got 'estop'$"):
        parse_query(Op.STOP, b'{"op": "estop", "id": 9}', "k")
    with pytest.raises(ProtocolError, match=r"twist.vx"):
        parse_query(Op.TWIST, b'{"op": "twist", "vx": true}', "k")
    # As on the socket, a twist without numbers is the zero twist.
    assert parse_query(Op.TWIST, None, "k") == TwistRequest(Twist(0.0, 0.0, 0.0))


@pytest.mark.parametrize(("raw", "expected"), [
    (None, None), (b"teleop1", "teleop1"), (b"fleet.manager-2_a", "fleet.manager-2_a"),
])
def test_a_commander_name(raw: bytes | None, expected: str | None) -> None:
    assert commander_of(raw, "k") == expected


@pytest.mark.parametrize("raw", [b"", b"a b", b"a/b", b"\xff", b"x" * (COMMANDER_MAX_CHARS + 1)])
def test_a_bad_commander_name_is_refused(raw: bytes) -> None:
    with pytest.raises(ProtocolError, match=r"^k: attachment: expected a commander name"):
        commander_of(raw, "k")


def test_the_session_listens_nowhere_and_scouts_nothing_unless_told() -> None:
    assert session_config(ZenohSettings()) == {
        "mode": "peer", "listen/endpoints": [], "connect/endpoints": [],
        "scouting/multicast/enabled": False, "transport/link/tx/lease": 10000,
    }
    told = session_config(ZenohSettings(ZenohMode.CLIENT, ("tcp/127.0.0.1:1",),
                                        ("tcp/10.0.0.2:7447",), True, 0.5))
    assert told["mode"] == "client" and told["transport/link/tx/lease"] == 500
    assert told["listen/endpoints"] == ["tcp/127.0.0.1:1"]
    assert told["scouting/multicast/enabled"] is True


class Ring:
    """A subscriber with a ring of one sample, as Zenoh's ``RingChannel(1)`` keeps it."""

    def __init__(self) -> None:
        self.sample: object | None = None

    def put(self, payload: bytes, attachment: bytes | None = None) -> None:
        self.sample = SimpleNamespace(
            payload=SimpleNamespace(to_bytes=lambda: payload), key_expr=KEYS.twist,
            attachment=None if attachment is None else SimpleNamespace(
                to_bytes=lambda: attachment))

    def try_recv(self) -> object | None:
        sample, self.sample = self.sample, None
        return sample


def _bare_bridge(*rings: Ring) -> Bridge:
    bridge = Bridge.__new__(Bridge)  # the loop's side only: no Zenoh session
    bridge._inbox = collections.deque()
    bridge._twists = [TwistSource(ring, _native_twist) for ring in rings]
    bridge.bad_twists = bridge.dropped = 0
    bridge.mailbox = Mailbox()
    return bridge


def _twist(vx: object) -> bytes:
    return json.dumps({"op": "twist", "vx": vx}).encode()


def test_the_loop_parses_the_newest_published_twist_of_each_source() -> None:
    """Zenoh keeps the newest sample of each twist subscriber (a ring of one): the loop parses
    that one, with its commander; a bad newest sample is counted and reported on the error
    key, and nothing of it is followed."""
    native, stamped = Ring(), Ring()
    bridge = _bare_bridge(native, stamped)
    native.put(_twist(0.999), b"teleop1")
    assert bridge.take_twists() == [
        Inbound(NO_REPLY, TwistRequest(Twist(0.999, 0.0, 0.0)), "teleop1")]
    assert bridge.take_twists() == []
    native.put(_twist("fast"))
    stamped.put(_twist(0.2))
    assert bridge.take_twists() == [Inbound(NO_REPLY, TwistRequest(Twist(0.2, 0.0, 0.0)))]
    assert bridge.bad_twists == 1
    errors = bridge.mailbox.take(0.0).errors
    assert [e.message for e in errors] == ['twist.vx: expected a finite number, got "fast"']
    native.put(_twist(0.1), b"a b")
    assert bridge.take_twists() == [] and bridge.bad_twists == 2
    assert "attachment: expected a commander name" in bridge.mailbox.take(0.0).errors[0].message


def test_a_flood_of_queries_never_crowds_out_a_commander_event() -> None:
    bridge = _bare_bridge()
    for k in range(INBOX_MAX + 10):
        bridge._admit(Inbound(k + 1, CommandRequest(Op.STATUS)))
    assert len(bridge._inbox) == INBOX_MAX and bridge.dropped == 10
    assert bridge._admit(CommanderEvent("teleop1", alive=False))
    rest: list[object] = []
    while (item := bridge.take()) is not None:
        rest.append(item)
    assert len(rest) == INBOX_MAX + 1 and rest[-1] == CommanderEvent("teleop1", alive=False)
