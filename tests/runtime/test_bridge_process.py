"""The Zenoh bridge's native keys across real sessions: the daemon as a process (``wheelgate
run --sim``), commanders and observers as other sessions on the loopback, free ports, multicast
off, every child ended by its PID.

What decides each test is what the robot does -- its odometry, from the simulated wheels --
and what the gateway reports, never how fast: ``cmd_timeout_s`` is 30 s here, so a stop that
comes within a second of a commander's death came from the deadman and nothing else.  The
reaction times themselves are measured by ``tools/bench_bridge.py``.
"""

from __future__ import annotations

import os
import signal
import subprocess
import time

import pytest

from tests.runtime import bridge_helpers
from tests.runtime.bridge_helpers import (
    NS,
    Observer,
    disappeared,
    ended,
    moving,
    spawn_commander,
    still,
)

pytest.importorskip("zenoh", reason="eclipse-zenoh not installed: pip install 'wheelgate[zenoh]'")
pytestmark = pytest.mark.timeout(90)

# The shared fixtures (bridge_helpers.py), bound here so that pytest finds them.
gateway = bridge_helpers.gateway
observer = bridge_helpers.observer


def test_nothing_listens_but_the_configured_endpoint(
        gateway: tuple[subprocess.Popen[bytes], str], observer: Observer) -> None:
    proc, connect = gateway
    port = int(connect.rsplit(":", 1)[1])
    listening = subprocess.run(["ss", "-ltnup"], capture_output=True, text=True, check=False)
    if listening.returncode != 0:
        pytest.skip("ss (iproute2) not available")
    mine = [line for line in listening.stdout.splitlines() if f"pid={proc.pid}," in line]
    assert len(mine) == 1 and f"127.0.0.1:{port}" in mine[0], mine


def test_the_status_query_answers_and_a_published_twist_drives(observer: Observer) -> None:
    status = observer.query("status", {"op": "status", "id": 5})
    assert status["ok"] is True and status["id"] == 5 and status["robot"] == "demo_mecanum"
    assert observer.query("twist", {"op": "twist", "vx": 0.25})["ok"] is True
    observer.wait(moving(0.25))
    assert observer.query("stop")["ok"] is True
    observer.wait(still)
    bad = observer.query("twist", {"op": "twist", "vx": "fast", "id": 1})
    assert bad["ok"] is False and bad["id"] == 1 and "twist.vx" in bad["error"]["message"]


def test_sigkill_of_the_commander_stops_the_robot(
        gateway: tuple[subprocess.Popen[bytes], str], observer: Observer) -> None:
    _, connect = gateway
    cmd = spawn_commander(connect, "teleop1", 0.3)
    try:
        observer.wait(moving(0.3))
        killed = time.monotonic()
        os.kill(cmd.pid, signal.SIGKILL)
        # The token's disappearance stops it (cmd_timeout_s, 30 s, would say otherwise).
        stopped = observer.wait(disappeared("teleop1"), after=killed, timeout_s=15.0)
        observer.wait(still, after=stopped)
    finally:
        ended(cmd)


def test_a_frozen_commander_stops_the_robot_after_the_lease(
        gateway: tuple[subprocess.Popen[bytes], str], observer: Observer) -> None:
    _, connect = gateway
    cmd = spawn_commander(connect, "teleop2", 0.2)
    try:
        observer.wait(moving(0.2))
        frozen = time.monotonic()
        os.kill(cmd.pid, signal.SIGSTOP)
        # The lease's expiry stops it (cmd_timeout_s, 30 s, would say otherwise).
        stopped = observer.wait(disappeared("teleop2"), after=frozen, timeout_s=15.0)
        observer.wait(still, after=stopped)
    finally:
        os.kill(cmd.pid, signal.SIGCONT)
        ended(cmd)


def test_the_gateway_token_disappears_after_sigterm(
        gateway: tuple[subprocess.Popen[bytes], str], observer: Observer) -> None:
    proc, _ = gateway
    seen: list[str] = []
    sub = observer.s.liveliness().declare_subscriber(
        f"wheelgate/{NS}/gateway", lambda s: seen.append(str(s.kind)), history=True)
    end = time.monotonic() + 10
    while not seen:
        assert time.monotonic() < end, "the gateway's token was never seen"
        time.sleep(0.02)
    assert seen[0].endswith("PUT")
    os.kill(proc.pid, signal.SIGTERM)
    assert proc.wait(20) == 0
    end = time.monotonic() + 5
    while not any(k.endswith("DELETE") for k in seen):
        assert time.monotonic() < end, seen
        time.sleep(0.02)
    sub.undeclare()
