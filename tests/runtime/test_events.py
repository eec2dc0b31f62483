"""The events the daemon sends its subscribers, byte for byte: the protocol is public, so the
lines a client reads stay what they were (pinned from the daemon's output before the outbox
was typed, issue 15)."""

from __future__ import annotations

import json
from typing import TYPE_CHECKING

import pytest

from gateway.core.types import GatewayState
from tests.conftest import CONFIG_DIR
from tests.e2e_helpers import Rig, SocketPilot, virtual_config

if TYPE_CHECKING:
    from gateway.core.kinematics.odometry import OdometryState

pytestmark = pytest.mark.timeout(60)

#: What a client subscribed to every topic reads in the first 45 cycles of a disabled
#: TurtleBot3 (200 Hz, odometry at 50 Hz, status at 10 Hz) whose odometry was reset to
#: (1.5, -2.25, 0.5), refused a twist at cycle 10 and was e-stopped at cycle 20.  Each report
#: is due on its own grid: the odometry at 0.1 s and 0.2 s comes in the cycle of the status
#: (before, a cycle of simulated time a hair short of 0.1 s put it one cycle later, and the
#: odometry of 0.22 s after the end).
DISABLED = b"""\
{"ok":true,"id":1,"topics":["error","odometry","status"]}
{"ok":true,"id":2,"odometry":{"x":1.5,"y":-2.25,"theta":0.5,"vx":0.0,"vy":0.0,"wz":0.0,\
"slip":0.0,"distance":0.0,"t":0.0}}
{"event":"odometry","x":1.5,"y":-2.25,"theta":0.5,"vx":0.0,"vy":0.0,"wz":0.0,"slip":0.0,\
"distance":0.0,"t":0.02}
{"event":"odometry","x":1.5,"y":-2.25,"theta":0.5,"vx":0.0,"vy":0.0,"wz":0.0,"slip":0.0,\
"distance":0.0,"t":0.04}
{"ok":false,"id":3,"error":{"code":"not_enabled","message":"gateway is DISABLED; send enable \
first"}}
{"event":"error","code":"not_enabled","message":"gateway is DISABLED; send enable first"}
{"event":"odometry","x":1.5,"y":-2.25,"theta":0.5,"vx":0.0,"vy":0.0,"wz":0.0,"slip":0.0,\
"distance":0.0,"t":0.05999999999999999}
{"event":"odometry","x":1.5,"y":-2.25,"theta":0.5,"vx":0.0,"vy":0.0,"wz":0.0,"slip":0.0,\
"distance":0.0,"t":0.08}
{"event":"odometry","x":1.5,"y":-2.25,"theta":0.5,"vx":0.0,"vy":0.0,"wz":0.0,"slip":0.0,\
"distance":0.0,"t":0.10000000000000002}
{"event":"status","state":"disabled","reason":""}
{"ok":true,"id":4,"state":"estop"}
{"event":"odometry","x":1.5,"y":-2.25,"theta":0.5,"vx":0.0,"vy":0.0,"wz":0.0,"slip":0.0,\
"distance":0.0,"t":0.12000000000000004}
{"event":"odometry","x":1.5,"y":-2.25,"theta":0.5,"vx":0.0,"vy":0.0,"wz":0.0,"slip":0.0,\
"distance":0.0,"t":0.14000000000000004}
{"event":"odometry","x":1.5,"y":-2.25,"theta":0.5,"vx":0.0,"vy":0.0,"wz":0.0,"slip":0.0,\
"distance":0.0,"t":0.16000000000000006}
{"event":"odometry","x":1.5,"y":-2.25,"theta":0.5,"vx":0.0,"vy":0.0,"wz":0.0,"slip":0.0,\
"distance":0.0,"t":0.18000000000000008}
{"event":"odometry","x":1.5,"y":-2.25,"theta":0.5,"vx":0.0,"vy":0.0,"wz":0.0,"slip":0.0,\
"distance":0.0,"t":0.2000000000000001}
{"event":"status","state":"estop","reason":"e-stop requested on the control socket"}
{"event":"odometry","x":1.5,"y":-2.25,"theta":0.5,"vx":0.0,"vy":0.0,"wz":0.0,"slip":0.0,\
"distance":0.0,"t":0.2200000000000001}
"""


class RawPilot(SocketPilot):
    """A socket client that keeps the lines as they came."""

    def lines(self) -> list[bytes]:
        """Every complete line received so far, newline included."""
        try:
            while chunk := self.sock.recv(65536):
                self.buf += chunk
        except BlockingIOError:
            pass
        *lines, self.buf = self.buf.split(b"\n")
        return [line + b"\n" for line in lines]


def _odometry_line(st: OdometryState) -> bytes:
    """The odometry event as the protocol writes it (compact JSON, keys in this order)."""
    p, v = st.pose, st.twist
    payload = {"event": "odometry", "x": p.x_m, "y": p.y_m, "theta": p.theta_rad,
               "vx": v.vx_m_s, "vy": v.vy_m_s, "wz": v.wz_rad_s, "slip": st.slip_m_s,
               "distance": st.distance_m, "t": st.timestamp_s}
    return json.dumps(payload, separators=(",", ":")).encode() + b"\n"


def test_subscribers_read_the_events_byte_for_byte(channel: str, sock_path: str) -> None:
    with Rig(virtual_config(CONFIG_DIR / "turtlebot3_burger.yaml", channel), sock_path) as rig:
        pilot = RawPilot(sock_path)
        try:
            pilot.send(op="subscribe", topics=["odometry", "status", "error"], id=1)
            pilot.send(op="reset_odometry", x=1.5, y=-2.25, theta=0.5, id=2)
            for k in range(45):
                rig.advance(rig.period)
                if k == 10:
                    pilot.send(op="twist", vx=0.1, id=3)
                elif k == 20:
                    pilot.send(op="estop", id=4)
            assert b"".join(pilot.lines()) == DISABLED

            # Moving: every odometry event is the odometry of the cycle that sent it, each
            # field under its own name (all of them differ from zero and from one another).
            pilot.send(op="enable", id=5)
            rig.advance(0.05)
            rig.enable()
            states = {}
            for _ in range(100):
                pilot.send(op="twist", vx=0.2, wz=0.5)
                rig.advance(rig.period)
                states[rig.gw.odometry.state.timestamp_s] = rig.gw.odometry.state
            odometry = [line for line in pilot.lines() if line.startswith(b'{"event":"odometry"')]
            moving = [line for line in odometry if b'"vx":0.0,' not in line]
            assert len(moving) >= 15
            for line in odometry[-20:]:
                assert line == _odometry_line(states[json.loads(line)["t"]])
            last = json.loads(moving[-1])
            values = [last[k] for k in ("x", "y", "theta", "vx", "wz", "distance", "t")]
            assert len(set(values)) == len(values) and 0.0 not in values
            assert rig.gw.state is GatewayState.RUNNING
        finally:
            pilot.close()
