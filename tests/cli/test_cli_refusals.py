"""How commands refuse and stop: ``monitor --once --json`` and ``scan --json`` fail in JSON
as ``status --json`` does; ``twist`` sends stop when a signal ends its ``--duration``; a
daemon running another robot is refused without click's usage lines, and ``status --json``
carries the warning."""

from __future__ import annotations

import binascii
import json
import os
import signal
from typing import TYPE_CHECKING, Any, ClassVar

import click
import pytest

import gateway.cli.commands.jog as jog_command
import gateway.cli.commands.monitor as monitor_command
import gateway.cli.commands.scan as scan_command
import gateway.cli.commands.status as status_command
import gateway.cli.commands.twist as twist_command
from gateway.apps.jog.keys import jog_limits
from gateway.cli import main
from gateway.cli.commands._common import daemon_config
from gateway.config import load_config
from gateway.core.errors import BusError
from tests.conftest import CONFIG_DIR
from tests.wire.test_status_format import SAMPLE_JSON

if TYPE_CHECKING:
    from collections.abc import Iterator
    from pathlib import Path

    from click.testing import CliRunner

MECANUM = str(CONFIG_DIR / "mecanum.yaml")


class FakeDaemon:
    """A control client whose daemon runs the robot of :data:`SAMPLE_JSON` ('tb3'); it keeps
    every request, and raises :attr:`signal_at` (a signal number) into this process at the
    third twist."""

    requests: ClassVar[list[dict[str, Any]]] = []
    signal_at: ClassVar[int | None] = None

    def __init__(self, path: str, timeout_s: float = 2.0) -> None:
        self.path = path

    def __enter__(self) -> FakeDaemon:
        return self

    def __exit__(self, *exc: object) -> None:
        pass

    def close(self) -> None:
        pass

    def request(self, payload: dict[str, Any]) -> dict[str, Any]:
        self.requests.append(dict(payload))
        if payload["op"] == "status":
            return {"ok": True, "id": 1, **SAMPLE_JSON}
        twists = sum(r["op"] == "twist" for r in self.requests)
        if payload["op"] == "twist" and twists == 3 and self.signal_at is not None:
            os.kill(os.getpid(), self.signal_at)
        applied = {"vx_m_s": payload.get("vx", 0.0), "vy_m_s": 0.0, "wz_rad_s": 0.0}
        return {"ok": True, "id": 1, "twist": applied, "applied": applied}


@pytest.fixture
def fake(monkeypatch: pytest.MonkeyPatch) -> Iterator[type[FakeDaemon]]:
    for module in (twist_command, status_command):
        monkeypatch.setattr(module, "ControlClient", FakeDaemon)
    FakeDaemon.requests = []
    FakeDaemon.signal_at = None
    yield FakeDaemon
    FakeDaemon.signal_at = None


def _unhandled(signum: int, frame: object) -> None:
    raise AssertionError(f"signal {signum} reached the test's handler: twist did not catch it")


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGINT])
def test_a_signal_ends_a_twist_with_stop(runner: CliRunner, fake: type[FakeDaemon],
                                         signum: signal.Signals) -> None:
    old = signal.signal(signum, _unhandled)
    try:
        fake.signal_at = signum
        result = runner.invoke(main, ["twist", "--socket", "/s", "--vx", "0.3",
                                      "--duration", "60", "--rate", "100"])
    finally:
        assert signal.getsignal(signum) is _unhandled  # twist put the handler back
        signal.signal(signum, old)
    assert result.exit_code == 0, result.output
    ops = [r["op"] for r in fake.requests]
    assert ops == ["twist"] * 3 + ["stop"]  # at once, not 60 s of twists
    assert f"twist: {signum.name}: ended early; stop sent to /s" in result.stderr


def test_another_robot_is_refused_without_usage_lines(runner: CliRunner,
                                                      fake: type[FakeDaemon]) -> None:
    result = runner.invoke(main, ["twist", "-c", MECANUM, "--socket", "/s", "--vx", "0.1"])
    assert result.exit_code == 2, result.output
    assert "runs the robot 'tb3', not 'mecanum'" in result.stderr
    assert "refusing to drive it" in result.stderr
    assert "Usage:" not in result.stderr and "--help" not in result.stderr
    assert [r["op"] for r in fake.requests] == ["status"]  # no twist went out


def test_status_json_carries_the_other_robot_warning(runner: CliRunner,
                                                     fake: type[FakeDaemon]) -> None:
    result = runner.invoke(main, ["status", "-c", MECANUM, "--socket", "/s", "--json"])
    assert result.exit_code == 0, result.output
    doc = json.loads(result.stdout)
    assert doc["warnings"] == [
        f"the daemon on this socket runs the robot 'tb3', not 'mecanum' of {MECANUM}"]
    assert "warning: the daemon on this socket runs the robot 'tb3'" in result.stderr
    same = json.loads(runner.invoke(main, ["status", "--socket", "/s", "--json"]).stdout)
    assert "warnings" not in same  # the reply as it came


def test_monitor_once_json_without_a_daemon_is_a_json_error(runner: CliRunner,
                                                            tmp_path: Path) -> None:
    sock = tmp_path / "none.sock"
    result = runner.invoke(main, ["monitor", "--once", "--json", "--socket", str(sock)])
    status = runner.invoke(main, ["status", "--json", "--socket", str(sock)])
    assert result.exit_code == status.exit_code == 1, result.output
    doc = json.loads(result.stdout)
    assert doc == json.loads(status.stdout)
    assert doc["ok"] is False and doc["error"]["code"] == "no_gateway"
    assert f"no gateway is listening on {sock}" in doc["error"]["message"]


def test_monitor_once_json_on_a_bus_that_cannot_open_is_a_json_error(
        runner: CliRunner, monkeypatch: pytest.MonkeyPatch) -> None:
    def no_bus(interface: str, channel: str, *args: object, **options: object) -> None:
        raise BusError(f"Cannot open CAN bus {interface}:{channel}: no such device")

    monkeypatch.setattr(monitor_command, "open_bus", no_bus)
    result = runner.invoke(main, ["monitor", "--bus", "--once", "--json"])
    assert result.exit_code == 1, result.output
    doc = json.loads(result.stdout)
    assert doc["ok"] is False and doc["error"]["code"] == "bus_unavailable"
    assert "Cannot open CAN bus virtual:" in doc["error"]["message"]
    assert "Error:" not in result.stderr
    plain = runner.invoke(main, ["monitor", "--bus", "--once"])
    assert plain.exit_code == 1 and plain.stdout == ""
    assert "Error: Cannot open CAN bus virtual:" in plain.stderr


def test_scan_json_fails_in_json_for_a_bus_or_a_configuration(
        runner: CliRunner, monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    def no_bus(*args: object) -> None:
        raise BusError("Cannot open CAN bus socketcan:can9: no such device")

    monkeypatch.setattr(scan_command, "scan", no_bus)
    result = runner.invoke(main, ["scan", "--json", "--timeout", "0.1"])
    assert result.exit_code == 1, result.output
    assert json.loads(result.stdout) == {"ok": False, "error": {
        "code": "bus_unavailable", "message": "Cannot open CAN bus socketcan:can9: no such device"}}
    missing = tmp_path / "robot.yaml"
    bad = runner.invoke(main, ["scan", "--json", "-c", str(missing)])
    assert bad.exit_code == 2, bad.output
    doc = json.loads(bad.stdout)
    assert doc["error"]["code"] == "bad_config" and str(missing) in doc["error"]["message"]
    plain = runner.invoke(main, ["scan", "--timeout", "0.1"])
    assert plain.exit_code == 1 and plain.stdout == "" and "Error: Cannot open" in plain.stderr


def test_an_edited_file_is_said_and_jog_takes_the_daemons_file(
        runner: CliRunner, fake: type[FakeDaemon], tmp_path: Path,
        monkeypatch: pytest.MonkeyPatch) -> None:
    """The daemon ('tb3') runs ``robot.yaml``: status -c of that file says when it has been
    edited since; jog without -c takes the daemon's file for its key limits (saying so when it
    has changed since), and the embedded default's when it cannot read a file of that robot."""
    robot = tmp_path / "robot.yaml"
    text = (CONFIG_DIR / "turtlebot3_burger.yaml").read_text().replace(
        "name: turtlebot3_burger", "name: tb3")
    robot.write_text(text)
    running = {"path": str(robot), "fingerprint": f"{binascii.crc32(robot.read_bytes()):08x}"}
    monkeypatch.setitem(SAMPLE_JSON, "config", running)
    ctx = click.Context(main)
    reply = FakeDaemon("/s").request({"op": "status"})
    cfg, note = daemon_config(ctx, reply)
    assert cfg is not None and cfg.name == "tb3" and note == ""
    limits = jog_command._checked(cfg, None, None)
    assert limits.max_linear_m_s < 0.5 < jog_limits(load_config(None)).max_linear_m_s
    with pytest.raises(click.BadParameter, match=r"at most 0\.21 m/s .*\(robot 'tb3'\)"):
        jog_command._checked(cfg, 0.5, None)
    quiet = runner.invoke(main, ["status", "-c", str(robot), "--socket", "/s"])
    assert quiet.exit_code == 0 and "warning" not in quiet.stderr, quiet.output
    robot.write_text(text + "# edited after the daemon started\n")
    said = (f"the daemon runs {robot} as it was when the daemon started; the file has "
            "changed since (restart the daemon to use the change)")
    edited = runner.invoke(main, ["status", "-c", str(robot), "--socket", "/s"])
    assert edited.exit_code == 0 and f"warning: {said}" in edited.stderr, edited.output
    cfg, note = daemon_config(ctx, reply)
    assert cfg is not None and cfg.name == "tb3" and note == f"warning: {said}"
    # Not this robot's file, no such file, a path no file can have: the default's limits.
    robot.write_text(text.replace("name: tb3", "name: other"))
    for path in (str(robot), str(tmp_path / "gone.yaml"), "bad\0path", str(tmp_path)):
        assert daemon_config(ctx, {**reply, "config": {**running, "path": path}}) == (None, "")
