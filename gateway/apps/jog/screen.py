"""The jog screen, pure: the daemon's status as the screen shows it, and :func:`render`.

:func:`daemon_view` reads a ``status`` reply into a :class:`DaemonView`; :func:`render` turns a
:class:`Screen` (the session of :mod:`gateway.apps.jog.keys` plus that view) into lines of text.
The
terminal itself is handled by :mod:`gateway.cli.commands.jog`.  No I/O, no clock.
"""

from __future__ import annotations

import math
import textwrap
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from gateway.apps.jog.keys import HELP, key_name
from gateway.core.types import Twist

if TYPE_CHECKING:
    from gateway.apps.jog.keys import JogState


# --------------------------------------------------------------------- what the daemon says


@dataclass(frozen=True, slots=True)
class MotorView:
    """One motor in the daemon's status."""

    name: str
    state: str
    faults: tuple[str, ...]
    feedback_age_s: float | None
    velocity_rad_s: float | None


@dataclass(frozen=True, slots=True)
class DaemonView:
    """The parts of the daemon's status the screen shows."""

    robot: str
    state: str
    reason: str
    odometry: tuple[float, float, float, float, float, float]  # x y theta vx vy wz
    applied: Twist | None
    speed_scale: float
    accel_scale: float
    motors: tuple[MotorView, ...]


def _num(value: object, default: float = math.nan) -> float:
    return float(value) if isinstance(value, (int, float)) else default


def _twist(obj: object) -> Twist | None:
    if not isinstance(obj, Mapping):
        return None
    return Twist(_num(obj.get("vx_m_s")), _num(obj.get("vy_m_s")), _num(obj.get("wz_rad_s")))


def daemon_view(status: Mapping[str, Any]) -> DaemonView:
    """The screen's view of a ``status`` reply (missing fields show as ``nan`` or ``-``)."""
    odo = status.get("odometry") or {}
    cmd = status.get("command") or {}
    motors = tuple(
        MotorView(str(m.get("name", "?")), str(m.get("state", "?")),
                  tuple(str(f) for f in m.get("faults") or ()),
                  None if m.get("feedback_age_s") is None else _num(m["feedback_age_s"]),
                  None if m.get("velocity_rad_s") is None else _num(m["velocity_rad_s"]))
        for m in status.get("motors") or () if isinstance(m, Mapping))
    return DaemonView(
        str(status.get("robot", "?")), str(status.get("state", "?")),
        str(status.get("reason") or ""),
        (_num(odo.get("x")), _num(odo.get("y")), _num(odo.get("theta")),
         _num(odo.get("vx")), _num(odo.get("vy")), _num(odo.get("wz"))),
        _twist(cmd.get("applied")), _num(cmd.get("speed_scale"), 1.0),
        _num(cmd.get("accel_scale"), 1.0), motors)


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
    """

    robot: str
    title: str
    connection: str
    jog: JogState
    daemon: DaemonView | None = None
    last_error: str = ""
    log: tuple[str, ...] = ()


def _fmt_twist(t: Twist) -> str:
    return f"vx={t.vx_m_s:+.3f} m/s vy={t.vy_m_s:+.3f} m/s wz={t.wz_rad_s:+.3f} rad/s"


def _wrapped(text: str, width: int, max_lines: int = 3) -> list[str]:
    return textwrap.wrap(text, width, subsequent_indent="    ", max_lines=max_lines) or [""]


def render(screen: Screen, width: int = 100) -> list[str]:
    """The screen as lines of at most ``width`` characters."""
    jog, lim = screen.jog, screen.jog.limits
    help_lines = list(HELP)
    if not lim.holonomic:
        help_lines[0] += f"   (not on this {lim.drive} drive)"
    if jog.moving:
        command = f"command: MOVING {key_name(jog.key)}  {_fmt_twist(jog.twist)}"
        scale = lim.command_scale(jog.twist)
        if scale is not None and scale < 1.0:
            command += f"  (limits scale it to {scale:.0%})"
    else:
        command = "command: STOPPED"
    lines = [
        f"wheelgate jog: {screen.title}   {screen.connection}",
        *help_lines,
        f"deadman: a move lasts while its key repeats; {jog.deadman_s:g} s without it: stop "
        "(second net: the daemon's cmd_timeout_s)",
        "",
        command,
        f"speeds:  linear {jog.linear_m_s:.3f} m/s (max {lim.max_linear_m_s:.3g}, "
        f"{lim.linear_by})   angular {jog.angular_rad_s:.3f} rad/s "
        f"(max {lim.max_angular_rad_s:.3g}, {lim.angular_by})",
        *_wrapped(f"message: {jog.message}", width),
        *_wrapped(f"last error: {screen.last_error or '-'}", width),
    ]
    d = screen.daemon
    if d is None:
        lines.append("daemon: no status yet")
    else:
        applied = "-" if d.applied is None else _fmt_twist(d.applied)
        lines += [
            f"daemon: state {d.state}{f' ({d.reason})' if d.reason else ''}   applied "
            f"{applied}   speed x{d.speed_scale:.2f} accel x{d.accel_scale:.2f}",
            *([] if d.robot in ("?", screen.robot) else _wrapped(
                f"warning: the daemon drives {d.robot!r}, but the key limits are those of "
                f"{screen.robot!r} (pass its configuration with -c)", width)),
            "odometry: x={:+.3f} m y={:+.3f} m theta={:+.3f} rad   v=({:+.3f}, {:+.3f}, "
            "{:+.3f})".format(*d.odometry),
        ]
        for m in d.motors:
            vel = "-" if m.velocity_rad_s is None else f"{m.velocity_rad_s:+.2f} rad/s"
            age = "-" if m.feedback_age_s is None else f"{m.feedback_age_s * 1e3:.1f} ms"
            lines.append(f"  {m.name:<14} {m.state:<9} wheel {vel:>13}  feedback {age:>9}  "
                         f"{', '.join(m.faults) or 'no faults'}")
    lines += [f"log: {line}" for line in screen.log]
    return [line[:width] for line in lines]
