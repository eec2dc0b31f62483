"""An e-stop taken between two cycles, and an enable taken after it before the next cycle:
the zero and disarm still reach the bus, and the limits start again from zero, whatever path
the e-stop came by (a socket request, a CAN ESTOP frame drained with an ENABLE frame, a bridge
commander's loss with ``deadman: estop``).

Before, the socket's e-stop disarmed at once but the next cycle ramped down from the speed of
before the e-stop; the CAN and the bridge e-stops were acted on only by a cycle that saw the
state ESTOP, which the enable had already left: nothing was disarmed.  Judged on what reaches
the bus (the TurtleBot's two ODrives: Set_Axis_State 0x07, Set_Input_Vel 0x0D)."""

from __future__ import annotations

import struct
from typing import TYPE_CHECKING

import can
import pytest

from gateway.core.bridge_settings import BridgeSettings, DeadmanAction, ZenohSettings
from gateway.core.settings import EstopRelease
from gateway.core.supervision import Source
from gateway.core.types import GatewayState, Twist
from gateway.runtime.bridge.deadman import Deadman
from gateway.runtime.requests import RequestHandler
from gateway.wire.can import TwistFlags
from tests.e2e_helpers import Rig, SocketPilot, virtual_config
from tests.runtime.safety_helpers import TB3

if TYPE_CHECKING:
    from collections.abc import Callable

IDLE = 1


def bus_after(channel: str, act: Callable[[], None]) -> tuple[list[int], list[float]]:
    """The axis states and the speeds (turns/s) the gateway sends while ``act`` runs."""
    spy = can.Bus(interface="virtual", channel=channel)
    try:
        act()
        seen = [(m.arbitration_id, bytes(m.data)) for m in iter(lambda: spy.recv(0.0), None)]
    finally:
        spy.shutdown()
    states = [d[0] for i, d in seen if i & 0x1F == 0x07]
    speeds = [struct.unpack("<f", d[:4])[0] for i, d in seen if i & 0x1F == 0x0D]
    return states, speeds


@pytest.mark.parametrize("cycle_between", [False, True])
def test_a_socket_estop_then_enable_starts_again_from_zero(
        channel: str, sock_path: str, cycle_between: bool) -> None:
    with Rig(virtual_config(TB3, channel, rate_hz=100.0), sock_path) as rig:
        rig.enable()
        a, b = SocketPilot(sock_path), SocketPilot(sock_path)
        a.send(op="twist", vx=0.2)
        rig.advance(0.5)

        def act() -> None:
            a.send(op="estop", id="A")
            if cycle_between:
                rig.advance(rig.period)
            b.send(op="enable", id="B")
            rig.advance(3 * rig.period)

        states, speeds = bus_after(channel, act)
        a.sock.close()
        b.sock.close()
        assert states.count(IDLE) == 2  # both axes disarmed
        assert speeds and all(v == 0.0 for v in speeds), speeds


def test_a_can_estop_drained_with_an_enable_disarms_and_starts_from_zero(channel: str) -> None:
    cfg = virtual_config(TB3, channel, rate_hz=100.0, estop_release=EstopRelease.ANY)
    with Rig(cfg) as rig:
        rig.enable()
        for _ in range(30):
            rig.send_can_twist(Twist(0.2, 0.0, 0.0))
            rig.advance(rig.period)

        def act() -> None:
            rig.send_can_twist(Twist(), TwistFlags.ESTOP)
            rig.send_can_twist(Twist(), TwistFlags.ENABLE)
            rig.advance(3 * rig.period)

        states, speeds = bus_after(channel, act)
        assert rig.gw.supervisor.counts.estops == 1
        assert states.count(IDLE) == 2
        assert speeds and all(v == 0.0 for v in speeds), speeds


def test_a_bridge_deadman_estop_then_a_socket_enable_disarms(
        channel: str, sock_path: str) -> None:
    with Rig(virtual_config(TB3, channel, rate_hz=100.0), sock_path) as rig:
        assert rig.daemon is not None
        rig.enable()
        pilot = SocketPilot(sock_path)
        pilot.send(op="twist", vx=0.2)
        rig.advance(0.3)
        remote = rig.daemon.remote

        class Settings:
            settings = BridgeSettings(ZenohSettings(), "robot", deadman=DeadmanAction.ESTOP)

        remote.bridge = Settings()  # type: ignore[assignment]
        remote.requests = RequestHandler(rig.gw, rig.daemon.server, rig.daemon.latch,
                                         rig.daemon.status, Source.BRIDGE, "the Zenoh bridge")
        remote.deadman = Deadman()
        remote.deadman.accepted("teleop", rig.gw.supervisor.target)

        def act() -> None:
            remote._commander("teleop", False, rig.t)  # as Remote.serve, between cycles
            assert rig.gw.state is GatewayState.ESTOP
            pilot.send(op="enable", id="B")
            rig.advance(3 * rig.period)

        try:
            states, speeds = bus_after(channel, act)
        finally:
            remote.bridge = None
        pilot.sock.close()
        assert states.count(IDLE) == 2
        assert speeds and all(v == 0.0 for v in speeds), speeds
