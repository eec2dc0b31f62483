"""``wheelgate jog``: drive the robot from the keyboard, on one terminal screen.

The terminal edge around :mod:`gateway.apps.jog.keys` and :mod:`gateway.apps.jog.screen`: raw
mode (so Ctrl-C arrives as a key), one screen redrawn in place with ANSI escapes (alternate
screen; no curses) and fitted to the terminal's size at every draw, faults in colour unless
``NO_COLOR`` is set, ``select`` on stdin with the deadman's deadlines as timeouts, status
polled at 5 Hz.  ``--standalone`` runs a daemon in a thread of this process, privately.
``--joystick`` adds a gamepad's device to the ``select`` (:mod:`gateway.apps.jog.joystick`,
:mod:`gateway.apps.jog.pad`); the daemon's socket is :mod:`gateway.apps.jog.link`.

Whatever ends the session -- Ctrl-C, Ctrl-D, Esc, end of input, a closed terminal, SIGHUP,
SIGTERM or SIGINT -- sends stop before the terminal mode is restored.  Should this program die
without it, the daemon's ``cmd_timeout_s`` stops the robot.
"""

from __future__ import annotations

import collections
import contextlib
import logging
import math
import os
import select
import shutil
import sys
import tempfile
import termios
import threading
import time
import tty
from typing import TYPE_CHECKING

import click

from gateway.apps.jog import keys
from gateway.apps.jog.joystick import Joystick, JoystickError
from gateway.apps.jog.keys import STOP, JogState, Request, jog_limits, split_keys, steps_errors
from gateway.apps.jog.link import JogLink
from gateway.apps.jog.pad import DEFAULT_AXES, DEFAULT_ENABLE, PadMap
from gateway.apps.jog.screen import Screen, read_status, render, reply_error
from gateway.apps.keyboard import read_keys
from gateway.apps.layout import steering_of, wants_colour
from gateway.cli import FilePath, UsageExit, config_option
from gateway.cli.commands import _common as common
from gateway.cli.commands._guards import caught_signals
from gateway.runtime.client import ClientError
from gateway.runtime.daemon import Daemon
from gateway.runtime.sdnotify import SystemdNotifier

if TYPE_CHECKING:
    from collections.abc import Iterator

    from gateway.apps.jog.keys import JogLimits
    from gateway.core.settings import GatewayConfig
    from gateway.core.status import GatewayStatus

#: How often the daemon's status is polled (s).
STATUS_PERIOD_S = 0.2
#: Log lines kept for the screen.
LOG_LINES = 3

#: Longest directory for the private socket of ``--standalone`` (AF_UNIX limit, with margin).
_MAX_SOCKET_DIR = 90

_ENTER = "\x1b[?1049h\x1b[?25l\x1b[2J"  # alternate screen, hide the cursor, clear
_LEAVE = "\r\n\x1b[?25h\x1b[?1049l"  # a fresh line where no alternate screen is restored


class _LogCapture(logging.Handler):
    """Keeps log records while the screen is up; they are re-emitted afterwards."""

    def __init__(self) -> None:
        super().__init__()
        self.records: list[logging.LogRecord] = []
        self.lines: collections.deque[str] = collections.deque(maxlen=LOG_LINES)

    def emit(self, record: logging.LogRecord) -> None:
        self.records.append(record)
        self.lines.append(f"{record.levelname} {record.name}: {record.getMessage()}")


@contextlib.contextmanager
def _captured_logs() -> Iterator[_LogCapture]:
    root = logging.getLogger()
    saved = root.handlers[:]
    capture = _LogCapture()
    root.handlers[:] = [capture]
    try:
        yield capture
    finally:
        root.handlers[:] = saved
        for record in capture.records:
            if record.levelno >= logging.WARNING:
                logging.getLogger(record.name).handle(record)


@contextlib.contextmanager
def _standalone(cfg: GatewayConfig, sim: bool) -> Iterator[str]:
    """A daemon in a thread of this process on a private socket; stopped on exit."""
    folder = tempfile.mkdtemp(prefix="wgjog")
    if len(folder) > _MAX_SOCKET_DIR:  # AF_UNIX paths end at 107 bytes; a long $TMPDIR
        os.rmdir(folder)
        folder = tempfile.mkdtemp(prefix="wgjog", dir="/tmp")
    daemon = None
    try:
        daemon = Daemon(cfg, sim=sim, socket_path=f"{folder}/s.sock",
                        notifier=SystemdNotifier(None))
        thread = threading.Thread(target=daemon.run, name="wheelgate-daemon", daemon=True)
        thread.start()
        try:
            yield daemon.socket_path
        finally:
            daemon.request_stop()
            thread.join(timeout=10.0)
    finally:
        if daemon is not None:
            daemon.close()
        shutil.rmtree(folder, ignore_errors=True)


@contextlib.contextmanager
def _raw_terminal(fd: int) -> Iterator[None]:
    """Raw mode on ``fd`` (no echo, no line editing, Ctrl-C as a byte), restored on exit."""
    saved = termios.tcgetattr(fd)
    try:
        tty.setraw(fd)
        yield
    finally:
        with contextlib.suppress(termios.error):  # EIO: the terminal is gone, nothing to restore
            termios.tcsetattr(fd, termios.TCSADRAIN, saved)


class _Terminal:
    """Writes to the screen; a closed terminal is noted, never fatal (stop must still go)."""

    def __init__(self, fd: int) -> None:
        self.fd = fd
        self.colour = wants_colour(os.isatty(fd), os.environ)
        self.gone = False
        self._last: tuple[int, int, list[str]] = (0, 0, [])

    def write(self, text: str) -> None:
        data = text.encode("utf-8", "replace")
        while data and not self.gone:
            try:
                data = data[os.write(self.fd, data):]
            except OSError:
                self.gone = True

    def draw(self, screen: Screen) -> None:
        """Draw ``screen`` in the terminal's rows, a column short of its width (no wrap)."""
        cols, rows = shutil.get_terminal_size((80, 24))
        lines = render(screen, max(cols - 1, 20), max(rows, 1), self.colour)
        if (cols, rows, lines) != self._last:  # redraw on a change or a resize
            self._last = (cols, rows, lines)
            self.write("\x1b[H" + "\x1b[K\r\n".join(lines) + "\x1b[K\x1b[J")


def _axes(ctx: click.Context, param: click.Parameter, value: str) -> tuple[int, int, int]:
    """``--joy-axes``: three joydev axis numbers (exit 2 for anything else)."""
    parts = [p.strip() for p in value.split(",")]
    if len(parts) != 3 or not all(p.isascii() and p.isdecimal() and int(p) <= 255
                                  for p in parts):
        raise click.BadParameter(f"expected three axis numbers 0 to 255 for vx, vy and wz, "
                                 f"as 1,0,3; got {value!r}")
    return int(parts[0]), int(parts[1]), int(parts[2])


def _checked(cfg: GatewayConfig, speed: float | None, turn: float | None) -> JogLimits:
    """The jog limits of ``cfg``; ``--speed`` and ``--turn`` refused beyond them (exit 2)."""
    limits = jog_limits(cfg)
    for option, why in steps_errors(limits, speed, turn):
        raise click.BadParameter(f"{why} (robot {cfg.name!r})", param_hint=option)
    return limits


def _session(fd_in: int, wake_fd: int, caught: list[str], term: _Terminal, link: JogLink,
             state: JogState, cfg: GatewayConfig, title: str, logs: _LogCapture,
             note: str, pad: Joystick | None) -> JogState:
    """The select loop; returns the final state (stop has been sent); ``note``: a warning
    about the daemon's configuration, on the screen; ``pad``: the gamepad, if any."""
    last_error = ""
    view: GatewayStatus | None = None
    next_status = 0.0
    steering = steering_of(cfg)

    def send(requests: tuple[Request, ...]) -> None:
        nonlocal last_error
        for req in requests:
            reply = link.send(req)
            if reply is None:
                last_error = f"connection: {link.error}"
            elif not reply.get("ok"):
                last_error = reply_error(reply)
            elif reply.get("warning"):
                last_error = f"warning: {reply['warning']}"
            elif req.op == "twist":
                last_error = ""

    try:
        while not state.ended:
            now = time.monotonic()
            if now >= next_status:
                link.retry()
                status = link.request({"op": "status"})
                if status is not None and status.get("ok"):
                    view, problem = read_status(status)
                    last_error = problem or last_error
                next_status = now + STATUS_PERIOD_S
            connection = (f"connected: {link.path}" if link.client is not None else
                          f"DISCONNECTED: {link.error} (retrying)")
            term.draw(Screen(cfg.name, title, connection, state, view, last_error,
                             tuple(logs.lines), link.client is not None, steering, note,
                             "" if pad is None else pad.describe(),
                             pad is None or pad.fd is not None))
            deadline = min(state.next_deadline_s(), next_status,
                           math.inf if pad is None else pad.next_retry_s())
            fds = [fd_in, wake_fd] + ([pad.fd] if pad is not None and pad.fd is not None else [])
            ready, _, _ = select.select(fds, [], [], max(0.0, deadline - now))
            now = time.monotonic()
            if wake_fd in ready:
                os.read(wake_fd, 512)
            if caught:
                step = state.on_quit(caught[0])
                state = step.state
                send(step.requests)
                break
            if fd_in in ready:
                try:
                    data = read_keys(fd_in, 1024)
                except OSError:  # EIO: the terminal is gone
                    data = b""
                if not data:
                    step = state.on_quit("end of input")
                    state = step.state
                    send(step.requests)
                    break
                for key in split_keys(data):
                    step = state.on_key(key, now)
                    state = step.state
                    send(step.requests)
                    if state.ended:
                        break
            if pad is not None:
                if pad.fd is not None and pad.fd in ready:
                    pad.read()
                pad.retry(now)
                step = state.on_pad(pad.pad.direction(state.limits.holonomic), now,
                                    "" if pad.fd is not None else f"lost: {pad.error}")
                state = step.state
                send(step.requests)
            step = state.on_tick(now)
            state = step.state
            send(step.requests)
    finally:
        if link.last_op != "stop":  # an exception, or the stop was not acknowledged
            send((STOP,))
    return state


@click.command()
@config_option
@click.option("--socket", "socket_path", type=FilePath(dir_okay=False), default=None,
              help="Control socket of the running daemon.")
@click.option("--standalone", is_flag=True,
              help="Own the bus: run the daemon in this process on a private socket.")
@click.option("--sim", is_flag=True,
              help="With --standalone: simulate the motor controllers on a virtual bus.")
@click.option("--deadman", type=click.FloatRange(min=0.1, max=5.0),
              default=keys.DEFAULT_DEADMAN_S, show_default=True,
              help="Stop when no motion key came for this long (s); keep it above the "
                   "keyboard's auto-repeat delay (250-500 ms).")
@click.option("--speed", type=float, default=None,
              help=f"First linear speed of the keys, m/s, at most the robot's limit "
                   f"(teleop_twist_keyboard's speed; default {keys.DEFAULT_LINEAR_M_S:g}).")
@click.option("--turn", type=float, default=None,
              help=f"First angular speed of the keys, rad/s, at most the robot's limit "
                   f"(teleop_twist_keyboard's turn; default {keys.DEFAULT_ANGULAR_RAD_S:g}).")
@click.option("--log", "log_path", type=FilePath(dir_okay=False, writable=True), default=None,
              help="Write every twist and stop sent, with its reply, as JSON lines.")
@click.option("--joystick", type=FilePath(dir_okay=False), default=None,
              help="Drive with a gamepad too: its Linux joystick device (e.g. /dev/input/js0). "
                   "Hold the enable button; the left stick drives, the right one turns.")
@click.option("--joy-enable", type=click.IntRange(0, 255), default=DEFAULT_ENABLE,
              show_default=True, help="The button to hold (joydev number; 4: LB, L1).")
@click.option("--joy-axes", default=",".join(map(str, DEFAULT_AXES)), show_default=True,
              callback=_axes,
              help="The axes for vx, vy and wz (joydev numbers; pushed up or left is "
                   "positive).")
@click.pass_context
def command(
    ctx: click.Context,
    config_path: str | None,
    socket_path: str | None,
    standalone: bool,
    sim: bool,
    deadman: float,
    speed: float | None,
    turn: float | None,
    log_path: str | None,
    joystick: str | None,
    joy_enable: int,
    joy_axes: tuple[int, int, int],
) -> None:
    """Drive the robot from the keyboard (teleop_twist_keyboard keys) on one screen.

    \b
       u i o     U I O   (shift: holonomic drives only)
       j k l     J K L   k, space, other keys: stop
       m , .     M < >   q/z w/x e/c: speeds +/-10%

    A move lasts while its key repeats; --deadman seconds without one sends stop.
    With --joystick a gamepad drives while its enable button is held (pressed after the pad
    was opened); letting go, or losing the pad, sends stop.
    Quit with Ctrl-C, Ctrl-D or Esc (q speeds up, as in teleop_twist_keyboard); quitting
    always sends stop.  Should this program die, the daemon's cmd_timeout_s stops the robot.
    The screen fits the terminal; faults are red unless NO_COLOR is set.
    """
    common.check_finite(deadman=deadman)
    if sim and not standalone:
        raise click.UsageError("--sim needs --standalone (a running daemon has its own bus)")
    if standalone and socket_path:
        raise click.UsageError("--standalone uses a private socket; drop --socket")
    cfg = common.load(ctx, config_path)
    daemons = config_path is None and not standalone  # the daemon's robot: known once asked
    limits = jog_limits(cfg) if daemons else _checked(cfg, speed, turn)
    if not sys.stdin.isatty():
        raise UsageExit("jog reads keys from a terminal, but stdin is not a terminal")
    with contextlib.ExitStack() as stack:
        pad = None
        if joystick is not None:  # (before a standalone daemon starts: refused, nothing ran)
            try:
                pad = Joystick(joystick, PadMap(joy_enable, *joy_axes))
            except JoystickError as err:
                raise UsageExit(f"--joystick: {err}") from err
            stack.callback(pad.close)
        log_file = None
        if log_path is not None:
            try:
                log_file = stack.enter_context(open(log_path, "w", encoding="utf-8"))
            except OSError as err:
                raise click.BadParameter(f"cannot write {log_path}: {err.strerror}",
                                         param_hint="--log") from err
        logs = stack.enter_context(_captured_logs())
        if standalone:
            path = stack.enter_context(_standalone(cfg, sim))
        else:
            path = common.socket_for(ctx, config_path, socket_path)
        try:
            link = JogLink(path, log_file)
        except ClientError as err:
            raise click.ClickException(str(err)) from err
        stack.callback(link.close)
        note = ""
        if daemons:  # its own file when it can be read here, else the embedded default
            found, note = (common.daemon_config(ctx, link.client.request({"op": "status"}))
                           if link.client is not None else (None, ""))
            cfg = found or cfg
            limits = _checked(cfg, speed, turn)
        elif not standalone and link.client is not None:
            note = common.refuse_other_robot(ctx, config_path, link.client)
        state = JogState.start(limits, speed, turn, deadman)
        title = (f"{cfg.name} ({cfg.drive})"
                 + (f", standalone{', simulated' if sim else ''}" if standalone else ""))
        fd_in, term = sys.stdin.fileno(), _Terminal(sys.stdout.fileno())
        wake_r, wake_w = os.pipe()
        for fd in (wake_r, wake_w):
            os.set_blocking(fd, False)
            stack.callback(os.close, fd)
        caught = stack.enter_context(caught_signals(wake_w))
        stack.enter_context(_raw_terminal(fd_in))
        term.write(_ENTER)
        stack.callback(term.write, _LEAVE)
        state = _session(fd_in, wake_r, caught, term, link, state, cfg, title, logs, note, pad)
    if link.last_op != "stop":
        raise click.ClickException(
            f"could not send stop to {path}: {link.error or 'refused'}; the daemon's "
            f"cmd_timeout_s ({cfg.loop.cmd_timeout_s:g} s) stops the robot")
    with contextlib.suppress(OSError):  # the terminal may be gone
        click.echo(f"jog: {state.ended}: stop sent to {path}", err=True)

