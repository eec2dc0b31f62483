"""``wheelgate jog`` in a real pseudo-terminal: keys in, the redrawn screen out.

Each test starts the command as a child process on the slave side of a pty
(:class:`tests.pty_helpers.Pty`: its stdin is a terminal, so it takes raw mode), writes keys to
the master side and reads back the screen: every frame starts with ``ESC [ H`` and ends with
``ESC [ J``, so the last complete frame is the screen as the user sees it.  Every wait is
bounded; the child is killed at the end of the test.
"""

from __future__ import annotations

import json
import math
import os
import re
import signal
import sys
from typing import TYPE_CHECKING, Protocol

import pytest

from gateway.cli import COMMANDS
from gateway.config import load_config
from gateway.core.types import Twist
from tests.conftest import CONFIG_DIR
from tests.pty_helpers import ANSI, Pty

if TYPE_CHECKING:
    from collections.abc import Iterator
    from pathlib import Path

    from gateway.runtime.daemon import Daemon

#: ``python -m gateway jog`` once ``jog`` is registered in ``gateway.cli.COMMANDS``; until
#: then the command module is run on its own, with the same arguments.
JOG = ([sys.executable, "-m", "gateway", "jog"] if "jog" in COMMANDS else
       [sys.executable, "-c", "from gateway.cli.commands.jog import command; command()"])

CTRL_C = b"\x03"
ESC = b"\x1b"
_ODOMETRY = re.compile(r"odometry: x=(\S+) m y=(\S+) m theta=\S+ rad\s+v=\((\S+), (\S+), (\S+)\)")

pytestmark = pytest.mark.timeout(20)


class Spawn(Protocol):
    def __call__(self, args: list[str], cols: int = ..., rows: int = ...,
                 env: dict[str, str | None] | None = ...) -> Pty: ...


@pytest.fixture
def spawn() -> Iterator[Spawn]:
    """``jog`` with these arguments on a pty (140 x 50 unless told)."""
    started: list[Pty] = []

    def start(args: list[str], cols: int = 140, rows: int = 50,
              env: dict[str, str | None] | None = None) -> Pty:
        started.append(Pty([*JOG, *args], cols, rows, env))
        return started[-1]

    yield start
    for p in started:
        p.close()


def odometry(screen: str) -> tuple[float, ...]:
    """x, y, vx, vy, wz from the screen's odometry line."""
    match = _ODOMETRY.search(screen)
    assert match, f"no odometry line on the screen:\n{screen}"
    return tuple(float(v) for v in match.groups())


def line(screen: str, prefix: str) -> str:
    found = [ln for ln in screen.splitlines() if ln.startswith(prefix)]
    assert found, f"no {prefix!r} line on the screen:\n{screen}"
    return found[0]


def sent(log: Path) -> list[dict[str, object]]:
    return [json.loads(ln) for ln in log.read_text().splitlines()]


def running(screen: str) -> bool:
    return "daemon: state running" in screen


def test_mecanum_moves_deadman_stops_holonomic_and_ctrl_c(
        spawn: Spawn, tmp_path: Path) -> None:
    log = tmp_path / "jog.jsonl"
    term = spawn(["--standalone", "-c", str(CONFIG_DIR / "mecanum.yaml"), "--sim",
                  "--log", str(log)])
    screen = term.wait_for("the daemon to run", running)
    assert "quit: Ctrl-C, Ctrl-D or Esc" in screen
    assert line(screen, "command:") == "command: STOPPED"
    x0 = odometry(screen)[0]

    term.hold(b"i", 1.0)
    screen = term.screen()
    assert line(screen, "command:").startswith(
        "command: MOVING 'i'  vx=+0.500 m/s vy=+0.000 m/s wz=+0.000 rad/s")
    assert odometry(screen)[0] > x0 + 0.05, screen

    # No key: the deadman sends stop and the robot comes to rest.
    screen = term.wait_for("the deadman", lambda s: "deadman: no key for 0.6 s" in s)
    assert line(screen, "command:") == "command: STOPPED"
    screen = term.wait_for("the robot to stop", lambda s: running(s) and all(
        abs(v) < 1e-3 for v in odometry(s)[2:]))
    x1, y1, *_ = odometry(screen)
    assert x1 > x0 + 0.1
    twists = [e for e in sent(log) if e["request"]["op"] == "twist"]  # type: ignore[index]
    assert len(twists) >= 5  # the held key was re-sent
    assert sent(log)[-1]["request"] == {"op": "stop"}

    # A holonomic key on a mecanum base moves it sideways.
    term.hold(b"J", 1.0)
    screen = term.screen()
    assert line(screen, "command:").startswith(
        "command: MOVING 'J'  vx=+0.000 m/s vy=+0.500 m/s wz=+0.000 rad/s")
    assert odometry(screen)[1] > y1 + 0.05, screen
    term.wait_for("the deadman", lambda s: line(s, "command:") == "command: STOPPED")

    term.send(b"q")
    term.wait_for("the speed step", lambda s: "linear 0.550 m/s" in line(s, "speeds:"))

    term.hold(b"i", 0.3)
    term.send(CTRL_C)
    assert term.wait_exit() == 0, term.text[-2000:]
    assert "\njog: Ctrl-C: stop sent to" in term.text  # on a line of its own
    last = sent(log)[-1]
    assert last["request"] == {"op": "stop"}
    assert last["reply"]["ok"] is True  # type: ignore[index]


def test_differential_refuses_holonomic_keys_and_esc_quits(
        spawn: Spawn, tmp_path: Path) -> None:
    log = tmp_path / "jog.jsonl"
    term = spawn(["--standalone", "-c", str(CONFIG_DIR / "turtlebot3_burger.yaml"), "--sim",
                  "--log", str(log)])
    screen = term.wait_for("the daemon to run", running)
    # teleop_twist_keyboard's 0.5 m/s is more than the burger's 61 rpm wheels allow.
    assert "linear speed 0.5 m/s clamped to 0.211 m/s by motor max_rpm" in screen
    assert "linear 0.211 m/s (max 0.211, motor max_rpm)" in line(screen, "speeds:")
    term.send(b"J")
    screen = term.wait_for("the refusal", lambda s: "holonomic (sideways) key" in s)
    assert "this differential drive cannot follow vy; sent stop" in line(screen, "message:")
    assert line(screen, "command:") == "command: STOPPED"
    assert [e["request"] for e in sent(log)] == [{"op": "stop"}]
    term.send(ESC)
    assert term.wait_exit() == 0, term.text[-2000:]
    assert "\njog: Esc: stop sent to" in term.text  # on a line of its own
    assert sent(log)[-1]["request"] == {"op": "stop"}


def test_hangup_sends_stop_and_restores(spawn: Spawn,
                                        tmp_path: Path) -> None:
    log = tmp_path / "jog.jsonl"
    term = spawn(["--standalone", "-c", str(CONFIG_DIR / "turtlebot3_burger.yaml"), "--sim",
                  "--log", str(log)])
    term.wait_for("the daemon to run", running)
    term.hold(b"i", 0.3)
    term.wait_for("the move", lambda s: line(s, "command:").startswith("command: MOVING"))
    term.proc.send_signal(signal.SIGHUP)
    assert term.wait_exit() == 0, term.text[-2000:]
    assert "\njog: SIGHUP: stop sent to" in term.text  # on a line of its own
    assert sent(log)[-1]["request"] == {"op": "stop"}
    assert sent(log)[0]["request"]["op"] == "twist"  # type: ignore[index]


def test_no_daemon_names_the_socket(spawn: Spawn, tmp_path: Path) -> None:
    path = str(tmp_path / "none.sock")
    term = spawn(["--socket", path])
    assert term.wait_exit() == 1
    assert f"no gateway is listening on {path}" in term.text


def test_closed_terminal_sends_stop(spawn: Spawn, tmp_path: Path) -> None:
    log = tmp_path / "jog.jsonl"
    term = spawn(["--standalone", "-c", str(CONFIG_DIR / "turtlebot3_burger.yaml"), "--sim",
                  "--log", str(log)])
    term.wait_for("the daemon to run", running)
    term.hold(b"i", 0.3)
    term.wait_for("the move", lambda s: line(s, "command:").startswith("command: MOVING"))
    os.close(term.fd)  # the terminal window closes
    term.fd = os.open(os.devnull, os.O_RDONLY)  # for close()
    term.eof = True
    assert term.proc.wait(timeout=10) == 0
    assert sent(log)[-1]["request"] == {"op": "stop"}
    assert sent(log)[-1]["reply"]["ok"] is True  # type: ignore[index]


def test_swerve_fits_80_by_24_with_its_steering_angles_and_speed(
        spawn: Spawn, tmp_path: Path) -> None:
    swerve = load_config(CONFIG_DIR / "swerve.yaml")
    term = spawn(["--standalone", "-c", str(CONFIG_DIR / "swerve.yaml"), "--sim",
                  "--speed", "0.25"], cols=80, rows=24)
    screen = term.wait_for("the daemon to run", running)
    assert line(screen, "speeds:").startswith("speeds:  linear 0.250 m/s (max 4.65")
    term.hold(b"u", 1.2)
    screen = term.screen()
    assert line(screen, "command:").startswith(
        "command: MOVING 'u'  vx=+0.250 m/s vy=+0.000 m/s wz=+1.000 rad/s")
    wanted = swerve.model.ik(Twist(0.25, 0.0, 1.0)).steer_rad
    for wheel, angle in zip(swerve.model.names, wanted, strict=True):
        assert angle is not None
        row = line(screen, f"  {wheel} ")  # one line per wheel, its angle beside its speed
        shown = float(row.split("rad/s")[1].split("deg")[0])
        # The actuator may turn the wheel the other way round and drive it backwards.
        assert abs((shown - math.degrees(angle) + 90.0) % 180.0 - 90.0) < 0.5, row
    frames = re.findall(r"\x1b\[H(.*?)\x1b\[J", term.raw.decode("utf-8", "replace"), re.S)
    assert len(frames) > 5
    for frame in frames:
        lines = ANSI.sub("", frame).replace("\r", "").split("\n")
        assert len(lines) <= 24 and max(len(ln) for ln in lines) <= 79, frame
    term.send(CTRL_C)
    assert term.wait_exit() == 0, term.text[-2000:]


@pytest.mark.parametrize("no_color", [None, "1"])
def test_errors_in_colour_unless_no_color(spawn: Spawn, no_color: str | None) -> None:
    term = spawn(["--standalone", "-c", str(CONFIG_DIR / "ackermann.yaml"), "--sim"],
                 cols=80, rows=24, env={"NO_COLOR": no_color, "TERM": "xterm"})
    term.wait_for("the daemon to run", running)
    term.send(b"j")  # a turn in place: the daemon refuses it
    term.wait_for("the refusal", lambda s: "is infeasible" in line(s, "last error:"))
    coloured = [ln for ln in term.raw_screen().split("\r\n") if "\x1b[31m" in ln]
    if no_color is None:
        assert coloured and coloured[0].startswith("last error: \x1b[31mTwist (vx=0 m/s")
    else:
        assert not re.search(r"\x1b\[[0-9;]*m", term.raw.decode("utf-8", "replace"))
    term.send(ESC)
    assert term.wait_exit() == 0, term.text[-2000:]


def test_without_c_the_keys_take_the_daemons_own_robot(
        spawn: Spawn, daemon: Daemon, sock_path: str) -> None:
    """The daemon runs the TurtleBot (its file readable here, unchanged): jog without -c takes
    that file's limits, not the embedded demo's, and checks --speed against them."""
    too_fast = spawn(["--socket", sock_path, "--speed", "0.3"])  # the demo's keys allow it
    assert too_fast.wait_exit() == 2, too_fast.text[-2000:]
    assert "at most 0.21 m/s (motor max_rpm), got 0.3 (robot 'turtlebot3_burger')" in \
        too_fast.text.replace("\r\n", " ").replace("\n", " ")
    term = spawn(["--socket", sock_path])
    screen = term.wait_for("the daemon's robot", running)
    assert "turtlebot3_burger (differential)" in screen
    assert "linear 0.211 m/s (max 0.211, motor max_rpm)" in line(screen, "speeds:")
    assert "warning:" not in screen
    term.send(ESC)
    assert term.wait_exit() == 0, term.text[-2000:]
