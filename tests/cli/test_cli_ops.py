"""``wheelgate estop``, ``enable`` and ``disable`` against a running daemon: what the simulated
drives do, what the command says, its exit code and its JSON."""

from __future__ import annotations

import contextlib
import dataclasses
import json
import threading
from typing import TYPE_CHECKING

from drivers.odrive.enums import AxisState
from gateway.cli import main
from gateway.config import load_config
from gateway.core.types import GatewayState
from gateway.runtime.daemon import Daemon
from gateway.runtime.sdnotify import SystemdNotifier
from tests.conftest import CONFIG_DIR

if TYPE_CHECKING:
    from collections.abc import Iterator
    from pathlib import Path

    from click.testing import CliRunner

TB3 = CONFIG_DIR / "turtlebot3_burger.yaml"


def axis_states(daemon: Daemon) -> set[object]:
    """The simulated ODrives' axis states (what reached the drives)."""
    sim = daemon.sim
    assert sim is not None
    states: set[object] = sim.snapshot(
        lambda: {getattr(s, "axis_state", None) for s in sim.simulators})
    return states


def test_estop_then_enable_from_the_shell(daemon: Daemon, sock_path: str,
                                          runner: CliRunner) -> None:
    assert axis_states(daemon) == {AxisState.CLOSED_LOOP_CONTROL}
    result = runner.invoke(main, ["estop", "--socket", sock_path])
    assert result.exit_code == 0, result.output
    assert result.stdout == ("e-stopped: every motor was sent zero and disarm; the e-stop "
                             "holds, across restarts too, until `wheelgate enable`\n")
    assert daemon.gateway.state is GatewayState.ESTOP
    result = runner.invoke(main, ["enable", "--socket", sock_path, "--json"])
    assert result.exit_code == 0, result.output
    assert json.loads(result.stdout) == {"ok": True, "state": "running"}
    assert axis_states(daemon) == {AxisState.CLOSED_LOOP_CONTROL}
    result = runner.invoke(main, ["disable", "--socket", sock_path])
    assert result.exit_code == 0, result.output
    assert result.stdout.startswith("disabled: the wheels ramp to zero, then every motor is ")


def test_an_estop_reaches_the_drives(daemon: Daemon, sock_path: str, runner: CliRunner) -> None:
    import time

    assert runner.invoke(main, ["estop", "--socket", sock_path, "--json"]).stdout == (
        '{"ok": true, "state": "estop"}\n')
    end = time.monotonic() + 5.0
    while axis_states(daemon) != {AxisState.IDLE} and time.monotonic() < end:
        time.sleep(0.02)
    assert axis_states(daemon) == {AxisState.IDLE}


def test_enable_refuses_another_robot_but_estop_goes_out(daemon: Daemon, sock_path: str,
                                                         runner: CliRunner) -> None:
    other = str(CONFIG_DIR / "mecanum.yaml")
    result = runner.invoke(main, ["estop", "-c", other, "--socket", sock_path])
    assert result.exit_code == 0, result.output
    assert "warning: the daemon on this socket runs the robot" in result.stderr
    assert daemon.gateway.state is GatewayState.ESTOP
    result = runner.invoke(main, ["enable", "-c", other, "--socket", sock_path])
    assert result.exit_code == 2, result.output
    assert "refusing to drive it" in result.stderr
    assert daemon.gateway.state is GatewayState.ESTOP


@contextlib.contextmanager
def lonely_daemon(sock_path: str, channel: str) -> Iterator[Daemon]:
    """A daemon whose motors never answer (no simulator on its bus), enabled on request,
    giving up after 0.3 s."""
    cfg = load_config(TB3, {"interface": "virtual", "channel": channel})
    cfg = dataclasses.replace(cfg, loop=dataclasses.replace(
        cfg.loop, enable_on_start=False, enable_timeout_s=0.3))
    d = Daemon(cfg, socket_path=sock_path, notifier=SystemdNotifier(None))
    thread = threading.Thread(target=d.run, daemon=True)
    thread.start()
    try:
        yield d
    finally:
        d.request_stop()
        thread.join(timeout=10)


def test_enable_says_why_the_motors_did_not_enable(sock_path: str, channel: str,
                                                  runner: CliRunner) -> None:
    with lonely_daemon(sock_path, channel):
        result = runner.invoke(main, ["enable", "--socket", sock_path, "--wait", "0.1"])
        assert result.exit_code == 1, result.output
        assert result.stderr == ("Error: the motors did not enable within 0.1 s: the gateway "
                                 "is still enabling (`wheelgate status` says what each motor "
                                 "reports)\n")
        result = runner.invoke(main, ["enable", "--socket", sock_path, "--json"])
        assert result.exit_code == 1, result.output
        doc = json.loads(result.stdout)
        assert doc["ok"] is False and doc["error"]["code"] == "error"
        assert doc["error"]["message"].startswith(
            "the motors did not enable: the gateway is fault: motor 'left' (node 1) did not "
            "enable within 0.3 s"), doc


def test_no_daemon_is_a_clear_error(runner: CliRunner) -> None:
    for op in ("estop", "enable", "disable"):
        result = runner.invoke(main, [op, "--socket", "/nonexistent/wg.sock", "--json"])
        assert result.exit_code == 1, result.output
        assert json.loads(result.stdout)["error"]["code"] == "no_gateway"


def test_an_estop_goes_out_with_a_configuration_that_cannot_be_read(
        daemon: Daemon, sock_path: str, runner: CliRunner, tmp_path: Path) -> None:
    broken = tmp_path / "robot.yaml"
    broken.write_text("drive: mecanum\nmotors: [\n")  # (edited, and not saved whole)
    result = runner.invoke(main, ["estop", "-c", str(broken), "--socket", sock_path])
    assert result.exit_code == 0, result.output
    assert result.stderr.startswith("warning: ") and f"sent to {sock_path} without checking " \
        "the robot" in result.stderr, result.stderr
    assert daemon.gateway.state is GatewayState.ESTOP
    result = runner.invoke(main, ["enable", "-c", str(broken), "--socket", sock_path])
    assert result.exit_code == 2, result.output  # an enable is not sent blind
    assert daemon.gateway.state is GatewayState.ESTOP
