"""The deadman across the network, on simulated time: a commander's lost token stops (or
e-stops) the robot only while the robot follows that commander's twist, and the wheels of the
simulated controllers come to rest.  The Zenoh side is replaced by a queue (the bridge's
inbox), so what is checked is the daemon's handling; ``test_bridge_process.py`` checks the
same across a real Zenoh session."""

from __future__ import annotations

from typing import TYPE_CHECKING

import pytest

from gateway.core.bridge_settings import BridgeSettings, DeadmanAction, ZenohSettings
from gateway.core.control import ZERO
from gateway.core.supervision import Source
from gateway.core.types import GatewayState, Twist
from gateway.runtime import remote as remote_module
from gateway.runtime.bridge.deadman import Deadman
from gateway.runtime.bridge.inbox import NO_REPLY, CommanderEvent, Inbound
from gateway.runtime.requests import RequestHandler
from gateway.wire.socket import CommandRequest, Op, TwistRequest
from tests.e2e_helpers import Rig, virtual_config

if TYPE_CHECKING:
    from collections.abc import Iterable, Iterator

    from gateway.wire.socket import Topic


class FakeBridge:
    """The bridge's loop-side face: an inbox the test fills, replies kept."""

    def __init__(self, action: DeadmanAction) -> None:
        self.settings = BridgeSettings(ZenohSettings(), "robot", deadman=action)
        self.inbox: list[Inbound | CommanderEvent] = []
        #: The newest published twist, as the bridge's slot holds it.
        self.twist: Inbound | None = None
        self.replies: list[tuple[int, bytes]] = []

    def take_twists(self) -> list[Inbound]:
        twist, self.twist = self.twist, None
        return [] if twist is None else [twist]

    def take(self) -> Inbound | CommanderEvent | None:
        return self.inbox.pop(0) if self.inbox else None

    def reply(self, client_id: int, data: bytes) -> bool:
        self.replies.append((client_id, data))
        return True

    def subscribe(self, client_id: int, topics: Iterable[Topic]) -> bool:
        return True

    def unsubscribe(self, client_id: int) -> bool:
        return True

    def close(self) -> None:
        pass


@pytest.fixture(params=[DeadmanAction.STOP, DeadmanAction.ESTOP], ids=lambda a: a.value)
def rig(request: pytest.FixtureRequest, sock_path: str) -> Iterator[tuple[Rig, FakeBridge]]:
    cfg = virtual_config(None, f"deadman-{request.param.value}", rate_hz=100.0,
                         cmd_timeout_s=30.0)
    with Rig(cfg, sock_path) as r:
        assert r.daemon is not None
        remote = r.daemon.remote
        fake = FakeBridge(request.param)
        remote.bridge = fake  # type: ignore[assignment]
        remote.requests = RequestHandler(r.gw, fake, r.daemon.latch, r.daemon.status,
                                         Source.BRIDGE, "the Zenoh bridge")
        remote.deadman = Deadman()
        r.enable()
        yield r, fake


def serve(r: Rig) -> None:
    assert r.daemon is not None
    r.daemon.remote.serve(r.t)


def wheel_speeds(r: Rig) -> list[float]:
    return [abs(s.model.velocity_rad_s) for s in r.sims]


def twist_from(commander: str | None, vx: float) -> Inbound:
    return Inbound(NO_REPLY, TwistRequest(Twist(vx, 0.0, 0.0)), commander)


def test_deadman_alone() -> None:
    d = Deadman()
    a, b = Twist(1.0), Twist(1.0)
    d.accepted("teleop", a)
    assert d.lost("teleop", a) is True
    d.accepted("teleop", a)
    assert d.lost("teleop", b) is False  # another twist (equal, not the same) is the target
    assert d.lost("nobody", a) is False


def test_losing_the_followed_commander_stops_the_wheels(rig: tuple[Rig, FakeBridge]) -> None:
    r, fake = rig
    fake.inbox += [CommanderEvent("teleop1", True), twist_from("teleop1", 0.4)]
    r.advance(1.0, serve)
    sup = r.gw.supervisor
    assert sup.target.vx_m_s == 0.4 and max(wheel_speeds(r)) > 1.0
    fake.inbox.append(CommanderEvent("teleop1", False))
    r.advance(r.period, serve)
    assert sup.target is ZERO
    last = r.gw.publisher.last_error
    assert last is not None and "commander teleop1 disappeared" in last.message
    action = fake.settings.deadman
    if action is DeadmanAction.ESTOP:
        assert r.gw.state is GatewayState.ESTOP
        assert r.daemon is not None and r.daemon.latch.read() is not None
    else:
        assert r.gw.state is GatewayState.RUNNING
    r.advance(1.5, serve)
    assert max(wheel_speeds(r)) < 0.05, wheel_speeds(r)


def test_losing_a_commander_the_robot_no_longer_follows_changes_nothing(
        rig: tuple[Rig, FakeBridge]) -> None:
    r, fake = rig
    fake.inbox.append(twist_from("teleop1", 0.4))
    r.advance(0.2, serve)
    fake.inbox.append(twist_from("planner", 0.2))  # a newer twist from someone else
    r.advance(0.2, serve)
    fake.inbox.append(CommanderEvent("teleop1", False))
    r.advance(0.2, serve)
    sup = r.gw.supervisor
    assert sup.target.vx_m_s == 0.2 and r.gw.state is GatewayState.RUNNING
    last = r.gw.publisher.last_error
    assert last is None or "disappeared" not in last.message, last


def test_a_twist_without_a_commander_is_not_stopped_by_a_token(
        rig: tuple[Rig, FakeBridge]) -> None:
    r, fake = rig
    fake.inbox += [twist_from("teleop1", 0.4), twist_from(None, 0.3)]
    r.advance(0.2, serve)
    fake.inbox.append(CommanderEvent("teleop1", False))
    r.advance(0.2, serve)
    assert r.gw.supervisor.target.vx_m_s == 0.3


def test_a_refused_twist_is_not_followed(rig: tuple[Rig, FakeBridge]) -> None:
    r, fake = rig
    r.gw.supervisor.disable()
    r.advance(0.1, serve)
    fake.inbox.append(twist_from("teleop1", 0.4))  # refused: the drives are disabled
    r.advance(0.1, serve)
    fake.inbox.append(CommanderEvent("teleop1", False))
    r.advance(0.1, serve)
    assert r.gw.state is GatewayState.DISABLED
    last = r.gw.publisher.last_error
    assert last is None or "disappeared" not in last.message, last


def test_a_published_twist_is_taken_before_the_token_events_that_came_after_it(
        rig: tuple[Rig, FakeBridge]) -> None:
    """A commander's last twist and then its token's disappearance reach the loop in one
    cycle: the twist (in the published twists' slot) is taken first, so the loss stops the
    robot rather than the dead commander's twist driving it."""
    r, fake = rig
    fake.inbox.append(CommanderEvent("teleop1", True))
    r.advance(0.1, serve)
    fake.twist = twist_from("teleop1", 0.4)
    fake.inbox.append(CommanderEvent("teleop1", False))
    r.advance(r.period, serve)
    assert r.gw.supervisor.target is ZERO
    r.advance(1.5, serve)
    assert max(wheel_speeds(r)) < 0.05, wheel_speeds(r)


def test_a_twist_published_while_the_loop_drains_the_inbox_is_taken_before_the_loss(
        rig: tuple[Rig, FakeBridge]) -> None:
    """The commander's last twist reaches its ring after the loop took the rings this cycle,
    and its token's loss reaches the inbox right after: the twist is taken before the loss is
    acted on, so the loss stops the robot for good (a review saw the dead commander's twist
    taken a cycle later, driving the robot again; with ``cmd_timeout_s`` 30 s here it would
    have driven on)."""
    r, fake = rig
    fake.inbox.append(CommanderEvent("teleop1", True))
    r.advance(0.1, serve)
    take = fake.take

    def take_after_the_last_twist() -> Inbound | CommanderEvent | None:
        item = take()
        if item == CommanderEvent("teleop1", False):
            fake.twist = twist_from("teleop1", 0.4)  # arrived just before the loss
        return item

    fake.take = take_after_the_last_twist  # type: ignore[method-assign]
    fake.inbox.append(CommanderEvent("teleop1", False))
    r.advance(r.period, serve)
    r.advance(1.5, serve)
    assert r.gw.supervisor.target is ZERO
    assert max(wheel_speeds(r)) < 0.05, wheel_speeds(r)


def test_the_loop_takes_at_least_one_waiting_item_a_cycle_within_its_share(
        rig: tuple[Rig, FakeBridge], monkeypatch: pytest.MonkeyPatch) -> None:
    """With no time to spare (a share of 0), every cycle still takes one query or token
    event, and the rest wait for the next cycles: none is lost."""
    r, fake = rig
    monkeypatch.setattr(remote_module, "SERVE_SHARE", 0.0)
    fake.inbox += [Inbound(k, CommandRequest(Op.STATUS)) for k in range(1, 6)]
    serve(r)
    assert [c for c, _ in fake.replies] == [1] and len(fake.inbox) == 4
    for _ in range(4):
        serve(r)
    assert [c for c, _ in fake.replies] == [1, 2, 3, 4, 5] and fake.inbox == []


def test_the_loop_loses_no_item_at_its_limit(
        rig: tuple[Rig, FakeBridge], monkeypatch: pytest.MonkeyPatch) -> None:
    """At most POLL_MAX items a cycle, and the one after the limit waits for the next cycle
    (it was taken from the inbox and dropped: an e-stop, an enable or a commander's loss)."""
    r, fake = rig
    monkeypatch.setattr(remote_module, "SERVE_SHARE", 1e6)  # only the count limits
    n = remote_module.POLL_MAX + 5
    fake.inbox += [Inbound(k, CommandRequest(Op.STATUS)) for k in range(1, n + 1)]
    serve(r)
    assert [c for c, _ in fake.replies] == list(range(1, remote_module.POLL_MAX + 1))
    serve(r)
    assert [c for c, _ in fake.replies] == list(range(1, n + 1)) and fake.inbox == []
