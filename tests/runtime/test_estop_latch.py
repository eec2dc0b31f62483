"""An e-stop lasts: across a crash and a restart, against enable_on_start, against a CAN
ENABLE flag unless allowed; only an explicit enable releases it."""

from __future__ import annotations

import errno
import json
import os
import signal
import subprocess
import sys
import threading
import time
from typing import TYPE_CHECKING

import pytest

import gateway.runtime.latch as latch_module
from gateway.core.types import GatewayState, Twist
from gateway.runtime.client import ControlClient
from gateway.runtime.latch import EstopLatch, latch_path
from gateway.wire.can import TwistFlags
from tests.conftest import CONFIG_DIR
from tests.e2e_helpers import Rig, SocketPilot, errors_on_can, virtual_config

if TYPE_CHECKING:
    from collections.abc import Callable
    from pathlib import Path

TB3 = CONFIG_DIR / "turtlebot3_burger.yaml"


def state(rig: Rig) -> GatewayState:
    """The gateway state, read through a call so mypy does not narrow it across cycles."""
    return rig.gw.state


def test_latch_path_prefers_the_config_then_systemd_then_xdg(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    assert str(latch_path("/var/lib/x/latch", "r")) == "/var/lib/x/latch"
    monkeypatch.setenv("STATE_DIRECTORY", f"{tmp_path}/a:{tmp_path}/b")
    assert latch_path("", "robot 1") == tmp_path / "a" / "estop"
    monkeypatch.delenv("STATE_DIRECTORY")
    monkeypatch.setenv("XDG_STATE_HOME", str(tmp_path))
    assert latch_path("", "robot 1/x") == tmp_path / "wheelgate" / "estop-robot_1_x"


def test_a_damaged_or_unreadable_latch_still_holds(tmp_path: Path) -> None:
    latch = EstopLatch(tmp_path / "d" / "estop")
    assert latch.read() is None
    assert latch.set("e-stop requested on CAN")
    reason = latch.read()
    assert reason is not None and reason.startswith("e-stop requested on CAN (latched since ")
    latch.path.write_bytes(b"\x00garbage")
    assert "damaged; treated as latched" in str(latch.read())
    latch.clear()
    assert latch.read() is None
    latch.clear()  # twice is fine


def test_a_latch_that_cannot_be_written_leaves_no_temporary_file(tmp_path: Path) -> None:
    (tmp_path / "estop").mkdir()  # the latch's place taken by a directory
    latch = EstopLatch(tmp_path / "estop")
    assert not latch.set("e-stop requested on the socket")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["estop"]


def own_fsyncs(monkeypatch: pytest.MonkeyPatch, tmp_path: Path,
               mine: Callable[[Path], None]) -> None:
    """Route the fsyncs of this test's latch (its file and folder, under ``tmp_path``) to
    ``mine``, every other one to the real function: an earlier test's latch may still be
    syncing in its background thread (CI run 99 counted one of those here)."""
    real = latch_module._fsync_path

    def routed(path: Path) -> None:
        (mine if path == tmp_path or tmp_path in path.parents else real)(path)

    monkeypatch.setattr(latch_module, "_fsync_path", routed)


def test_one_estop_is_written_once(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    # The socket's request and the cycle that sees ESTOP both set the latch: one write (two
    # fsyncs, the file's and the folder's).
    syncs: list[Path] = []
    real = latch_module._fsync_path

    def counted(path: Path) -> None:
        syncs.append(path)
        real(path)

    own_fsyncs(monkeypatch, tmp_path, counted)
    latch = EstopLatch(tmp_path / "estop")
    assert latch.set("e-stop requested on the control socket")
    assert latch.set("e-stop requested on the control socket")
    assert latch.wait_durable() and syncs == [latch.path, tmp_path]
    latch.clear()  # the folder's fsync
    assert latch.set("e-stop requested on the control socket")  # a new e-stop: written
    assert latch.wait_durable() and latch.path.exists() and len(syncs) == 5


def test_the_caller_never_waits_for_the_disk(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                             caplog: pytest.LogCaptureFixture) -> None:
    # A slow SD card stalls an fsync for seconds: the loop thread (the caller) only writes
    # and renames; the fsyncs wait in the background, and a failing one is logged.
    release = threading.Event()
    synced: list[Path] = []

    def slow(path: Path) -> None:
        assert release.wait(10.0)
        synced.append(path)
        raise OSError(errno.EIO, "Input/output error")

    own_fsyncs(monkeypatch, tmp_path, slow)
    latch = EstopLatch(tmp_path / "estop")
    assert latch.set("e-stop requested on the control socket")  # returns, the fsync blocked
    assert json.loads(latch.path.read_text())["reason"] == "e-stop requested on the control socket"
    latch.clear()
    assert not latch.path.exists() and synced == []
    assert not latch.wait_durable(0.05)
    release.set()
    assert latch.wait_durable() and len(synced) == 2  # (each thread's first fsync failed)
    assert sorted(r.getMessage().split(": ")[1].split(",")[0] for r in caplog.records
                  if ", but not flushed to disk" in r.getMessage()) == ["removed", "written"]


def test_a_state_file_that_is_a_directory_is_a_config_error(tmp_path: Path) -> None:
    from gateway.config import load_config
    from gateway.core.errors import ConfigError

    robot = tmp_path / "robot.yaml"
    robot.write_text((CONFIG_DIR / "turtlebot3_burger.yaml").read_text()
                     + f"gateway: {{state_file: {tmp_path}}}\n")
    with pytest.raises(ConfigError) as err:
        load_config(robot)
    assert str(err.value) == (
        f"{robot}: gateway.state_file: expected the path of the e-stop latch file, got "
        f"'{tmp_path}', a directory (the e-stop would not survive a restart)")


def test_an_estop_and_an_enable_handled_before_a_cycle_still_stop_and_release(
    channel: str, sock_path: str
) -> None:
    """Two clients: one e-stops, the other enables right after, both handled between two
    cycles.  The e-stop's zero and disarm still reach every controller (before, the next
    cycle saw only ENABLING and nothing was disarmed), and the release removes the latch (it
    was left behind: the next start came up e-stopped)."""
    import can

    cfg = virtual_config(TB3, channel, rate_hz=100.0)
    with Rig(cfg, sock_path) as rig:
        rig.enable()
        assert rig.daemon is not None
        a, b = SocketPilot(sock_path), SocketPilot(sock_path)
        a.send(op="twist", vx=0.2)
        rig.advance(0.3)
        spy = can.Bus(interface="virtual", channel=channel)
        try:
            a.send(op="estop", id="A")
            b.send(op="enable", id="B")
            rig.advance(rig.period)
            seen = [(m.arbitration_id, bytes(m.data)) for m in iter(lambda: spy.recv(0.0), None)]
        finally:
            spy.shutdown()
        idle = b"\x01" + bytes(7)  # Set_Axis_State (0x07) IDLE
        for node in (1, 2):
            assert (node << 5 | 0x07, idle) in seen, seen
        assert not rig.daemon.latch.path.exists()
        assert state(rig) in (GatewayState.ENABLING, GatewayState.RUNNING)
        a.sock.close()
        b.sock.close()


@pytest.mark.parametrize("then", ["estop", "disable"])
def test_an_enable_then_an_estop_or_disable_before_a_cycle_enables_nothing(
    channel: str, sock_path: str, then: str
) -> None:
    """The other order: an enable, then an e-stop (or a disable) from another client, both
    handled between two cycles.  Before, the next cycle still took the enable and armed the
    axes while the state said ESTOP."""
    import can

    cfg = virtual_config(TB3, channel, rate_hz=100.0)
    with Rig(cfg, sock_path) as rig:
        rig.enable()
        rig.gw.supervisor.disable()
        rig.advance(0.2)
        assert state(rig) is GatewayState.DISABLED
        a, b = SocketPilot(sock_path), SocketPilot(sock_path)
        spy = can.Bus(interface="virtual", channel=channel)
        try:
            a.send(op="enable", id="A")
            b.send(op=then, id="B")
            rig.advance(0.5)
            seen = [(m.arbitration_id, bytes(m.data)) for m in iter(lambda: spy.recv(0.0), None)]
        finally:
            spy.shutdown()
        closed_loop = b"\x08" + bytes(7)  # Set_Axis_State (0x07) CLOSED_LOOP_CONTROL
        assert not [f for f in seen if f[0] & 0x1F == 0x07 and f[1] == closed_loop], seen
        assert state(rig) is (GatewayState.ESTOP if then == "estop" else GatewayState.DISABLED)
        a.sock.close()
        b.sock.close()


def handle_one(rig: Rig) -> None:
    """Wait for one request on the control socket and handle it, between cycles."""
    assert rig.daemon is not None
    end = time.monotonic() + 5.0
    while time.monotonic() < end:
        for client, request in rig.daemon.server.poll(0.01):
            rig.daemon.handle(client, request, rig.t)
            return
    raise AssertionError("no request came")


def test_a_can_estop_after_a_socket_release_is_latched(channel: str, sock_path: str) -> None:
    """A cycle sees ESTOP; before the next, a socket enable releases it (the latch goes) and a
    CAN ESTOP frame arrives, drained by that next cycle: the state is ESTOP at both steps, no
    change, and the CAN e-stop was not written (a restart came up without it)."""
    cfg = virtual_config(TB3, channel, rate_hz=100.0)
    with Rig(cfg, sock_path) as rig:
        assert rig.daemon is not None
        rig.enable()
        pilot = SocketPilot(sock_path)
        pilot.send(op="estop", id="1")
        handle_one(rig)
        rig.advance(rig.period)
        latch = rig.daemon.latch
        assert state(rig) is GatewayState.ESTOP and latch.path.exists()
        pilot.send(op="enable", id="2")
        handle_one(rig)  # between cycles: ENABLING, the latch gone
        assert state(rig) is GatewayState.ENABLING and not latch.path.exists()
        rig.send_can_twist(Twist(), TwistFlags.ESTOP)  # drained by the next cycle
        rig.advance(rig.period)
        assert state(rig) is GatewayState.ESTOP
        assert rig.gw.supervisor.reason == "e-stop requested on CAN"
        assert latch.path.exists()
        pilot.close()
    with Rig(cfg, f"{sock_path}2") as rig:
        assert rig.daemon is not None
        rig.daemon.run(max_cycles=3)
        assert rig.gw.supervisor.reason.startswith("e-stop requested on CAN (latched since")


def test_socket_estop_survives_a_restart_and_enable_on_start(channel: str, sock_path: str) -> None:
    cfg = virtual_config(TB3, channel, rate_hz=100.0)
    with Rig(cfg, sock_path) as rig:
        rig.enable()
        pilot = SocketPilot(sock_path)
        pilot.send(op="estop", id=1)
        rig.advance(0.05)
        assert state(rig) is GatewayState.ESTOP
        assert rig.daemon is not None
        path = rig.daemon.latch.path
        assert path.exists()
        # disable does not release it either
        pilot.send(op="disable", id=2)
        rig.advance(0.05)
        assert state(rig) is GatewayState.ESTOP and path.exists()
        pilot.close()
    # The same robot again (a restart): enable_on_start is true, the e-stop holds.
    with Rig(cfg, f"{sock_path}2") as rig:
        assert rig.daemon is not None
        rig.daemon.run(max_cycles=3)  # ends with the shutdown (STOPPING)
        assert rig.gw.supervisor.counts.estops == 1
        assert rig.daemon.latch.path.exists()
        assert "e-stop requested on the control socket (latched since" in rig.gw.supervisor.reason
        assert all(not s.model.armed for s in rig.sims)


def test_a_can_enable_flag_does_not_release_a_socket_estop_unless_allowed(
    channel: str, sock_path: str
) -> None:
    cfg = virtual_config(TB3, channel, rate_hz=100.0)
    with Rig(cfg, sock_path) as rig:
        rig.enable()
        pilot = SocketPilot(sock_path)
        pilot.send(op="estop")
        rig.advance(0.05)
        rig.send_can_twist(Twist(), TwistFlags.ENABLE)
        rig.advance(0.5)
        assert state(rig) is GatewayState.ESTOP
        reports = errors_on_can(rig)
        assert reports and "ESTOP" in reports[-1].code.name
        pilot.send(op="enable", id=3)  # the socket may
        rig.advance(1.0)
        assert state(rig) is GatewayState.RUNNING
        assert rig.daemon is not None and not rig.daemon.latch.path.exists()
        pilot.close()
    cfg = virtual_config(TB3, channel, rate_hz=100.0, estop_release="any")
    with Rig(cfg, f"{sock_path}2") as rig:
        rig.enable()
        rig.send_can_twist(Twist(), TwistFlags.ESTOP)
        rig.advance(0.05)
        assert state(rig) is GatewayState.ESTOP
        assert rig.daemon is not None and rig.daemon.latch.path.exists()  # a CAN e-stop too
        rig.send_can_twist(Twist(), TwistFlags.ENABLE)
        rig.advance(1.0)
        assert state(rig) is GatewayState.RUNNING


@pytest.mark.timeout(60)
def test_kill_9_after_an_estop_restarts_estopped(sock_path: str) -> None:
    """The crash case itself: a daemon e-stopped, killed with SIGKILL, started again."""
    def start() -> subprocess.Popen[bytes]:
        return subprocess.Popen([sys.executable, "-m", "gateway", "run", "--sim", "--socket",
                                 sock_path], stdout=subprocess.PIPE, stderr=subprocess.PIPE)

    def wait_socket(proc: subprocess.Popen[bytes]) -> None:
        end = time.monotonic() + 30
        while not os.path.exists(sock_path):
            assert proc.poll() is None and time.monotonic() < end, proc.communicate()
            time.sleep(0.05)

    proc = start()
    try:
        wait_socket(proc)
        with ControlClient(sock_path) as client:
            end = time.monotonic() + 20
            while client.request({"op": "status"})["state"] != "running":
                assert time.monotonic() < end
                time.sleep(0.05)
            assert client.request({"op": "estop"})["ok"]
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=10)
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.communicate()
    os.unlink(sock_path)  # what SIGKILL left behind (a restart removes a stale one too)
    proc = start()
    try:
        wait_socket(proc)
        with ControlClient(sock_path) as client:
            time.sleep(0.5)
            status = client.request({"op": "status"})
        assert status["state"] == "estop", json.dumps(status)[:500]
        assert "latched since" in status["reason"]
    finally:
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=10)
    assert b"starting e-stopped" in err
