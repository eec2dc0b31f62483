"""A request over the bridge gets exactly the socket's reply: the same handler, the same path
(newest valid wins, the limits), and an infeasible twist's error with its details."""

from __future__ import annotations

import json
from typing import TYPE_CHECKING

import pytest

from gateway.core.settings import EstopRelease
from gateway.core.supervision import Source
from gateway.core.types import GatewayState
from gateway.runtime.requests import RequestHandler
from gateway.wire.socket import ProtocolError, parse_request
from tests.conftest import CONFIG_DIR
from tests.e2e_helpers import Rig, virtual_config

if TYPE_CHECKING:
    from collections.abc import Iterable

    from gateway.wire.socket import Topic


class Replies:
    """A reply sink, as the control server or the bridge is one."""

    def __init__(self) -> None:
        self.lines: list[bytes] = []

    def reply(self, client_id: int, data: bytes) -> bool:
        self.lines.append(data)
        return True

    def subscribe(self, client_id: int, topics: Iterable[Topic]) -> bool:
        return True

    def unsubscribe(self, client_id: int) -> bool:
        return True


def test_an_infeasible_twist_gets_the_same_reply_over_the_bridge(sock_path: str) -> None:
    cfg = virtual_config(CONFIG_DIR / "turtlebot3_burger.yaml", "bridge-requests",
                         rate_hz=100.0)
    with Rig(cfg, sock_path) as rig:
        assert rig.daemon is not None
        rig.enable()
        socket_side, bridge_side = Replies(), Replies()
        handlers = [
            RequestHandler(rig.gw, socket_side, rig.daemon.latch, rig.daemon.status),
            RequestHandler(rig.gw, bridge_side, rig.daemon.latch, rig.daemon.status,
                           Source.BRIDGE, "the Zenoh bridge"),
        ]
        for line in (b'{"op": "twist", "vx": 0.1, "vy": 0.2, "id": 7}',
                     b'{"op": "twist", "vx": 0.1, "id": 8}', b'{"op": "twist", "vx": "x"}'):
            for handler in handlers:
                try:
                    request = parse_request(line)
                except ProtocolError as err:
                    handler.handle(1, err, rig.t)
                else:
                    handler.handle(1, request, rig.t)
        assert socket_side.lines == bridge_side.lines
        refused = json.loads(bridge_side.lines[0])
        assert refused["ok"] is False and refused["id"] == 7
        assert refused["error"]["code"] == "infeasible_twist"
        assert {"wheel", "constraint", "residual_m_s", "nearest"} <= set(refused["error"])
        assert json.loads(bridge_side.lines[1])["id"] == 8
        assert json.loads(bridge_side.lines[2])["ok"] is False
        assert handlers[1].last_accepted is not None and handlers[0].last_accepted is not None


def test_the_reply_says_what_the_robot_will_follow(sock_path: str) -> None:
    """Asked 5 m/s, the demo robot follows 1.5 m/s (its max_linear_m_s), and says so."""
    cfg = virtual_config(None, "bridge-applied", rate_hz=100.0)
    with Rig(cfg, sock_path) as rig:
        assert rig.daemon is not None
        rig.enable()
        replies = Replies()
        handler = RequestHandler(rig.gw, replies, rig.daemon.latch, rig.daemon.status)
        for line in (b'{"op": "twist", "vx": 5.0}', b'{"op": "twist", "vx": 0.2, "wz": 0.1}'):
            request = parse_request(line)
            handler.handle(1, request, rig.t)
        fast, slow = (json.loads(line) for line in replies.lines)
        assert fast["twist"]["vx_m_s"] == 5.0
        assert fast["applied"] == {"vx_m_s": 1.5, "vy_m_s": 0.0, "wz_rad_s": 0.0}
        assert fast["limited_by"] == "max_linear_m_s 1.5 m/s"
        assert slow["applied"] == slow["twist"] and slow["limited_by"] is None


@pytest.mark.parametrize("release", [EstopRelease.SOCKET, EstopRelease.ANY])
def test_a_bridge_enable_releases_an_estop_only_when_the_config_allows_it(
        sock_path: str, release: EstopRelease) -> None:
    """``estop_release: socket`` (the default) keeps an e-stop until an enable on the control
    socket: an enable query from a Zenoh peer is refused, naming the setting, as the CAN ENABLE
    flag is; ``any`` lets it release the e-stop, as it lets the CAN flag."""
    cfg = virtual_config(None, f"bridge-estop-{release.value}", rate_hz=100.0,
                         estop_release=release)
    with Rig(cfg, sock_path) as rig:
        assert rig.daemon is not None
        rig.enable()
        socket_side, bridge_side = Replies(), Replies()
        on_socket = RequestHandler(rig.gw, socket_side, rig.daemon.latch, rig.daemon.status)
        on_bridge = RequestHandler(rig.gw, bridge_side, rig.daemon.latch, rig.daemon.status,
                                   Source.BRIDGE, "the Zenoh bridge")
        def state() -> GatewayState:
            return rig.gw.state

        on_bridge.handle(1, parse_request(b'{"op": "estop", "id": 1}'), rig.t)
        rig.advance(0.1)
        assert state() is GatewayState.ESTOP
        on_bridge.handle(1, parse_request(b'{"op": "enable", "id": 2}'), rig.t)
        rig.advance(1.0)
        reply = json.loads(bridge_side.lines[-1])
        if release is EstopRelease.SOCKET:
            assert reply == {"ok": False, "id": 2, "error": {
                "code": "estop", "state": "estop",
                "message": "an e-stop is released only by an enable on the control socket "
                           "(gateway.estop_release: socket); the enable from the Zenoh bridge "
                           "was refused"}}
            assert state() is GatewayState.ESTOP
            assert rig.daemon.latch.read() is not None
            on_socket.handle(1, parse_request(b'{"op": "enable", "id": 3}'), rig.t)
            rig.advance(1.0)
            assert json.loads(socket_side.lines[-1])["ok"] is True
        else:
            assert reply["ok"] is True
        assert state() is GatewayState.RUNNING
