"""The jog screen (:mod:`gateway.apps.jog.screen`): the daemon's replies, and the screen drawn
to the terminal's size -- the swerve robot on 80 x 24, colour, no floating-point noise."""

from __future__ import annotations

import dataclasses
import re
from typing import TYPE_CHECKING

from gateway.apps.jog.keys import JogLimits, JogState, jog_limits
from gateway.apps.jog.screen import Screen, read_status, render, reply_error
from gateway.apps.layout import steering_of
from gateway.config import load_config
from gateway.core.kinematics.odometry import OdometryState, Pose
from gateway.core.status import CommandReport, MotorReport
from gateway.core.types import DriveFault, DriveState, Twist
from gateway.wire.socket.status import status_to_json
from tests.conftest import CONFIG_DIR
from tests.wire.status_samples import sample_status

if TYPE_CHECKING:
    from gateway.core.status import GatewayStatus

HOLO = JogLimits(2.0, 4.0, "motor max_rpm", "motor max_rpm", holonomic=True, drive="mecanum")
STATUS = sample_status(
    robot="turtlebot3_burger",
    command=CommandReport(Twist(0.25, 0.0, 0.5), Twist(0.25, 0.0, 0.5), False, 0.5, 1.0),
    odometry=OdometryState(Pose(1.5, -0.25, 0.125), Twist(0.25, 0.0, 0.5), 0.0, 1.0, 3.0),
)
SWERVE = load_config(CONFIG_DIR / "swerve.yaml")
#: The swerve robot's steering angles (rad) in the status, and how the screen writes them.
ANGLES = {"front_left": (0.7853981633974483, "+45.0 deg"), "front_right": (0.3217505, "+18.4 deg"),
          "rear_left": (-0.7853981633974483, "-45.0 deg"), "rear_right": (-0.3217505, "-18.4 deg")}
_SGR = re.compile(r"\x1b\[[0-9;]*m")


def swerve_status(fault: bool = False) -> GatewayStatus:
    """The swerve robot running: four drive motors (one faulted if ``fault``), then four
    steering actuators at :data:`ANGLES`."""
    drives = [MotorReport(m.wheel, m.node_id, DriveState.ENABLED, DriveFault.NONE, "", 0.004,
                          3.0, 12.0) for m in SWERVE.motors if m is not None]
    if fault:
        drives[1] = MotorReport("front_right", 2, DriveState.FAULT, DriveFault.OVER_CURRENT,
                                "x", None, None, None)
    steers = [MotorReport(a.wheel, a.node_id, DriveState.ENABLED, DriveFault.NONE, "", 0.005,
                          ANGLES[a.steers[0]][0], 0.0) for a in SWERVE.steering]
    return sample_status(robot="swerve", motors=(*drives, *steers))


def swerve_screen(fault: bool = False) -> Screen:
    state = JogState.start(jog_limits(SWERVE)).on_key("u", 0.0).state
    return Screen("swerve", "swerve (swerve)", "connected: /run/wheelgate/wheelgate.sock", state,
                  swerve_status(fault), "", ("WARNING gateway: a", "INFO gateway: b"),
                  steering=steering_of(SWERVE))


def row(lines: list[str], wheel: str) -> str:
    found = [ln for ln in lines if ln.startswith(f"  {wheel} ")]
    assert len(found) == 1, (wheel, lines)
    return found[0]


# --------------------------------------------------------------------- daemon replies


def test_the_status_is_read_from_its_reply() -> None:
    assert read_status({"ok": True, "id": 4, **status_to_json(STATUS)}) == (STATUS, "")
    reply = {"ok": True, "id": 4, **status_to_json(STATUS), "motors": [{"name": "left"}]}
    assert read_status(reply) == (
        None, "status: status.motors[0].node_id: expected an integer, got nothing")


def test_reply_error() -> None:
    assert reply_error({"ok": True}) == ""
    assert reply_error({"ok": False, "error": {"code": "infeasible_twist",
                                               "message": "wheel 'left' slides"}}) == \
        "wheel 'left' slides"
    assert reply_error({"ok": False, "error": {"code": "estop"}}) == "estop"
    assert "without a message" in reply_error({"ok": False})


# --------------------------------------------------------------------- the screen


def test_render_moving_with_status() -> None:
    lim = jog_limits(load_config(CONFIG_DIR / "turtlebot3_burger.yaml"))
    state = JogState.start(lim).on_key("u", 0.0).state
    lines = render(Screen("turtlebot3_burger", "burger (differential)", "connected: /s", state,
                          STATUS,
                          "Twist is infeasible: " + "x" * 150, ("WARNING a: b",)), width=80)
    text = "\n".join(lines)
    assert all(len(ln) <= 80 for ln in lines)
    assert lines[0] == "wheelgate jog: burger (differential)   connected: /s"
    assert "holonomic (shift) keys: not on this differential drive; they stop" in lines
    assert "quit: Ctrl-C, Ctrl-D or Esc" in text
    assert "command: MOVING 'u'  vx=+0.211 m/s vy=+0.000 m/s wz=+1.000 rad/s" in text
    assert "(limits scale it to 72%)" in render(Screen("t", "t", "c", state), width=200)[10]
    assert "speeds:  linear 0.211 m/s (max 0.211, motor max_rpm)" in lines
    assert "         angular 1.000 rad/s (max 2.64, motor max_rpm)" in lines  # two lines at 80
    error = [ln for ln in lines if ln.startswith(("last error:", "    x"))]
    assert len(error) == 3  # wrapped, at most 3 lines
    assert "daemon: state running   applied vx=+0.250 m/s" in text
    assert "odometry: x=+1.500 m y=-0.250 m theta=+0.125 rad   v=(+0.250, +0.000, +0.500)" \
        in text
    assert lines[-4] == "  wheel        state            speed   feedback  faults"
    assert lines[-3] == "  left         enabled    +6.00 rad/s     2.0 ms  no faults"
    assert lines[-2] == ("  right        fault                -          -  over_temperature, "
                         "encoder")
    assert lines[-1] == "log: WARNING a: b"
    assert not any(ln.startswith("warning:") for ln in lines)


def test_render_warns_when_the_daemon_drives_another_robot() -> None:
    screen = Screen("default", "default (mecanum)", "connected: /s", JogState.start(HOLO),
                    STATUS)
    assert ("warning: the daemon drives 'turtlebot3_burger', but the key limits are those of "
            "'default' (pass its configuration with -c)") in render(screen, width=200)
    # The same robot from another text: the note of jog -c (refuse_other_robot's warning).
    note = "warning: the daemon runs /r.yaml as it was when the daemon started; ..."
    same = dataclasses.replace(screen, robot="turtlebot3_burger", note=note)
    assert note in render(same, width=200)
    assert not any(ln.startswith("warning:") for ln in render(
        dataclasses.replace(same, note=""), width=200))


def test_render_stopped_without_status() -> None:
    lines = render(Screen("m", "m", "DISCONNECTED: gone (retrying)", JogState.start(HOLO)))
    assert "command: STOPPED" in lines
    assert "daemon: no status yet" in lines
    assert "last error: -" in lines
    assert not any("not on this" in ln for ln in lines)


def test_swerve_fits_80_by_24_with_its_steering_angles() -> None:
    lines = render(swerve_screen(), width=79, height=24)  # the terminal's width less one
    assert len(lines) <= 24 and max(len(ln) for ln in lines) <= 79, "\n".join(lines)
    # One line per wheel: its speed and its steering actuator's angle.
    assert "  wheel        state            speed       steer   feedback  faults" in lines
    for wheel, (_, angle) in ANGLES.items():
        assert row(lines, wheel).split()[1:5] == ["enabled", "+12.00", "rad/s", angle[:-4]]
    assert not any("steering" in ln for ln in lines)  # merged into their wheels' rows
    assert row(lines, "front_left").endswith("  5.0 ms  no faults")  # the older feedback
    assert "quit: Ctrl-C, Ctrl-D or Esc" in "\n".join(lines)
    assert "log: WARNING gateway: a" in lines


def test_swerve_on_a_tall_terminal_has_a_row_per_motor() -> None:
    lines = render(swerve_screen(), width=119, height=60)
    at = lines.index(row(lines, "front_left"))
    assert lines[at + 1].split() == ["steering", "enabled", "+45.0", "deg", "5.0", "ms",
                                     "no", "faults"]
    assert len(lines) == 26  # nothing gave way


def test_short_terminals_give_way_but_keep_the_width_and_the_height() -> None:
    screen = swerve_screen(fault=True)
    for width, height in ((79, 16), (59, 12), (40, 6), (20, 1)):
        lines = render(screen, width, height)
        assert len(lines) <= height and max(len(ln) for ln in lines) <= width, (width, height)
    lines = render(screen, 79, 16)
    assert lines[1].startswith("move: u i o / j k l / m , .")  # the keys in three lines
    assert row(lines, "front_right").endswith("over_current")
    lines = render(screen, 79, 14)
    assert lines[1].startswith("keys: uio/jkl/m,. move")  # in one line
    assert lines[-1] == row(lines, "rear_right")  # every wheel, without the table's header
    lines = render(screen, 79, 12)
    assert lines[-3:-1] == [row(lines, "front_left"), row(lines, "front_right")]
    assert lines[-1] == "  ... 2 more (a taller terminal shows them)"


def test_faults_errors_and_warnings_in_colour() -> None:
    screen = swerve_screen(fault=True)
    plain = render(screen, 79, 24)
    assert not any("\x1b" in ln for ln in plain)
    lines = render(screen, 79, 24, colour=True)
    assert [_SGR.sub("", ln) for ln in lines] == plain  # only colour is added
    fault = row(lines, "front_right")
    assert fault.startswith("  front_right  \x1b[31mfault") and fault.endswith("\x1b[0m")
    assert "log: \x1b[33mWARNING gateway: a\x1b[0m" in lines
    assert "log: INFO gateway: b" in lines
    down = Screen("s", "s", "DISCONNECTED: refused (retrying)", screen.jog, None,
                  "warning: projected", connected=False)
    lines = render(down, 79, 24, colour=True)
    assert lines[0] == "wheelgate jog: s   \x1b[31mDISCONNECTED: refused (retrying)\x1b[0m"
    assert "last error: \x1b[33mwarning: projected\x1b[0m" in lines


def test_no_floating_point_noise() -> None:
    tiny = -2.7755575615628914e-17
    status = sample_status(
        command=CommandReport(Twist(0.5, tiny, 0.0), Twist(0.5, tiny, -1e-17), False, 1.0, 1.0),
        odometry=OdometryState(Pose(0.3126, -0.0001, tiny), Twist(0.5, tiny, -0.0004), 0.0, 1.0,
                               1.0))
    text = "\n".join(render(Screen("tb3", "t", "c", JogState.start(HOLO), status), 200))
    assert "applied vx=+0.500 m/s vy=+0.000 m/s wz=+0.000 rad/s" in text
    assert "odometry: x=+0.313 m y=+0.000 m theta=+0.000 rad   v=(+0.500, +0.000, +0.000)" \
        in text
    assert not re.search(r"-0(?:\.0+)?(?![\d.])|\de[-+]?\d", text), text
