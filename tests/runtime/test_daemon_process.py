"""The daemon as a process: sd_notify, SIGTERM/SIGINT with the recorded last frames."""

from __future__ import annotations

import os
import signal
import socket
import struct
import subprocess
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING

import can
import pytest

import gateway
from gateway.config import load_config
from gateway.runtime.client import ControlClient
from gateway.runtime.latch import EstopLatch
from gateway.runtime.report import motors_text
from tests.conftest import CONFIG_DIR

if TYPE_CHECKING:
    from collections.abc import Iterator


#: Longer than the 10 s default: each starts the daemon as a process.
pytestmark = pytest.mark.timeout(30)


@pytest.fixture
def notify_socket(sock_path: str) -> Iterator[tuple[socket.socket, str]]:
    path = sock_path.replace("s.sock", "n.sock")
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    sock.bind(path)
    sock.settimeout(0.2)
    yield sock, path
    sock.close()


def read_notify(sock: socket.socket, until: bytes, timeout_s: float) -> list[bytes]:
    got: list[bytes] = []
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        try:
            msg = sock.recv(4096)
        except TimeoutError:
            continue
        got.append(msg)
        if msg.startswith(until):
            break
    return got


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGINT, signal.SIGHUP,
                                    signal.SIGQUIT, signal.SIGABRT, signal.SIGUSR1,
                                    signal.SIGUSR2])
@pytest.mark.timeout(60)
def test_signal_sends_zero_and_disarm_then_exits_0(
    signum: int, sock_path: str, tmp_path: Path, notify_socket: tuple[socket.socket, str]
) -> None:
    nsock, npath = notify_socket
    record = tmp_path / "run.log"
    env = {**os.environ, "NOTIFY_SOCKET": npath, "WATCHDOG_USEC": "400000"}
    env.pop("WATCHDOG_PID", None)
    proc = subprocess.Popen(
        [sys.executable, "-m", "gateway", "run", "--sim", "--socket", sock_path,
         "--record", str(record)],
        env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
    )
    try:
        before = read_notify(nsock, b"READY=1", 30.0)
        assert before and before[-1].startswith(b"READY=1"), (before, proc.poll())
        with ControlClient(sock_path) as client:
            # READY=1 comes with the bus and the socket up; the drives enable just after.
            end = time.monotonic() + 10
            while client.request({"op": "status"})["state"] != "running":
                assert time.monotonic() < end, "the drives did not enable"
                time.sleep(0.05)
            for _ in range(10):
                assert client.request({"op": "twist", "vx": 0.4, "wz": 0.5})["ok"]
                time.sleep(0.05)
        during = read_notify(nsock, b"WATCHDOG=1", 5.0)
        assert any(m == b"WATCHDOG=1" for m in during)
        start = time.monotonic()
        proc.send_signal(signum)
        code = proc.wait(timeout=10)
        elapsed = time.monotonic() - start
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        _, err = proc.communicate()
    assert code == 0, err.decode()
    # No fatal-signal handler between the signal and the stop: faulthandler's SIGABRT handler
    # walked the running threads and could crash the process before the zero went out.
    assert b"Fatal Python error" not in err, err.decode()
    if signum == signal.SIGABRT:
        # systemd's watchdog signal: where each thread was is written (by Python, safely).
        assert b"most recent call first" in err, err.decode()
    # Bounded, not a timing assertion: the daemon's own grace is 0.3 s of its 1 s budget.
    assert elapsed < 5.0
    after = read_notify(nsock, b"STOPPING=1", 2.0)
    assert any(m.startswith(b"STOPPING=1") for m in after)
    assert any(m.startswith(b"STATUS=") for m in before + during + after)
    sent = [m for m in can.LogReader(str(record)) if not m.is_rx]
    assert len(sent) > 50
    # Embedded default: ODrive nodes 1..4.  After the last moving velocity command each node
    # gets Set_Input_Vel 0 and Set_Axis_State IDLE.
    for node in (1, 2, 3, 4):
        vel_id, state_id = node << 5 | 0x0D, node << 5 | 0x07
        velocities = [(i, struct.unpack("<f", bytes(m.data[:4]))[0])
                      for i, m in enumerate(sent) if m.arbitration_id == vel_id]
        assert any(v != 0.0 for _, v in velocities), f"node {node} never moved"
        last_moving = max(i for i, v in velocities if v != 0.0)
        assert velocities[-1][1] == 0.0
        idle = [i for i, m in enumerate(sent)
                if m.arbitration_id == state_id and bytes(m.data[:4]) == b"\x01\x00\x00\x00"]
        assert idle and idle[-1] > last_moving, f"node {node} was not disarmed at the end"
    assert not os.path.exists(sock_path), "the socket file was left behind"
    if signum not in (signal.SIGTERM, signal.SIGINT):
        assert f"stopped ({signal.Signals(signum).name}); every motor" in err.decode()


@pytest.mark.timeout(60)
def test_ready_with_the_motors_unpowered_and_the_status_says_what_it_waits_for(
    sock_path: str, tmp_path: Path, notify_socket: tuple[socket.socket, str]
) -> None:
    """systemd must not wait for the motors: READY=1 once the bus and the socket are up, the
    state in STATUS=, and the drives enable when the motors answer."""
    nsock, npath = notify_socket
    cfg = tmp_path / "robot.yaml"
    cfg.write_text((CONFIG_DIR / "turtlebot3_burger.yaml").read_text()
                   + "\ngateway:\n  enable_timeout_s: 0.5\n")
    env = {**os.environ, "NOTIFY_SOCKET": npath}
    # No --sim: nothing answers on this virtual bus, as with the motors' power off.
    proc = subprocess.Popen(
        [sys.executable, "-m", "gateway", "--interface", "virtual", "--channel",
         f"unpowered-{os.getpid()}", "run",
         "-c", str(cfg), "--socket", sock_path],
        env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
    )
    try:
        ready = read_notify(nsock, b"READY=1", 30.0)
        assert any(m.startswith(b"READY=1") for m in ready), (ready, proc.poll())
        # First it listens for another program commanding these motors, then it waits.
        assert any(b"ENABLING: listening 0.25 s" in m for m in ready), ready
        waiting = read_notify(nsock, b"STATUS=ENABLING: waiting for the motors to enable", 10.0)
        assert any(b"STATUS=ENABLING: waiting for the motors to enable" in m
                   for m in waiting), waiting
        later = read_notify(nsock, b"waiting for motors", 10.0)
        assert any(b"STATUS=FAULT" in m and b"waiting for motors: left, right silent" in m
                   for m in later), later
        with ControlClient(sock_path) as client:
            assert client.request({"op": "status"})["state"] == "fault"
    finally:
        proc.send_signal(signal.SIGTERM)
        proc.communicate(timeout=10)


@pytest.mark.timeout(60)
def test_run_says_when_the_motors_run_and_why_they_do_not(sock_path: str, tmp_path: Path,
                                                           channel: str) -> None:
    # The lines a person reads on starting the daemon, in order: the bus is open, then the
    # motors are enabled; on a virtual bus with no simulator, that only simulators answer there.
    def run(*args: str) -> list[str]:
        done = subprocess.run(
            [sys.executable, "-m", "gateway", "--interface", "virtual", "--channel", channel,
             "run", "--socket", sock_path, "--duration", "3", *args],
            check=False, capture_output=True, text=True, timeout=50)
        assert done.returncode == 0, done.stderr
        return [line for line in done.stderr.splitlines() if line.startswith("wheelgate: ")]

    lines = run("--sim")
    assert lines[0].startswith(f"wheelgate: demo_mecanum (mecanum, 4 wheels) at 200 Hz: bus "
                               f"virtual {channel} open with simulated controllers"), lines
    assert lines[1] == (f"wheelgate: running on virtual {channel}: 4 motors enabled; control "
                        f"socket {sock_path}"), lines
    assert lines[-1].startswith("wheelgate: stopped"), lines
    quick = tmp_path / "robot.yaml"
    quick.write_text(CONFIG_DIR.joinpath("turtlebot3_burger.yaml").read_text().replace(
        "bus:", "gateway: {enable_timeout_s: 1.0}\nbus:") + "")
    lines = run("-c", str(quick))
    assert not any("running on" in line for line in lines), lines
    failed = [line for line in lines if "did not enable" in line]
    assert len(failed) == 1 and "where only simulated controllers answer" in failed[0], lines
    assert "`wheelgate run --sim`" in failed[0]
    # A daemon that starts e-stopped (a latch from before) does not say it is enabling.
    latched = tmp_path / "latched.yaml"
    EstopLatch(tmp_path / "estop").set("e-stop requested on the socket")
    latched.write_text(f"gateway: {{state_file: {tmp_path / 'estop'}}}\n"
                       + (Path(gateway.__file__).parent / "data" / "default.yaml").read_text())
    lines = run("--sim", "-c", str(latched))
    assert lines[0].endswith("; 4 motors held e-stopped until an enable"), lines
    assert not any("running on" in line or "enabling" in line for line in lines), lines


def test_the_start_and_running_lines_count_motors_and_steering_actuators_alike() -> None:
    swerve = load_config(CONFIG_DIR / "swerve.yaml")
    assert motors_text(swerve) == "4 motors and 4 steering actuators"
    assert motors_text(load_config(None)) == "4 motors"
