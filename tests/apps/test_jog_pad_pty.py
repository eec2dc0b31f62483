"""``wheelgate jog --joystick`` in a real pseudo-terminal, the pad played by a FIFO that
carries joydev events as the kernel writes them: what reaches the simulated wheels while the
enable button is held, the stop when it is let go, a button held at open, a pad that goes."""

from __future__ import annotations

import os
import struct
from typing import TYPE_CHECKING

import pytest

from gateway.apps.jog.pad import AXIS, BUTTON, INIT
from tests.apps.test_jog_pty import CTRL_C, line, odometry, running, sent, spawn
from tests.conftest import CONFIG_DIR

if TYPE_CHECKING:
    from collections.abc import Iterator
    from pathlib import Path

    from tests.apps.test_jog_pty import Spawn

__all__ = ["spawn"]  # (the fixture, used by name)

pytestmark = pytest.mark.timeout(30)


class FakePad:
    """A FIFO standing for ``/dev/input/js0``: held open for writing, so the reader sees no end
    of file until :meth:`unplug`."""

    def __init__(self, path: Path, held: bool = False) -> None:
        os.mkfifo(path)
        self.path = path
        self.fd: int | None = os.open(path, os.O_RDWR | os.O_NONBLOCK)
        # What joydev sends at open: every button and axis, flagged INIT (an Xbox pad: 11
        # buttons, 8 axes).
        self.write(*(event(1 if held and n == 4 else 0, BUTTON | INIT, n) for n in range(11)),
                   *(event(0, AXIS | INIT, n) for n in range(8)))

    def write(self, *events: bytes) -> None:
        assert self.fd is not None
        os.write(self.fd, b"".join(events))

    def unplug(self) -> None:
        if self.fd is not None:
            os.close(self.fd)
            self.fd = None


def event(value: int, kind: int, number: int) -> bytes:
    return struct.pack("=IhBB", 0, value, kind, number)


@pytest.fixture
def pad(tmp_path: Path) -> Iterator[FakePad]:
    fake = FakePad(tmp_path / "js0")
    yield fake
    fake.unplug()


def test_the_pad_drives_only_while_enable_is_held(
        spawn: Spawn, pad: FakePad, tmp_path: Path) -> None:
    log = tmp_path / "jog.jsonl"
    term = spawn(["--standalone", "-c", str(CONFIG_DIR / "mecanum.yaml"), "--sim",
                  "--log", str(log), "--joystick", str(pad.path)])
    screen = term.wait_for("the daemon to run", running)
    assert f"joystick: {pad.path} idle; hold button 4; axis 1 vx, axis 0 vy, axis 3 wz" in screen
    x0 = odometry(screen)[0]

    pad.write(event(-32767, AXIS, 1))  # stick full up, enable not held: nothing moves
    term.pump(0.5)
    assert line(term.screen(), "command:") == "command: STOPPED"
    assert not log.exists() or sent(log) == []

    pad.write(event(1, BUTTON, 4))
    screen = term.wait_for("the pad to drive", lambda s: "DRIVING" in s)
    assert line(screen, "command:").startswith(
        "command: MOVING joystick  vx=+0.500 m/s vy=+0.000 m/s wz=+0.000 rad/s")
    screen = term.wait_for("the wheels to move the robot",
                           lambda s: running(s) and odometry(s)[0] > x0 + 0.1)
    pad.write(event(-16384, AXIS, 0))  # half left, on a mecanum base: sideways too
    screen = term.wait_for("sideways", lambda s: odometry(s)[3] > 0.1)

    pad.write(event(0, BUTTON, 4))  # let go: stop at once
    screen = term.wait_for("the stop", lambda s: line(s, "command:") == "command: STOPPED")
    assert "joystick: enable button released: sent stop" in line(screen, "message:")
    term.wait_for("the robot to stop", lambda s: running(s) and all(
        abs(v) < 1e-3 for v in odometry(s)[2:]))
    assert sent(log)[-1]["request"] == {"op": "stop"}
    twists = [e for e in sent(log) if e["request"]["op"] == "twist"]  # type: ignore[index]
    assert len(twists) >= 5  # re-sent while held

    pad.unplug()  # (a FIFO's end of file; a real pad reads ENODEV)
    screen = term.wait_for("the loss", lambda s: "joystick: LOST" in s)
    assert "end of file (unplugged?)" in screen
    term.send(CTRL_C)
    assert term.wait_exit() == 0, term.text[-2000:]


def test_a_pad_lost_while_driving_stops_the_robot(
        spawn: Spawn, pad: FakePad, tmp_path: Path) -> None:
    log = tmp_path / "jog.jsonl"
    term = spawn(["--standalone", "-c", str(CONFIG_DIR / "turtlebot3_burger.yaml"), "--sim",
                  "--log", str(log), "--joystick", str(pad.path)])
    term.wait_for("the daemon to run", running)
    pad.write(event(1, BUTTON, 4), event(-32767, AXIS, 3))  # turn left in place
    screen = term.wait_for("the turn", lambda s: running(s) and odometry(s)[4] > 0.3)
    assert "wz=+" in line(screen, "command:")
    pad.unplug()
    screen = term.wait_for("the stop", lambda s: line(s, "command:") == "command: STOPPED")
    assert line(screen, "message:") == (
        f"message: joystick: lost: {pad.path}: end of file (unplugged?): sent stop")
    assert sent(log)[-1]["request"] == {"op": "stop"}
    term.send(CTRL_C)
    assert term.wait_exit() == 0, term.text[-2000:]


def test_a_button_held_when_the_pad_is_opened_does_not_drive(
        spawn: Spawn, tmp_path: Path) -> None:
    held = FakePad(tmp_path / "js0", held=True)
    try:
        log = tmp_path / "jog.jsonl"
        term = spawn(["--standalone", "-c", str(CONFIG_DIR / "mecanum.yaml"), "--sim",
                      "--log", str(log), "--joystick", str(held.path)])
        screen = term.wait_for("the daemon to run", running)
        held.write(event(-32767, AXIS, 1))
        term.pump(0.5)
        screen = term.screen()
        assert "enable held since before it was opened: release and press it" in screen
        assert line(screen, "command:") == "command: STOPPED"
        held.write(event(0, BUTTON, 4), event(1, BUTTON, 4))
        term.wait_for("the pad to drive", lambda s: "DRIVING" in s)
        term.send(CTRL_C)
        assert term.wait_exit() == 0, term.text[-2000:]
        assert sent(log)[-1]["request"] == {"op": "stop"}
    finally:
        held.unplug()


def test_a_joystick_that_is_not_there_is_a_usage_error(spawn: Spawn, tmp_path: Path) -> None:
    term = spawn(["--standalone", "--sim", "--joystick", str(tmp_path / "js9")])
    assert term.wait_exit() == 2
    assert " ".join(term.text.split()) == (
        f"Error: --joystick: cannot open {tmp_path / 'js9'}: No such file or directory; is the "
        "pad connected? (ls /dev/input/js*)")
