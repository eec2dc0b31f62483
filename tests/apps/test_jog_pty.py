"""``wheelgate jog`` in a real pseudo-terminal: keys in, the redrawn screen out.

Each test starts the command as a child process on the slave side of a pty (its stdin is a
terminal, so it takes raw mode), writes keys to the master side and reads back the screen:
every frame starts with ``ESC [ H`` and ends with ``ESC [ J``, so the last complete frame is the
screen as the user sees it.  Every wait is bounded; the child is killed in ``finally``.
"""

from __future__ import annotations

import fcntl
import json
import os
import re
import select
import signal
import struct
import subprocess
import sys
import termios
import time
from typing import TYPE_CHECKING

import pytest

from gateway.cli import COMMANDS
from tests.conftest import CONFIG_DIR, REPO

if TYPE_CHECKING:
    from collections.abc import Callable, Iterator
    from pathlib import Path

#: ``python -m gateway jog`` once ``jog`` is registered in ``gateway.cli.COMMANDS``; until
#: then the command module is run on its own, with the same arguments.
JOG = ([sys.executable, "-m", "gateway", "jog"] if "jog" in COMMANDS else
       [sys.executable, "-c", "from gateway.cli.commands.jog import command; command()"])

CTRL_C = b"\x03"
ESC = b"\x1b"
_ANSI = re.compile(r"\x1b\[[0-9;?]*[A-Za-z]")
_ODOMETRY = re.compile(r"odometry: x=(\S+) m y=(\S+) m theta=\S+ rad\s+v=\((\S+), (\S+), (\S+)\)")

pytestmark = pytest.mark.timeout(20)


class Pty:
    """The command running on a pseudo-terminal of ``cols`` x ``rows``."""

    def __init__(self, args: list[str], cols: int = 140, rows: int = 50) -> None:
        master, slave = os.openpty()
        try:
            fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", rows, cols, 0, 0))
            self.proc = subprocess.Popen(
                [*JOG, *args], stdin=slave, stdout=slave, stderr=slave, cwd=REPO,
                start_new_session=True,
            )
        except BaseException:
            os.close(master)
            raise
        finally:
            os.close(slave)
        self.fd = master
        self.raw = b""
        self.eof = False

    def pump(self, timeout_s: float) -> None:
        """Read whatever the child wrote within ``timeout_s``."""
        if self.eof:
            time.sleep(timeout_s)
            return
        ready, _, _ = select.select([self.fd], [], [], timeout_s)
        if ready:
            try:
                chunk = os.read(self.fd, 65536)
            except OSError:  # EIO: every slave descriptor is closed, the child is gone
                chunk = b""
            self.raw += chunk
            self.eof = not chunk

    @property
    def text(self) -> str:
        """Everything written, escape codes removed."""
        return _ANSI.sub("", self.raw.decode("utf-8", "replace")).replace("\r", "")

    def screen(self) -> str:
        """The last complete frame."""
        text = self.raw.decode("utf-8", "replace")
        end = text.rfind("\x1b[J")
        start = text.rfind("\x1b[H", 0, end)
        if start < 0:
            return ""
        return _ANSI.sub("", text[start:end]).replace("\r", "")

    def wait_for(self, what: str, check: Callable[[str], bool], timeout_s: float = 8.0) -> str:
        """Pump until ``check(screen)`` holds; the screen then."""
        end = time.monotonic() + timeout_s
        while time.monotonic() < end:
            self.pump(0.05)
            if check(self.screen()):
                return self.screen()
        raise AssertionError(f"timed out waiting for {what}; screen:\n{self.screen()}\n"
                             f"output tail:\n{self.text[-2000:]}")

    def send(self, keys: bytes) -> None:
        os.write(self.fd, keys)

    def hold(self, key: bytes, seconds: float, every_s: float = 0.04) -> None:
        """Auto-repeat: ``key`` every ``every_s`` for ``seconds``, reading meanwhile."""
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.send(key)
            self.pump(every_s)

    def wait_exit(self, timeout_s: float = 10.0) -> int:
        end = time.monotonic() + timeout_s
        while self.proc.poll() is None and time.monotonic() < end:
            self.pump(0.05)
        code = self.proc.wait(timeout=max(0.1, end - time.monotonic()))
        while not self.eof:
            self.pump(0.05)
        return code

    def close(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait(timeout=5)
        os.close(self.fd)


@pytest.fixture
def spawn() -> Iterator[Callable[[list[str]], Pty]]:
    started: list[Pty] = []

    def start(args: list[str]) -> Pty:
        started.append(Pty(args))
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
        spawn: Callable[[list[str]], Pty], tmp_path: Path) -> None:
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
    assert "jog: Ctrl-C: stop sent to" in term.text
    last = sent(log)[-1]
    assert last["request"] == {"op": "stop"}
    assert last["reply"]["ok"] is True  # type: ignore[index]


def test_differential_refuses_holonomic_keys_and_esc_quits(
        spawn: Callable[[list[str]], Pty], tmp_path: Path) -> None:
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
    assert "jog: Esc: stop sent to" in term.text
    assert sent(log)[-1]["request"] == {"op": "stop"}


def test_hangup_sends_stop_and_restores(spawn: Callable[[list[str]], Pty],
                                        tmp_path: Path) -> None:
    log = tmp_path / "jog.jsonl"
    term = spawn(["--standalone", "-c", str(CONFIG_DIR / "turtlebot3_burger.yaml"), "--sim",
                  "--log", str(log)])
    term.wait_for("the daemon to run", running)
    term.hold(b"i", 0.3)
    term.wait_for("the move", lambda s: line(s, "command:").startswith("command: MOVING"))
    term.proc.send_signal(signal.SIGHUP)
    assert term.wait_exit() == 0, term.text[-2000:]
    assert "jog: SIGHUP: stop sent to" in term.text
    assert sent(log)[-1]["request"] == {"op": "stop"}
    assert sent(log)[0]["request"]["op"] == "twist"  # type: ignore[index]


def test_no_daemon_names_the_socket(spawn: Callable[[list[str]], Pty], tmp_path: Path) -> None:
    path = str(tmp_path / "none.sock")
    term = spawn(["--socket", path])
    assert term.wait_exit() == 1
    assert f"no gateway is listening on {path}" in term.text


def test_closed_terminal_sends_stop(spawn: Callable[[list[str]], Pty], tmp_path: Path) -> None:
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
