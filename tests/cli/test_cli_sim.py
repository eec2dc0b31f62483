"""``wheelgate sim``: the simulated controllers as a process of their own, with the robot's
true pose; and the monitor's word on a virtual bus."""

from __future__ import annotations

import dataclasses
import json
import math
import os
import signal
import subprocess
import sys
from typing import TYPE_CHECKING, Any

import pytest

from gateway.cli import main
from gateway.cli.commands.monitor import virtual_bus_note
from gateway.cli.commands.sim import announce_lines, report_line
from gateway.config import load_config
from gateway.core.control import Source
from gateway.core.types import Twist
from gateway.drive.driveset import DriveSet
from gateway.sim.registry import simulators_for
from gateway.sim.truth import SimTruth, state_line
from tests.conftest import CONFIG_DIR
from tests.e2e_helpers import Rig, path_legs, virtual_config
from tests.socketcan_helpers import Lines

if TYPE_CHECKING:
    from pathlib import Path

    from click.testing import CliRunner


#: The keys of a device in a state line (``--json``).
DEVICE_KEYS = {"name", "node_id", "armed", "wheel_rad_s", "wheel_rad", "steer_rad"}


@pytest.mark.parametrize("name", ["mecanum.yaml", "swerve.yaml", "ackermann.yaml",
                                  "differential_castor.yaml"])
def test_the_sim_truth_is_the_end_to_end_truth(name: str, channel: str) -> None:
    """The pose ``wheelgate sim`` reports is the ground truth the in-process end-to-end tests
    use (exact wheel and steering angles, integrated every simulator step; a castor, steered by
    no actuator, left out)."""
    cfg = virtual_config(CONFIG_DIR / name, channel, rate_hz=100.0)
    with Rig(cfg) as rig:
        truth = SimTruth(cfg, rig.gw.drives, rig.sims)
        assert truth.available
        rig.ctl.on_step = truth.update
        rig.enable()
        truth.odometry.reset()
        for twist, seconds in path_legs(cfg, "square")[:4]:
            rig.gw.twist(twist, rig.t, Source.SOCKET)
            rig.advance(min(seconds, 1.5))
        rig.gw.twist(Twist(), rig.t, Source.SOCKET)
        rig.advance(1.0)
        mine, theirs = truth.odometry.state.pose, rig.truth.state.pose
        assert rig.truth.state.distance_m > 0.3
        assert (mine.x_m, mine.y_m, mine.theta_rad) == pytest.approx(
            (theirs.x_m, theirs.y_m, theirs.theta_rad), abs=1e-9)
        assert truth.odometry.state.distance_m == pytest.approx(rig.truth.state.distance_m,
                                                                abs=1e-9)
        state = truth.snapshot(1.0, 10, 1)
        assert state["pose"] == {"x": mine.x_m, "y": mine.y_m, "theta": mine.theta_rad}
        assert state["steps"] == 10 and state["late_steps"] == 1
        devices: list[dict[str, Any]] = state["devices"]  # type: ignore[assignment]
        assert [d["name"] for d in devices] == [s.motor.wheel for s in rig.sims]
        for d, sim in zip(devices, rig.sims, strict=True):
            assert set(d) == DEVICE_KEYS
            assert d["wheel_rad"] == sim.wheel_position_rad
            assert d["steer_rad"] == (sim.steer_rad if sim.motor.steering else None)
            assert d["armed"] is True


def test_a_wheel_steered_without_an_actuator_has_no_truth(channel: str) -> None:
    cfg = dataclasses.replace(virtual_config(CONFIG_DIR / "swerve.yaml", channel), steering=())
    drives = DriveSet(cfg)
    sims = simulators_for(drives.all_motors())
    truth = SimTruth(cfg, drives, sims)
    assert not truth.available
    assert truth.unsimulated == ("front_left", "front_right", "rear_left", "rear_right")
    state = truth.snapshot(0.0)
    assert state["pose"] is None and state["distance"] is None
    assert state_line(state).startswith("sim t=0.0s pose unknown | front_left 0.00 rad/s idle")
    text = announce_lines(cfg, sims, truth, 1000.0, as_json=False)[-1]
    assert ("; no true pose: wheel(s) front_left, front_right, rear_left, rear_right steered "
            "without a steering actuator (") in text
    ready = json.loads(announce_lines(cfg, sims, truth, 1000.0, as_json=True)[-1])
    assert ready["truth"] is False
    assert ready["unsimulated"] == ["front_left", "front_right", "rear_left", "rear_right"]


def test_state_lines_text_and_json() -> None:
    state: dict[str, Any] = {
        "t": 12.34, "pose": {"x": 1.0, "y": -0.0001, "theta": math.pi / 2}, "distance": 2.5,
        "steps": 12340, "late_steps": 3,
        "devices": [
            {"name": "front_left", "node_id": 1, "armed": True, "wheel_rad_s": 6.0612,
             "wheel_rad": 40.0, "steer_rad": None},
            {"name": "rear_right", "node_id": 4, "armed": False, "wheel_rad_s": -0.001,
             "wheel_rad": 0.0, "steer_rad": None},
            {"name": "front_left steering", "node_id": 5, "armed": True, "wheel_rad_s": 0.0,
             "wheel_rad": 0.2, "steer_rad": math.radians(-12.34)},
        ],
    }
    line = ("t=12.3s pose x=+1.000 y=+0.000 th=+90.0deg | front_left 6.06 rad/s armed | "
            "rear_right 0.00 rad/s idle | front_left steering -12.3deg armed")
    assert state_line(state) == f"sim {line}"
    assert report_line("state", state, as_json=False) == f"sim {line}"
    assert report_line("stopped", state, as_json=False) == f"sim stopped: {line}"
    assert json.loads(report_line("stopped", state, as_json=True)) == {"event": "stopped",
                                                                         **state}
    assert json.loads(report_line("state", state, as_json=True))["event"] == "state"


def test_announce_lines_name_every_device_then_the_bus(channel: str) -> None:
    cfg = load_config(CONFIG_DIR / "ackermann.yaml", {"interface": "virtual",
                                                       "channel": channel})
    drives = DriveSet(cfg)
    sims = simulators_for(drives.all_motors())
    truth = SimTruth(cfg, drives, sims)
    assert announce_lines(cfg, sims, truth, 1000.0, as_json=False) == [
        "sim: rear_left vesc node 1 (drive motor)",
        "sim: rear_right vesc node 2 (drive motor)",
        "sim: front_axle steering odrive node 3 (steering actuator)",
        f"sim: ready: 3 devices on virtual:{channel}, stepping at 1000 Hz (SIGUSR1 or Enter: "
        f"state line; Ctrl-C: stop)",
    ]
    assert [json.loads(line) for line in announce_lines(cfg, sims, truth, 250.0,
                                                        as_json=True)] == [
        {"event": "device", "name": "rear_left", "driver": "vesc", "node_id": 1,
         "role": "drive"},
        {"event": "device", "name": "rear_right", "driver": "vesc", "node_id": 2,
         "role": "drive"},
        {"event": "device", "name": "front_axle steering", "driver": "odrive", "node_id": 3,
         "role": "steer"},
        {"event": "ready", "interface": "virtual", "channel": channel, "devices": 3,
         "rate_hz": 250.0},
    ]


def sim_command(channel: str, *args: str) -> list[str]:
    """``python -m gateway ... sim`` on a virtual channel."""
    return [sys.executable, "-m", "gateway", "--interface", "virtual", "--channel", channel,
            "sim", *args]


@pytest.mark.timeout(60)
def test_sim_process_announces_reports_on_sigusr1_and_stops_cleanly(channel: str) -> None:
    proc = subprocess.Popen(
        sim_command(channel, "-c", str(CONFIG_DIR / "swerve.yaml"), "--json", "--every", "0",
                    "--rate", "200"),
        stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
    )
    try:
        assert proc.stdout is not None
        out = Lines(proc.stdout)
        lines = [out.next(30) for _ in range(9)]
        devices = [d for d in lines if d["event"] == "device"]
        assert [(d["name"], d["node_id"], d["role"]) for d in devices[:2]] == [
            ("front_left", 1, "drive"), ("front_right", 2, "drive")]
        assert sum(d["role"] == "steer" for d in devices) == 4
        ready = lines[-1]
        assert ready == {"event": "ready", "interface": "virtual", "channel": channel,
                         "devices": 8, "rate_hz": 200.0}
        proc.send_signal(signal.SIGUSR1)
        state = out.next(10)
        assert state["event"] == "state"
        assert state["pose"] == {"x": 0.0, "y": 0.0, "theta": 0.0}
        assert state["distance"] == 0.0
        assert isinstance(state["steps"], int) and state["steps"] > 0
        assert isinstance(state["late_steps"], int)
        assert len(state["devices"]) == 8
        assert all(set(d) == DEVICE_KEYS and d["armed"] is False for d in state["devices"])
        proc.send_signal(signal.SIGTERM)
        stopped = out.next(10)
        assert stopped["event"] == "stopped"
        assert stopped["steps"] >= state["steps"]
        assert proc.wait(timeout=10) == 0
    finally:
        if proc.poll() is None:
            proc.kill()
        _, err = proc.communicate()
    assert b"virtual bus exists only inside this process" in err


@pytest.mark.timeout(60)
def test_sim_in_a_terminal_reports_on_enter_and_stops_on_ctrl_c(channel: str) -> None:
    master, slave = os.openpty()
    try:
        proc = subprocess.Popen(sim_command(channel, "--every", "0", "--rate", "200"),
                                stdin=slave, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL)
    finally:
        os.close(slave)
    try:
        assert proc.stdout is not None
        out = Lines(proc.stdout)
        lines = [out.text(30) for _ in range(5)]
        assert lines[0] == "sim: front_left odrive node 1 (drive motor)"
        assert lines[-1].startswith(f"sim: ready: 4 devices on virtual:{channel}, stepping at "
                                    f"200 Hz (SIGUSR1 or Enter")
        for _ in range(2):
            os.write(master, b"\n")
            asked = out.text(10)
            assert asked.startswith("sim t=")
            assert "pose x=+0.000 y=+0.000 th=+0.0deg | front_left 0.00 rad/s idle |" in asked
        proc.send_signal(signal.SIGINT)
        last = out.text(10)
        assert last.startswith("sim stopped: t=")
        assert last.endswith("| rear_right 0.00 rad/s idle")
        assert proc.wait(timeout=10) == 0
    finally:
        os.close(master)
        if proc.poll() is None:
            proc.kill()
        proc.communicate()


@pytest.mark.timeout(60)
def test_sim_reports_every_period_unasked(channel: str) -> None:
    proc = subprocess.Popen(sim_command(channel, "--json", "--every", "0.3", "--rate", "200"),
                            stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                            stderr=subprocess.DEVNULL)
    try:
        assert proc.stdout is not None
        out = Lines(proc.stdout)
        while out.next(30)["event"] != "ready":
            pass
        first, second = out.next(10), out.next(10)
        assert first["event"] == second["event"] == "state"
        assert 0.1 < second["t"] - first["t"] < 5.0
        proc.send_signal(signal.SIGTERM)
        while (last := out.next(10))["event"] == "state":
            pass
        assert last["event"] == "stopped"
        assert proc.wait(timeout=10) == 0
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.communicate()


def test_sim_says_which_bus_it_cannot_open(runner: CliRunner) -> None:
    result = runner.invoke(main, ["--interface", "socketcan", "--channel", "wgnosuchcan0",
                                  "sim"])
    assert result.exit_code == 1, result.output
    assert "wheelgate sim: Cannot open CAN bus socketcan:wgnosuchcan0" in result.stderr
    # What to do, said once: the kernel has no SocketCAN (this CI host), or no such interface.
    said = ("this kernel has no SocketCAN: load it", "there is no network interface "
            "'wgnosuchcan0' (ip -details link show lists them; a test bus: modprobe vcan")
    assert sum(s in result.stderr for s in said) == 1, result.stderr


def test_sim_refuses_a_bad_configuration(runner: CliRunner, tmp_path: Path) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("drive: hovercraft\n")
    result = runner.invoke(main, ["sim", "-c", str(bad)])
    assert result.exit_code == 2, result.output
    assert str(bad) in result.stderr


@pytest.mark.filterwarnings("ignore::pytest.PytestUnhandledThreadExceptionWarning")
def test_sim_stops_with_an_error_when_its_simulator_thread_dies(
        runner: CliRunner, channel: str, monkeypatch: pytest.MonkeyPatch) -> None:
    def broken(self: SimTruth, now_s: float) -> None:
        raise ZeroDivisionError("deliberately broken truth")

    monkeypatch.setattr(SimTruth, "update", broken)
    result = runner.invoke(main, ["--interface", "virtual", "--channel", channel, "sim",
                                  "--every", "0"])
    assert result.exit_code == 1, result.output
    assert "the simulator thread stopped: ZeroDivisionError('deliberately broken truth')" in (
        result.stderr)


def test_monitor_on_a_virtual_bus_says_why_it_sees_nothing(runner: CliRunner,
                                                           channel: str) -> None:
    result = runner.invoke(main, ["--interface", "virtual", "--channel", channel, "monitor",
                                  "--bus", "--once", "--window", "0.1"])
    assert result.exit_code == 0, result.output
    assert result.stderr == virtual_bus_note(channel) + "\n"
    assert f"python-can's virtual one (channel {channel!r}), which exists only inside one " \
           f"process" in result.stderr
    for command in ("sudo ip link add vcan0 type vcan && sudo ip link set vcan0 up",
                    "wheelgate --interface socketcan --channel vcan0 sim",
                    "wheelgate --interface socketcan --channel vcan0 run",
                    "wheelgate --interface socketcan --channel vcan0 monitor --bus",
                    "candump vcan0"):
        assert command in result.stderr
    assert result.stdout.strip(), "the monitor still runs and prints its snapshot"


def test_monitor_on_another_interface_gives_no_virtual_bus_note(runner: CliRunner) -> None:
    result = runner.invoke(main, ["--interface", "socketcan", "--channel", "wgnosuchcan0",
                                  "monitor", "--bus", "--once", "--window", "0.1"])
    assert result.exit_code == 1, result.output
    assert "Cannot open CAN bus socketcan:wgnosuchcan0" in result.stderr
    assert "virtual" not in result.stderr
