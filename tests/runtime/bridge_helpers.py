"""Shared harness of the bridge's process tests: the daemon with a ``bridge:`` block as a
process, an observer session, and the peers of ``tools/bridge_peer.py`` as processes; loopback
only, free ports, multicast off, every child ended by its PID."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from typing import TYPE_CHECKING, Any

import pytest
import yaml

from tests.conftest import REPO

sys.path.insert(0, str(REPO / "tools"))
from bridge_peer import free_port, session

if TYPE_CHECKING:
    from collections.abc import Callable, Iterator
    from pathlib import Path

PEER = str(REPO / "tools" / "bridge_peer.py")

zenoh = pytest.importorskip("zenoh", reason="eclipse-zenoh not installed: "
                                            "pip install 'wheelgate[zenoh]'")

NS = "robot1"
LEASE_S = 1.0


class NoReplyError(AssertionError):
    """No queryable answered."""


class Observer:
    """A session that records the gateway's events and answers questions about them."""

    def __init__(self, connect: str) -> None:
        self.s = session(connect, LEASE_S)
        self.events: list[tuple[float, str, dict[str, Any]]] = []
        self.lock = threading.Lock()
        self._subs = [self.s.declare_subscriber(f"wheelgate/{NS}/{k}", self._on)
                      for k in ("odom", "status", "error")]

    def _on(self, sample: Any) -> None:
        with self.lock:
            self.events.append((time.monotonic(), str(sample.key_expr).rsplit("/", 1)[-1],
                                json.loads(sample.payload.to_bytes())))

    def query(self, op: str, request: dict[str, object] | None = None,
              timeout_s: float = 10.0) -> dict[str, Any]:
        payload = None if request is None else json.dumps(request)
        for reply in self.s.get(f"wheelgate/{NS}/rpc/{op}", payload=payload, timeout=timeout_s):
            assert reply.ok is not None, reply.err
            got: dict[str, Any] = json.loads(reply.ok.payload.to_bytes())
            return got
        raise NoReplyError(op)

    def wait(self, what: Callable[[str, dict[str, Any]], bool], after: float = 0.0,
             timeout_s: float = 15.0) -> float:
        """When the first event after ``after`` matching ``what`` arrived."""
        end = time.monotonic() + timeout_s
        while time.monotonic() < end:
            with self.lock:
                for t, key, event in self.events:
                    if t >= after and what(key, event):
                        return t
            time.sleep(0.01)
        errors = [e for e in self.events if e[1] != "odom"]
        raise AssertionError(f"no such event within {timeout_s} s; last: {self.events[-3:]}; "
                             f"not odometry: {errors[-5:]}")

    def close(self) -> None:
        self.s.close()


def ended(proc: subprocess.Popen[bytes]) -> None:
    if proc.poll() is None:
        os.kill(proc.pid, signal.SIGKILL)
    proc.wait(10)


@pytest.fixture
def gateway(tmp_path: Path, sock_path: str, request: pytest.FixtureRequest
            ) -> Iterator[tuple[subprocess.Popen[bytes], str]]:
    """The daemon with the bridge, on free ports; its ``bridge.ros2`` block is ``{}`` unless
    a test parametrizes ``gateway`` indirectly with another."""
    ros2_block = getattr(request, "param", {})
    port = free_port()
    raw = yaml.safe_load((REPO / "gateway" / "data" / "default.yaml").read_text())
    raw["gateway"] = {"socket": sock_path, "rate_hz": 100.0, "cmd_timeout_s": 30.0}
    raw["bridge"] = {"zenoh": {"listen": [f"tcp/127.0.0.1:{port}"], "lease_s": LEASE_S},
                     "namespace": NS, "ros2": ros2_block}
    path = tmp_path / "robot.yaml"
    path.write_text(yaml.safe_dump(raw))
    log = (tmp_path / "gateway.log").open("wb")
    proc = subprocess.Popen([sys.executable, "-m", "gateway", "-v", "run", "--sim", "-c",
                             str(path)], stdout=log, stderr=subprocess.STDOUT)
    connect = f"tcp/127.0.0.1:{port}"
    try:
        yield proc, connect
    finally:
        ended(proc)
        log.close()
        sys.stderr.write((tmp_path / "gateway.log").read_text(errors="replace")[-3000:])


@pytest.fixture
def observer(gateway: tuple[subprocess.Popen[bytes], str]) -> Iterator[Observer]:
    proc, connect = gateway
    end = time.monotonic() + 30
    obs: Observer | None = None
    while obs is None:
        assert proc.poll() is None, "the gateway ended"
        try:
            obs = Observer(connect)
        except zenoh.ZError:
            assert time.monotonic() < end, "the gateway's endpoint never opened"
            time.sleep(0.2)
    try:
        while True:
            assert time.monotonic() < end, "the gateway did not answer or enable"
            try:
                if obs.query("status", timeout_s=1.0).get("state") == "running":
                    break
            except NoReplyError:
                assert proc.poll() is None, "the gateway ended"
            time.sleep(0.1)
        yield obs
    finally:
        obs.close()


def spawn_ros_node(connect: str, *args: str) -> subprocess.Popen[bytes]:
    """``tools/bridge_peer.py ros-node`` with ``args``, once it is ready."""
    proc = subprocess.Popen([sys.executable, PEER, "ros-node", "--connect", connect,
                             "--lease", str(LEASE_S), *args], stdout=subprocess.PIPE, cwd=REPO)
    assert proc.stdout is not None and proc.stdout.readline().strip() == b"ready"
    return proc


def spawn_commander(connect: str, name: str, vx: float) -> subprocess.Popen[bytes]:
    proc = subprocess.Popen(
        [sys.executable, PEER, "commander", "--connect", connect,
         "--ns", NS, "--name", name, "--vx", str(vx), "--lease", str(LEASE_S)],
        stdout=subprocess.PIPE, cwd=REPO)
    assert proc.stdout is not None and proc.stdout.readline().strip() == b"ready"
    return proc


def moving(vx: float) -> Callable[[str, dict[str, Any]], bool]:
    return lambda key, e: key == "odom" and abs(e["vx"] - vx) < 0.02


def still(key: str, event: dict[str, Any]) -> bool:
    return key == "odom" and abs(event["vx"]) < 0.005


def disappeared(name: str) -> Callable[[str, dict[str, Any]], bool]:
    """The gateway's error for the commander ``name`` (or whose name starts so) gone."""
    return lambda key, e: (key == "error" and e["message"].startswith(f"commander {name}")
                           and "disappeared" in e["message"])
