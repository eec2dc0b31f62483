"""The jog screen, pure: :func:`render` turns a :class:`Screen` -- the session of
:mod:`gateway.apps.jog.keys` and the daemon's last status (:class:`gateway.core.status.
GatewayStatus`, which :func:`read_status` takes from a reply) -- into lines of text.  The
terminal itself is handled by :mod:`gateway.cli.commands.jog`.  No I/O, no clock.
"""

from __future__ import annotations

import textwrap
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from gateway.apps.jog.keys import HELP, key_name
from gateway.core.status import fault_names, state_name
from gateway.wire.socket import ProtocolError
from gateway.wire.socket.status import status_from_json

if TYPE_CHECKING:
    from gateway.apps.jog.keys import JogState
    from gateway.core.status import GatewayStatus
    from gateway.core.types import Twist


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
    """

    robot: str
    title: str
    connection: str
    jog: JogState
    daemon: GatewayStatus | None = None
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
        cmd, pose, vel = d.command, d.odometry.pose, d.odometry.twist
        lines += [
            f"daemon: state {state_name(d.state)}{f' ({d.reason})' if d.reason else ''}   "
            f"applied {_fmt_twist(cmd.applied)}   speed x{cmd.speed_scale:.2f} "
            f"accel x{cmd.accel_scale:.2f}",
            *([] if d.robot == screen.robot else _wrapped(
                f"warning: the daemon drives {d.robot!r}, but the key limits are those of "
                f"{screen.robot!r} (pass its configuration with -c)", width)),
            f"odometry: x={pose.x_m:+.3f} m y={pose.y_m:+.3f} m theta={pose.theta_rad:+.3f} rad"
            f"   v=({vel.vx_m_s:+.3f}, {vel.vy_m_s:+.3f}, {vel.wz_rad_s:+.3f})",
        ]
        for m in d.motors:
            speed = "-" if m.velocity_rad_s is None else f"{m.velocity_rad_s:+.2f} rad/s"
            age = "-" if m.feedback_age_s is None else f"{m.feedback_age_s * 1e3:.1f} ms"
            lines.append(f"  {m.name:<14} {state_name(m.state):<9} wheel {speed:>13}  "
                         f"feedback {age:>9}  {', '.join(fault_names(m.faults)) or 'no faults'}")
    lines += [f"log: {line}" for line in screen.log]
    return [line[:width] for line in lines]
