"""``wheelgate monitor`` end to end: a log, a virtual bus with simulated controllers, a daemon
in a thread, bad arguments, and the live screen on an 80 x 24 terminal (a pty)."""

from __future__ import annotations

import json
import re
import sys
from typing import TYPE_CHECKING

import pytest

from gateway import cli
from gateway.cli import main
from gateway.sim.bus import SimulatedControllers
from tests.apps.monitor_helpers import Session, config_at, default_config
from tests.conftest import CONFIG_DIR
from tests.pty_helpers import ANSI, MONITOR_FRAME, Pty

if TYPE_CHECKING:
    from pathlib import Path

    from click.testing import CliRunner, Result

    from gateway.runtime.daemon import Daemon

#: Wall-clock start of the generated log (python-can records time.time()).
EPOCH = 1_700_000_000.0
#: Line of the corrupt entry in the generated log.
BAD_LINE = 7


@pytest.fixture(autouse=True)
def _registered(monkeypatch: pytest.MonkeyPatch) -> None:
    """Run the command through the real root group, as ``wheelgate monitor``."""
    monkeypatch.setitem(cli.COMMANDS, "monitor", "monitor")


def monitor(runner: CliRunner, *args: str) -> Result:
    return runner.invoke(main, ["monitor", *args])


@pytest.fixture
def log_file(tmp_path: Path) -> Path:
    """Three seconds of the demo robot (four ODrives) at 2 rad/s, in candump format, with one
    corrupt line and one error frame."""
    frames = Session(default_config()).run(3.0, [2.0, 2.0, 2.0, 2.0])
    lines = [f"({EPOCH + t:.6f}) can0 {f.to_cansend()} {'T' if d == 'tx' else 'R'}"
             for t, f, d in frames]
    lines.insert(BAD_LINE - 1, "(1700000000.1) can0 06D#00112233445566778899 R")
    lines.insert(BAD_LINE + 2, f"({EPOCH + 0.2:.6f}) can0 20000080#0000000000000000 R")
    path = tmp_path / "robot.log"
    path.write_text("# recorded by a test\n" + "\n".join(lines) + "\n")
    return path


def test_log_once_json_is_the_state_at_the_end_of_the_log(runner: CliRunner,
                                                          log_file: Path) -> None:
    result = monitor(runner, "--log", str(log_file), "--once", "--json")
    assert result.exit_code == 0, result.output
    assert result.stderr == (f"{log_file}: line {BAD_LINE + 1}: expected at most 8 data bytes, "
                             "got 10 (skipped)\n")  # + 1: the comment line
    doc = json.loads(result.stdout)
    assert doc["source"] == f"log {log_file}"
    assert doc["time_s"] == pytest.approx(EPOCH + 2.995)
    assert doc["elapsed_s"] == pytest.approx(2.995)
    assert [m["state"] for m in doc["motors"]] == ["enabled"] * 4
    assert doc["motors"][1]["velocity_rad_s"] == pytest.approx(2.0, abs=1e-3)
    assert doc["motors"][1]["motor_rpm"] == pytest.approx(-190.986, abs=0.01)
    assert doc["errors"] == {"rejected by odrive": 0, "bus error frames": 1,
                             "unreadable lines": 1}
    ids = {(i["id_hex"], i["direction"]): i for i in doc["ids"]}
    est = ids[("0x069", "rx")]
    assert est["label"] == "ODrive node 3 Get_Encoder_Estimates (rear_left)"
    assert est["rate_hz"] == pytest.approx(100.0, abs=0.5)
    assert ids[("0x06D", "tx")]["rate_hz"] == pytest.approx(200.0, abs=0.5)
    # 4 x (200 Set_Input_Vel + 100 estimates + 10 heartbeats) of 8 bytes a second on 1 Mbit/s.
    assert doc["load"]["nominal_percent"] == pytest.approx(4 * 310 * 111 / 1e4, rel=0.01)
    assert doc["load"]["worst_percent"] == pytest.approx(4 * 310 * 135 / 1e4, rel=0.01)


def test_a_file_without_a_readable_line_is_refused(runner: CliRunner, tmp_path: Path) -> None:
    # (An empty log is a recording of nothing: test_empty_log.)
    path = tmp_path / "not.log"
    path.write_text("# a comment\ngarbage\nmore garbage\n")
    result = monitor(runner, "--log", str(path), "--once")
    assert result.exit_code == 2, result.output
    assert result.stdout == ""
    assert result.stderr.endswith(
        f"Error: {path}: no readable frames in the log (2 unreadable lines); expected a "
        f"candump log (candump -l, wheelgate run --record)\n")


def test_a_log_of_error_frames_only_is_shown(runner: CliRunner, tmp_path: Path) -> None:
    path = tmp_path / "errors.log"
    path.write_text("(1.0) vcan0 20000004#0000000000000000\n")
    result = monitor(runner, "--log", str(path), "--once")
    assert result.exit_code == 0, result.output
    assert "bus error frames 1" in result.stdout


def test_log_once_text(runner: CliRunner, log_file: Path) -> None:
    result = monitor(runner, "--log", str(log_file), "--once", "--window", "1")
    assert result.exit_code == 0, result.output
    assert "wheelgate monitor: log" in result.stdout
    assert "front_right   odrive     2  enabled" in result.stdout
    assert "ODrive node 4 Set_Input_Vel (rear_right)" in result.stdout
    assert "\x1b[" not in result.stdout  # not a terminal: no screen control


def test_log_live_replay_fast_prints_the_end(runner: CliRunner, log_file: Path) -> None:
    result = monitor(runner, "--log", str(log_file), "--fast", "--refresh", "100")
    assert result.exit_code == 0, result.output
    assert result.stdout.count("wheelgate monitor: log") >= 1
    assert "  2.995 s into the log\n" in result.stdout.split("wheelgate monitor: log")[-1]


def test_log_replay_at_recorded_speed_and_ctrl_c(runner: CliRunner, log_file: Path,
                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    """Waiting for the log's next frame sleeps; Ctrl-C there ends the monitor with 0."""
    sleeps: list[float] = []

    def interrupted_sleep(seconds: float) -> None:
        sleeps.append(seconds)
        raise KeyboardInterrupt

    monkeypatch.setattr("gateway.cli.commands.monitor.time.sleep", interrupted_sleep)
    result = monitor(runner, "--log", str(log_file))
    assert result.exit_code == 0, result.output
    assert len(sleeps) == 1 and 0.0 < sleeps[0] <= 0.2  # the first gap of the log is 5 ms


def test_empty_log(runner: CliRunner, tmp_path: Path) -> None:
    path = tmp_path / "empty.log"
    path.write_text("")
    result = monitor(runner, "--log", str(path), "--once", "--json")
    assert result.exit_code == 0, result.output
    doc = json.loads(result.stdout)
    assert (doc["frames"], doc["ids"]) == (0, [])
    assert [m["state"] for m in doc["motors"]] == ["offline"] * 4


# --------------------------------------------------------------------- bus


def test_bus_once_with_simulated_controllers_sends_nothing(runner: CliRunner,
                                                           channel: str) -> None:
    cfg = default_config()
    with SimulatedControllers(Session(cfg).sims, channel).start() as sims:
        result = runner.invoke(main, ["--interface", "virtual", "--channel", channel, "monitor",
                                      "--bus", "--once", "--json", "--window", "0.5"])
        received = [s.received for s in sims.simulators]
    assert result.exit_code == 0, result.output
    assert received == [0, 0, 0, 0]  # the monitor never sent a frame
    doc = json.loads(result.stdout)
    assert doc["source"] == f"bus virtual:{channel}"
    # Answering, not armed (no gateway here): the ODrive heartbeat says idle.
    assert [m["state"] for m in doc["motors"]] == ["disabled"] * 4
    assert all(m["feedback_age_s"] is not None and m["feedback_age_s"] < 0.5
               for m in doc["motors"])
    labels = {i["label"]: i for i in doc["ids"]}
    est = labels["ODrive node 2 Get_Encoder_Estimates (front_right)"]
    assert est["direction"] == "rx" and est["rate_hz"] > 0.0
    assert "ODrive node 4 Heartbeat (rear_right)" in labels
    assert doc["load"]["nominal_percent"] > 0.0
    assert doc["errors"] == {"rejected by odrive": 0, "bus error frames": 0,
                             "receive errors": 0}


def test_bus_live_view_stops_on_ctrl_c_and_closes_the_bus(
        runner: CliRunner, channel: str, monkeypatch: pytest.MonkeyPatch) -> None:
    shown: list[str] = []

    def show_then_interrupt(self: object, snap: object) -> None:
        shown.append("shown")
        raise KeyboardInterrupt

    monkeypatch.setattr("gateway.cli.commands.monitor.Screen.show", show_then_interrupt)
    result = runner.invoke(main, ["--interface", "virtual", "--channel", channel, "monitor",
                                  "--bus", "--refresh", "50"])
    assert result.exit_code == 0, result.output
    assert shown == ["shown"]  # the leak check of conftest proves the bus was closed


# --------------------------------------------------------------------- daemon


def test_daemon_once_json(runner: CliRunner, daemon: Daemon, sock_path: str) -> None:
    config = str(CONFIG_DIR / "turtlebot3_burger.yaml")
    result = monitor(runner, "-c", config, "--socket", sock_path, "--once", "--json",
                     "--window", "0.3")
    assert result.exit_code == 0, result.output
    doc = json.loads(result.stdout)
    assert doc["source"] == f"daemon {sock_path}"
    assert doc["state"] == "running"
    assert [(m["name"], m["state"]) for m in doc["motors"]] == [("left", "enabled"),
                                                               ("right", "enabled")]
    assert doc["window_s"] >= 0.3
    labels = {(i["label"], i["direction"]): i for i in doc["ids"]}
    assert labels[("ODrive node 1 Set_Input_Vel (left)", "tx")]["rate_hz"] > 0.0
    assert labels[("ODrive node 2 Get_Encoder_Estimates (right)", "rx")]["rate_hz"] > 0.0
    assert doc["load"]["nominal_percent"] > 0.0
    assert doc["errors"]["rejected by odrive"] == 0
    assert doc["notes"] == []


def test_daemon_is_the_default_source(runner: CliRunner, daemon: Daemon, sock_path: str,
                                      monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("WHEELGATE_SOCKET", sock_path)
    result = monitor(runner, "--once", "--window", "0.2")
    assert result.exit_code == 0, result.output
    assert f"wheelgate monitor: daemon {sock_path}" in result.stdout
    assert "gateway running" in result.stdout
    # The embedded demo robot is not the daemon's: the monitor says so.
    assert "note: the daemon runs robot 'turtlebot3_burger'" in result.stdout


def test_no_daemon_names_the_socket_and_the_other_sources(
        runner: CliRunner, sock_path: str, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("WHEELGATE_SOCKET", sock_path)
    result = monitor(runner, "--once")
    assert result.exit_code == 1
    assert f"no gateway is listening on {sock_path}" in result.stderr
    assert "use --bus, or --log FILE" in result.stderr
    result = monitor(runner, "--socket", sock_path, "--once")
    assert result.exit_code == 1
    assert sock_path in result.stderr and "--bus" not in result.stderr


# --------------------------------------------------------------------- bad arguments


@pytest.mark.parametrize(("args", "message"), [
    (["--refresh", "0"], "Invalid value for '--refresh': expected a number above 0 and at "
                         "most 100 Hz, got 0.0"),
    (["--refresh", "nan"], "Invalid value for '--refresh'"),
    (["--window", "-1"], "Invalid value for '--window': expected a number above 0 and at "
                         "most 3600 s, got -1.0"),
    (["--json"], "--json needs --once"),
    (["--bus", "--log", "{log}"], "expected one source, got --bus and --log"),
    (["--socket", "x.sock", "--bus"], "expected one source, got --socket and --bus"),
    (["--fast", "--bus"], "--fast applies to --log only"),
    (["--log", "{missing}"], "Invalid value for '--log': File '{missing}' does not exist."),
])
def test_bad_arguments_exit_2(runner: CliRunner, log_file: Path, tmp_path: Path,
                              args: list[str], message: str) -> None:
    missing = str(tmp_path / "missing.log")
    args = [a.format(log=log_file, missing=missing) for a in args]
    result = monitor(runner, *args)
    assert result.exit_code == 2, result.output
    if "--json" in args:  # asked for JSON: the usage error is a JSON document on stdout too
        assert message in json.loads(result.stdout)["error"]["message"]
    else:
        assert message.format(missing=missing) in result.stderr


def test_bad_config_exits_2(runner: CliRunner, log_file: Path, tmp_path: Path) -> None:
    bad = tmp_path / "robot.yaml"
    bad.write_text("drive: nonsense\n")
    result = monitor(runner, "-c", str(bad), "--log", str(log_file), "--once")
    assert result.exit_code == 2
    assert str(bad) in result.stderr


# --------------------------------------------------------------------- on a terminal


@pytest.fixture
def swerve_log(tmp_path: Path) -> Path:
    """Eight seconds of the swerve robot (four drive motors, four steering actuators), with one
    unreadable line (an error count that is not zero: shown in colour)."""
    frames = Session(config_at("swerve.yaml")).run(8.0, [2.0, 2.0, 2.0, 2.0])
    lines = [f"({EPOCH + t:.6f}) can0 {f.to_cansend()} {'T' if d == 'tx' else 'R'}"
             for t, f, d in frames]
    lines.insert(BAD_LINE - 1, "(1700000000.1) can0 06D#00112233445566778899 R")
    path = tmp_path / "swerve.log"
    path.write_text("\n".join(lines) + "\n")
    return path


def live_monitor(log: Path, **env: str | None) -> Pty:
    """``wheelgate monitor`` replaying ``log`` at its own speed on an 80 x 24 terminal."""
    return Pty([sys.executable, "-m", "gateway", "monitor", "-c", str(CONFIG_DIR / "swerve.yaml"),
                "--log", str(log)], cols=80, rows=24, env={"TERM": "xterm", **env}, cleared=True)


@pytest.mark.timeout(30)
def test_live_screen_fits_80_by_24_pages_and_quits_on_q(swerve_log: Path,
                                                        runner: CliRunner) -> None:
    end = monitor(runner, "-c", str(CONFIG_DIR / "swerve.yaml"), "--log", str(swerve_log),
                  "--once", "--json")
    end_s = json.loads(end.stdout)["elapsed_s"]  # where the log ends, on its own clock
    term = live_monitor(swerve_log, NO_COLOR=None)
    try:
        screen = term.wait_for("the swerve robot", lambda s: "front_left" in s and "IDs" in s)
        frames = term.raw.decode().split(MONITOR_FRAME)[1:-1]  # the complete ones
        for frame in [*frames, term.raw_screen()]:
            lines = ANSI.sub("", frame).replace("\r", "").split("\n")
            assert len(lines) <= 24 and max(len(ln) for ln in lines) <= 80, frame
        assert "q: quit" in screen
        wheel = next(ln for ln in screen.splitlines() if ln.startswith("front_left"))
        assert wheel.split()[1:3] == ["1/5", "enabled"] and wheel.split()[5] == "+0.0"
        errors = term.raw_screen().split("\n")[-1]
        assert errors.startswith("errors: \x1b[33m")  # colour on a terminal
        assert errors.endswith("unreadable lines 1\x1b[0m")
        term.send(b" ")
        term.wait_for("the next page", lambda s: "page 2/" in s)
        term.send(b"q")
        assert term.wait_exit(10.0) == 0, term.text[-2000:]
        # q, not the end of the 8 s log (which draws its end, then quits by itself): the last
        # screen is short of the log's end on the log's own clock (no wall-clock bound)
        last = term.raw.decode("utf-8", "replace").rsplit(MONITOR_FRAME, 1)[-1]  # as left
        into = re.findall(r"([\d.]+) s into the log", ANSI.sub("", last))
        assert into and float(into[-1]) < end_s - 1.0, (into, end_s)
    finally:
        term.close()


@pytest.mark.timeout(30)
def test_no_color_is_honoured(swerve_log: Path) -> None:
    term = live_monitor(swerve_log, NO_COLOR="1")
    try:
        term.wait_for("the swerve robot", lambda s: "unreadable lines 1" in s)
        assert not re.search(r"\x1b\[[0-9;]*m", term.raw.decode())
        term.send(b"\x1b")  # Esc quits as q does (jog's too)
        assert term.wait_exit(5.0) == 0
    finally:
        term.close()
