"""The jog screen, pure: :func:`render` turns a :class:`Screen` -- the session of
:mod:`gateway.apps.jog.keys` and the daemon's last status (:class:`gateway.core.status.
GatewayStatus`, which :func:`read_status` takes from a reply) -- into lines of text.  The
terminal itself is handled by :mod:`gateway.cli.commands.jog`.  No I/O, no clock.

The screen fits the terminal (:mod:`gateway.apps.layout`): on a short one the motors condense
to one line per wheel (its speed and its steering actuator's angle), the key help to three
lines then one, the messages and the log to a line each; no line is wider than the terminal.
Faults and errors are red, warnings yellow, when the caller asks for colour.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from gateway.apps.jog.keys import key_name
from gateway.apps.layout import Level, Line, fit, pack, paint, pair_steering, wrap
from gateway.core.numfmt import fixed
from gateway.core.status import fault_names, state_name
from gateway.core.types import DriveFault, DriveState, GatewayState
from gateway.wire.socket import ProtocolError
from gateway.wire.socket.status import status_from_json

if TYPE_CHECKING:
    from collections.abc import Sequence

    from gateway.apps.jog.keys import JogState
    from gateway.core.status import GatewayStatus, MotorReport
    from gateway.core.types import Twist


#: The keys on the screen, in full: at most 79 columns, as on an 80-column terminal.
HELP = (
    "Moving around:        Holonomic (shift):      Speeds, +/-10 %:",
    "   u    i    o           U    I    O             q/z  both",
    "   j    k    l           J    K    L             w/x  linear only",
    "   m    ,    .           M    <    >             e/c  angular only",
    "k, space, any other key: stop      t/b (z): not applicable, stop",
    "quit: Ctrl-C, Ctrl-D or Esc; quitting sends stop (q is a speed key)",
)
#: The line added to :data:`HELP` for a drive that cannot follow vy.
HELP_NOT_HOLONOMIC = "holonomic (shift) keys: not on this {drive} drive; they stop"
#: The keys in three lines, for a short terminal (``{deadman}``: the deadman time, s).
HELP_COMPACT = (
    "move: u i o / j k l / m , .   sideways (shift): U I O / J K L / M < >",
    "stop: k, space, other keys   +/-10 %: q/z both speeds, w/x linear, e/c angular",
    "quit: Ctrl-C, Ctrl-D or Esc (sends stop)   deadman: {deadman:g} s without a key, stop",
)
#: The first line of :data:`HELP_COMPACT` for a drive that cannot follow vy.
HELP_COMPACT_NOT_HOLONOMIC = (
    "move: u i o / j k l / m , .   (shift keys, sideways: not on this drive)")
#: The keys in one line, for a very short terminal.
HELP_LINE = "keys: uio/jkl/m,. move, shift sideways  k stop  q/z w/x e/c speeds  Ctrl-C quit"


# --------------------------------------------------------------------- what the daemon says


def read_status(reply: Mapping[str, Any]) -> tuple[GatewayStatus | None, str]:
    """The status in an ``ok`` reply to ``status``, or ``None`` and why it cannot be read (a
    daemon that speaks another status)."""
    try:
        return status_from_json(reply), ""
    except ProtocolError as err:
        return None, f"status: {err}"


def reply_error(reply: Mapping[str, Any]) -> str:
    """The message of an error reply, ``""`` for an ``ok`` one."""
    if reply.get("ok"):
        return ""
    error = reply.get("error")
    if isinstance(error, Mapping):
        return str(error.get("message") or error.get("code") or error)
    return f"error reply without a message: {dict(reply)}"


# --------------------------------------------------------------------- the screen


@dataclass(frozen=True, slots=True)
class Screen:
    """Everything on the screen.

    :param robot: the name of the robot whose limits the keys use.
    :param title: robot and drive.
    :param connection: where the daemon is and whether it answers.
    :param jog: the session.
    :param daemon: its last status, ``None`` before the first.
    :param last_error: the daemon's last refusal of a request (or a connection error).
    :param log: the last log lines of this process.
    :param connected: whether the daemon answers (``connection`` is shown as an error if not).
    :param steering: per steering actuator (its status name), the wheels it turns
        (:func:`gateway.apps.layout.steering_of` of the configuration).
    :param note: a warning about the daemon's configuration (the same robot from an edited
        file, :func:`gateway.cli.commands._common.other_text`), ``""``: none.
    :param pad: the gamepad's line (:meth:`gateway.apps.jog.joystick.Joystick.describe`),
        ``""``: no gamepad.
    :param pad_ok: whether the gamepad is read (its line is an error if not).
    """

    robot: str
    title: str
    connection: str
    jog: JogState
    daemon: GatewayStatus | None = None
    last_error: str = ""
    log: tuple[str, ...] = ()
    connected: bool = True
    steering: Mapping[str, tuple[str, ...]] = field(default_factory=dict)
    note: str = ""
    pad: str = ""
    pad_ok: bool = True


def _twist(t: Twist) -> str:
    return (f"vx={fixed(t.vx_m_s, 3, sign=True)} m/s vy={fixed(t.vy_m_s, 3, sign=True)} m/s "
            f"wz={fixed(t.wz_rad_s, 3, sign=True)} rad/s")


def _help(screen: Screen) -> list[list[Line]]:
    """The key help, full, in three lines and in one."""
    lim = screen.jog.limits
    full = [*HELP, *([] if lim.holonomic else [HELP_NOT_HOLONOMIC.format(drive=lim.drive)]),
            f"deadman: a move lasts while its key repeats; {screen.jog.deadman_s:g} s without "
            "it sends stop"]
    compact = [HELP_COMPACT[0] if lim.holonomic else HELP_COMPACT_NOT_HOLONOMIC,
               HELP_COMPACT[1], HELP_COMPACT[2].format(deadman=screen.jog.deadman_s)]
    return [[Line(t) for t in full], [Line(t) for t in compact], [Line(HELP_LINE)]]


# --------------------------------------------------------------------- motors


def _level(*motors: MotorReport) -> Level:
    if any(m.faults != DriveFault.NONE or m.state is DriveState.FAULT for m in motors):
        return Level.ERROR
    if any(m.state is DriveState.OFFLINE for m in motors):
        return Level.WARNING
    return Level.PLAIN


def _faults(m: MotorReport) -> str:
    return ", ".join(fault_names(m.faults)) or "no faults"


def _speed(m: MotorReport) -> str:
    v = m.velocity_rad_s
    return "-" if v is None else f"{fixed(v, 2, sign=True)} rad/s"


def _angle(m: MotorReport) -> str:
    a = m.position_rad
    return "-" if a is None else f"{fixed(math.degrees(a), 1, sign=True)} deg"


def _age(*motors: MotorReport) -> str:
    ages = [m.feedback_age_s for m in motors]
    if any(a is None for a in ages):
        return "-"
    return f"{fixed(max(a for a in ages if a is not None) * 1e3, 1)} ms"


class _Rows:
    """The motor table: one row per motor, or one per wheel with its steering actuator."""

    def __init__(self, motors: Sequence[MotorReport], steering: Mapping[str, tuple[str, ...]]
                 ) -> None:
        self.motors = motors
        self.pairs = pair_steering([m.name for m in motors], steering)
        self.steered = any(m.name in steering for m in motors)
        self.steering = steering
        own = [motors[i].name for i, _ in self.pairs]
        self.width = min(max([12, *(len(n) for n in own)]), 20)

    def _row(self, name: str, state: str, speed: str, steer: str, age: str, faults: str,
             level: Level) -> Line:
        angle = f"  {steer:>10}" if self.steered else ""
        text = f"  {name:<{self.width}.{self.width}} {state:<9} {speed:>12}{angle}  {age:>9}  "
        return Line(text + faults, level, 3 + self.width)

    def header(self) -> Line:
        return self._row("wheel", "state", "speed", "steer", "feedback", "faults", Level.PLAIN)

    def _alone(self, m: MotorReport, name: str = "") -> Line:
        actuator = m.name in self.steering
        return self._row(name or m.name, state_name(m.state), "" if actuator else _speed(m),
                         _angle(m) if actuator else "", _age(m), _faults(m), _level(m))

    def each(self) -> list[Line]:
        """A row per motor, an actuator under its wheel."""
        out = []
        for i, j in self.pairs:
            out.append(self._alone(self.motors[i]))
            if j is not None:
                out.append(self._alone(self.motors[j], "  steering"))
        return out

    def merged(self) -> list[Line]:
        """A row per wheel: its speed and its steering actuator's angle."""
        out = []
        for i, j in self.pairs:
            m = self.motors[i]
            if j is None:
                out.append(self._alone(m))
                continue
            a = self.motors[j]
            faults = _faults(m)
            if a.faults != DriveFault.NONE:
                faults += f"; steering {state_name(a.state)}: {_faults(a)}"
            elif a.state is not m.state and a.state is not DriveState.ENABLED:
                faults += f"; steering {state_name(a.state)}"
            out.append(self._row(m.name, state_name(m.state), _speed(m), _angle(a),
                                 _age(m, a), faults, _level(m, a)))
        return out


def _motors(screen: Screen) -> list[list[Line]]:
    """The motor table, from the fullest to the leanest: a row per motor; a row per wheel;
    without its header; then fewer rows, the last saying how many are left out."""
    d = screen.daemon
    if d is None or not d.motors:
        return [[]]
    rows = _Rows(d.motors, screen.steering)
    merged = rows.merged()
    out = [[rows.header(), *rows.each()], [rows.header(), *merged], merged]
    for keep in range(len(merged) - 1, -1, -1):
        more = len(merged) - keep
        out.append([*merged[:keep], Line(f"  ... {more} more (a taller terminal shows them)")])
    return out


# --------------------------------------------------------------------- the whole


def _daemon(screen: Screen, width: int) -> list[list[Line]]:
    d = screen.daemon
    if d is None:
        return [[Line("daemon: no status yet")]]
    cmd, pose, vel = d.command, d.odometry.pose, d.odometry.twist
    bad = d.state in (GatewayState.FAULT, GatewayState.ESTOP)
    state = [f"daemon: state {state_name(d.state)}{f' ({d.reason})' if d.reason else ''}",
             f"applied {_twist(cmd.applied)}",
             f"speed x{cmd.speed_scale:.2f} accel x{cmd.accel_scale:.2f}"]
    warning = screen.note if d.robot == screen.robot else (
        f"warning: the daemon drives {d.robot!r}, but the key limits are those of "
        f"{screen.robot!r} (pass its configuration with -c)")
    odometry = (f"odometry: x={fixed(pose.x_m, 3, sign=True)} m y={fixed(pose.y_m, 3, sign=True)} "
                f"m theta={fixed(pose.theta_rad, 3, sign=True)} rad   "
                f"v=({fixed(vel.vx_m_s, 3, sign=True)}, {fixed(vel.vy_m_s, 3, sign=True)}, "
                f"{fixed(vel.wz_rad_s, 3, sign=True)})")
    level = Level.ERROR if bad else Level.PLAIN
    return [[*pack(state, width, n, level, 8, "   "),
             *(wrap(warning, width, n, Level.WARNING) if warning else []),
             *wrap(odometry, width, n)] for n in (2, 1)]


def _log(screen: Screen) -> list[list[Line]]:
    lines = []
    for text in screen.log:
        level = (Level.ERROR if text.startswith(("ERROR", "CRITICAL")) else
                 Level.WARNING if text.startswith("WARNING") else Level.PLAIN)
        lines.append(Line(f"log: {text}", level, 5))
    return [lines, lines[-1:], []]


def render(screen: Screen, width: int = 100, height: int | None = None,
           colour: bool = False) -> list[str]:
    """The screen as at most ``height`` lines (``None``: as many as it takes) of at most
    ``width`` characters, coloured (ANSI SGR) when ``colour``."""
    jog, lim = screen.jog, screen.jog.limits
    if jog.moving:
        command = f"command: MOVING {key_name(jog.key)}  {_twist(jog.twist)}"
        scale = lim.command_scale(jog.twist)
        if scale is not None and scale < 1.0:
            command += f"  (limits scale it to {scale:.0%})"
    else:
        command = "command: STOPPED"
    linear = (f"linear {fixed(jog.linear_m_s, 3)} m/s (max {lim.max_linear_m_s:.3g}, "
              f"{lim.linear_by})")
    angular = (f"angular {fixed(jog.angular_rad_s, 3)} rad/s (max {lim.max_angular_rad_s:.3g}, "
               f"{lim.angular_by})")
    speeds = [Line(f"speeds:  {linear}   {angular}")]
    if len(speeds[0].text) > width:
        speeds = [Line(f"speeds:  {linear}"), Line(f"         {angular}")]
    error = screen.last_error or "-"
    error_level = (Level.PLAIN if error == "-" else
                   Level.WARNING if error.startswith("warning:") else Level.ERROR)
    connection = Level.PLAIN if screen.connected else Level.ERROR
    title = f"wheelgate jog: {screen.title}   "
    sections: list[list[list[Line]]] = [
        [wrap(title + screen.connection, width, 2, connection, len(title))],
        _help(screen),
        [[Line("")], []],
        [[*wrap(command, width, 2),
          *(wrap(screen.pad, width, 2, Level.PLAIN if screen.pad_ok else Level.ERROR, 10)
            if screen.pad else [])]],
        [speeds],
        [wrap(f"message: {jog.message}", width, n) for n in (3, 1)],
        [wrap(f"last error: {error}", width, n, error_level, 12) for n in (3, 1)],
        _daemon(screen, width),
        _motors(screen),
        _log(screen),
    ]
    # Giving way, in turn: a row per wheel; the blank line; the help in three lines; one log
    # line; one line of message, of error, of daemon; no log; the motors' header; the help in
    # one line; then fewer motors.
    motors = 8
    give_way = [motors, 2, 1, 9, 5, 6, 7, 9, motors, 1, *[motors] * len(sections[motors])]
    return [paint(line, width, colour) for line in fit(sections, height, give_way)]
