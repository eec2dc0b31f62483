"""``wheelgate monitor``: a live, decoded view of the configured robot's bus.

One of three sources:

* the daemon (the default, when one answers; ``--socket PATH``): its ``status`` is polled at
  the refresh rate and read into :class:`gateway.core.status.GatewayStatus`, and rates come
  from the differences between statuses;
* ``--bus``: the configured bus (or the root ``--interface``/``--channel``), opened with
  python-can.  **Read-only**: the monitor never sends a frame, not even a request; it decodes
  what the controllers and the gateway put on the bus.  (On SocketCAN the adapter still
  acknowledges frames as every node does; for a silent tap set the link listen-only with
  ``ip link set can0 type can listen-only on``.)  Frame times are the monitor's monotonic
  clock at receipt;
* ``--log FILE``: a candump log (``candump -l``, ``wheelgate run --record``), replayed at the
  recorded speed, or as fast as possible with ``--fast``; the log's time stamps are the clock.
  Unreadable lines are reported on stderr with their line number and skipped.

The screen is redrawn in place (ANSI home and clear) ``--refresh`` times a second when stdout
is a terminal, fitted to its size (:mod:`gateway.apps.monitor.screen`: no line wider, no more
lines than it has rows; the frame IDs paged) with faults in colour unless ``NO_COLOR`` is set;
else printed whole, one snapshot after the other.  ``--once`` prints one snapshot (of a log: at
its end, read as fast as possible; of a bus or the daemon: after ``--window`` seconds) and
``--json`` prints it as JSON (and a failure as ``{"ok": false, "error": {"code", "message"}}``
on stdout, exit code 1, or 2 for a bad configuration).  ``q`` or Esc (when stdin is a terminal
too) or Ctrl-C ends the monitor with exit code 0; space and ``b`` (or Page Down and Page Up) page
the frame IDs.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import select
import shutil
import sys
import termios
import time
import tty
from typing import TYPE_CHECKING

import can
import click

from gateway.apps.jog.keys import split_keys
from gateway.apps.keyboard import read_keys
from gateway.apps.layout import wants_colour
from gateway.apps.monitor import WINDOW_S, BusMonitor, StatusMonitor, render, snapshot_json
from gateway.apps.monitor.view import ERROR_FRAMES, error_class_counter
from gateway.bus.can_bus import open_bus, to_frame
from gateway.bus.edge import bus_options
from gateway.bus.health import CLASS_COUNTERS, ErrorFrame
from gateway.cli import FilePath, UsageExit, config_option, json_option
from gateway.cli.commands._common import load, socket_for
from gateway.cli.commands._guards import fail_json_of
from gateway.core.errors import GatewayError
from gateway.runtime.client import ClientError, ControlClient
from gateway.wire.candump import CandumpError, is_error_frame_line, parse_line
from gateway.wire.socket.status import status_from_json

if TYPE_CHECKING:
    from collections.abc import Callable, Iterator

    from gateway.apps.monitor import MonitorSnapshot
    from gateway.core.settings import GatewayConfig
    from gateway.core.status import GatewayStatus

#: Largest accepted --refresh (Hz) and --window (s).
MAX_REFRESH_HZ = 100.0
MAX_WINDOW_S = 3600.0
#: Line width when stdout is not a terminal.
PIPE_WIDTH = 1000
#: ANSI: cursor home, clear screen.
CLEAR = "\x1b[H\x1b[2J"
#: Keys of the live view: quit, next and previous page of frame IDs (Page Down, Page Up).
QUIT_KEYS = frozenset({"q", "Q", "\x1b"})  # Esc alone (an escape sequence is one key)
NEXT_KEYS = frozenset({" ", "n", "\x1b[6~"})
BACK_KEYS = frozenset({"b", "p", "\x1b[5~"})
#: Longest wait for a frame while keys are read (s): how late ``q`` may be on a bus.
KEY_POLL_S = 0.1


class Quit(KeyboardInterrupt):
    """``q`` or Esc was pressed: the monitor ends as on Ctrl-C (exit code 0)."""


def _positive(limit: float, unit: str) -> Callable[[click.Context, click.Parameter, float], float]:
    def check(ctx: click.Context, param: click.Parameter, value: float) -> float:
        if not (math.isfinite(value) and 0.0 < value <= limit):
            raise click.BadParameter(f"expected a number above 0 and at most {limit:g} {unit}, "
                                     f"got {value!r}")
        return value
    return check


class Screen:
    """Where snapshots go: redrawn in place on a terminal, one after the other otherwise; and
    the keys of the live view, once :meth:`reading_keys` has put stdin in cbreak mode.

    :param as_json: print the final snapshot as JSON.
    :param once: print only the final snapshot, whole (``--once``): it is not redrawn.
    """

    def __init__(self, as_json: bool = False, once: bool = False) -> None:
        self.as_json = as_json
        self.once = once
        self.tty = sys.stdout.isatty()
        self.colour = wants_colour(self.tty, os.environ)
        #: stdin's descriptor while keys are read, else ``None``.
        self.keys: int | None = None
        #: The page of frame IDs shown (modulo the pages).
        self.page = 0
        self._last: MonitorSnapshot | None = None

    @contextlib.contextmanager
    def reading_keys(self) -> Iterator[None]:
        """Read keys while the live view runs, when stdin and stdout are terminals: stdin in
        cbreak mode (a key arrives unechoed, without Enter; Ctrl-C still interrupts)."""
        fd = sys.stdin.fileno() if self.tty and sys.stdin.isatty() else None
        saved = None if fd is None else termios.tcgetattr(fd)
        try:
            if fd is not None:
                tty.setcbreak(fd)
                self.keys = fd
            yield
        finally:
            self.keys = None
            if fd is not None and saved is not None:
                with contextlib.suppress(termios.error):
                    termios.tcsetattr(fd, termios.TCSADRAIN, saved)
            if self.tty and self._last is not None:
                click.echo("")  # the prompt below the last screen

    def _draw(self, snap: MonitorSnapshot) -> None:
        self._last = snap
        if self.tty:
            cols, rows = shutil.get_terminal_size((80, 24))
            text = render(snap, max(cols - 1, 20), max(rows, 1), self.page, self.colour,
                          self.keys is not None)
            click.echo(CLEAR + text, nl=False)  # no newline after the last row: no scroll
        else:
            click.echo(render(snap, PIPE_WIDTH) + "\n")

    def show(self, snap: MonitorSnapshot) -> None:
        """Draw one live snapshot (fitted to the terminal; whole lines into a pipe), then take
        the keys pressed since the last."""
        self._draw(snap)
        self.wait(0.0)

    def wait(self, seconds: float) -> None:
        """Sleep ``seconds`` (none without keys when 0), taking the keys meanwhile.

        :raises Quit: on ``q`` or Esc.
        """
        if self.keys is None:
            if seconds > 0.0:
                time.sleep(seconds)
            return
        end = time.monotonic() + seconds
        while True:
            ready, _, _ = select.select([self.keys], [], [], max(end - time.monotonic(), 0.0))
            data = read_keys(self.keys, 64) if ready else b""
            if ready and not data:  # end of input: no more keys, only the time
                self.keys = None
                self.wait(max(end - time.monotonic(), 0.0))
                return
            for key in split_keys(data):
                if key in QUIT_KEYS:
                    raise Quit
                turn = 1 if key in NEXT_KEYS else -1 if key in BACK_KEYS else 0
                if turn and self._last is not None:
                    self.page += turn
                    self._draw(self._last)
            if time.monotonic() >= end:
                return

    def final(self, snap: MonitorSnapshot) -> None:
        """Print the last snapshot (as JSON with ``--json``; with ``--once`` whole, as into a
        pipe but cut to the terminal's width)."""
        if self.as_json:
            click.echo(json.dumps(snapshot_json(snap)))
        elif self.once and self.tty:
            cols = shutil.get_terminal_size((80, 24)).columns
            click.echo(render(snap, max(cols - 1, 20), colour=self.colour))
        else:
            self.show(snap)


@click.command()
@config_option
@click.option("--socket", "socket_path", type=FilePath(dir_okay=False), default=None,
              help="Control socket of the daemon to watch (the default source).")
@click.option("--bus", "use_bus", is_flag=True,
              help="Listen on the configured bus directly (read-only: sends nothing).")
@click.option("--log", "log_path", type=FilePath(exists=True, dir_okay=False), default=None,
              help="Replay a candump log (e.g. from `wheelgate run --record`).")
@click.option("--fast", is_flag=True, help="With --log: replay as fast as possible.")
@click.option("--refresh", type=float, default=5.0, show_default=True,
              callback=_positive(MAX_REFRESH_HZ, "Hz"),
              help=f"Screen updates per second, above 0 and at most {MAX_REFRESH_HZ:g}.")
@click.option("--window", type=float, default=WINDOW_S, show_default=True,
              callback=_positive(MAX_WINDOW_S, "s"),
              help=f"Rates and bus load average over this many seconds, above 0 and at "
                   f"most {MAX_WINDOW_S:g}.")
@click.option("--once", is_flag=True, help="Print one snapshot and exit.")
@json_option
@click.pass_context
def command(
    ctx: click.Context, config_path: str | None, socket_path: str | None, use_bus: bool,
    log_path: str | None, fast: bool, refresh: float, window: float, once: bool, as_json: bool,
) -> None:
    """Watch the robot's bus: motor states, speeds, positions and faults, frame rates per ID,
    bus load and error counters; from the daemon, the bus (--bus) or a log (--log)."""
    if as_json and not once:
        raise click.UsageError("--json needs --once (the live view is text)")
    sources = [name for name, on in (("--socket", socket_path), ("--bus", use_bus),
                                     ("--log", log_path)) if on]
    if len(sources) > 1:
        raise click.UsageError(f"expected one source, got {' and '.join(sources)}")
    if fast and log_path is None:
        raise click.UsageError("--fast applies to --log only")
    screen = Screen(as_json, once)
    period = 1.0 / refresh
    try:
        cfg = load(ctx, config_path)
        with contextlib.nullcontext() if once else screen.reading_keys():
            if log_path is not None:
                watch_log(cfg, log_path, screen, period, window, fast=fast or once, once=once)
            elif use_bus:
                watch_bus(cfg, screen, period, window, once)
            else:
                with _client(ctx, config_path, socket_path) as client:
                    watch_daemon(cfg, client, screen, period, window, once)
    except KeyboardInterrupt:  # Ctrl-C, or q (Quit)
        return
    except (click.ClickException, GatewayError) as err:
        if not as_json:  # with --json (and --once) a failure too is JSON, as status's
            raise
        fail_json_of(ctx, err)


def _client(ctx: click.Context, config_path: str | None, socket_path: str | None
            ) -> ControlClient:
    """A client of the daemon to watch.

    :raises click.ClickException: when none answers, naming the other sources.
    """
    try:
        return ControlClient(socket_for(ctx, config_path, socket_path))
    except ClientError as err:
        hint = "" if socket_path else (
            "; to watch without a daemon use --bus, or --log FILE for a recording")
        raise click.ClickException(f"{err}{hint}") from err


def watch_log(cfg: GatewayConfig, path: str, screen: Screen, period: float, window: float,
              fast: bool, once: bool) -> None:
    """Replay a candump log through a :class:`BusMonitor` on the log's clock."""
    mon = BusMonitor(cfg, window, source=f"log {path}")
    mon.count(ERROR_FRAMES, 0)
    mon.count("unreadable lines", 0)
    t: float | None = None
    offset: float | None = None  # wall clock - log clock, at recorded speed
    next_draw = time.monotonic() + period
    with open(path, encoding="utf-8", errors="replace") as lines:
        for number, line in enumerate(lines, start=1):
            if line[:1] != "(" and (not line.strip() or line.lstrip().startswith("#")):
                continue  # blank lines and comments, as gateway.wire.candump.read_lines skips them
            try:
                entry = parse_line(line, number)
            except CandumpError as err:
                if is_error_frame_line(line):
                    mon.count(ERROR_FRAMES)
                else:
                    mon.count("unreadable lines")
                    click.echo(f"{path}: {err} (skipped)", err=True)
                continue
            if not fast:
                if offset is None:
                    offset = time.monotonic() - entry.timestamp_s
                while (now := time.monotonic()) < entry.timestamp_s + offset:
                    if now >= next_draw and t is not None:
                        screen.show(mon.snapshot(max(now - offset, t)))
                        next_draw = max(next_draw + period, now)
                    screen.wait(max(min(entry.timestamp_s + offset, next_draw) - now, 0.0))
            t = entry.timestamp_s
            mon.feed(entry.frame, t, "rx" if entry.is_rx else "tx", decode=entry.is_rx)
            if not once and number & 0xFF == 0 and (now := time.monotonic()) >= next_draw:
                screen.show(mon.snapshot(t))
                next_draw = max(next_draw + period, now)
    bad = mon.counters["unreadable lines"]
    if bad and t is None and not mon.counters[ERROR_FRAMES]:  # (an empty log shows no frames)
        raise UsageExit(f"{path}: no readable frames in the log ({bad:,} unreadable lines); "
                        f"expected a candump log (candump -l, wheelgate run --record)")
    screen.final(mon.snapshot(0.0 if t is None else t))


def virtual_bus_note(channel: str) -> str:
    """What ``monitor --bus`` says up front on a ``virtual`` bus: why it sees nothing of other
    processes, and how to watch a gateway and its controllers anyway."""
    kernel = "wheelgate --interface socketcan --channel vcan0"
    return (
        f"monitor: the bus is python-can's virtual one (channel {channel!r}), which exists only "
        f"inside one process: this monitor sees nothing of a gateway ('wheelgate run --sim') or "
        f"of simulated controllers ('wheelgate sim') running in another process.\n"
        f"  To watch them, run the gateway and 'wheelgate sim' on a kernel bus:\n"
        f"    sudo modprobe vcan && sudo ip link add vcan0 type vcan && "
        f"sudo ip link set vcan0 up\n"
        f"    {kernel} sim\n"
        f"    {kernel} run\n"
        f"    {kernel} monitor --bus    (or: candump vcan0)\n"
        f"  or watch the daemon through its socket: wheelgate monitor (without --bus).\n"
        f"  Listening on the virtual bus anyway."
    )


def watch_bus(cfg: GatewayConfig, screen: Screen, period: float, window: float,
              once: bool) -> None:
    """Listen on the configured bus (never sending) through a :class:`BusMonitor`."""
    if cfg.bus.interface == "virtual":
        click.echo(virtual_bus_note(cfg.bus.channel), err=True)
    bus = open_bus(cfg.bus.interface, cfg.bus.channel, cfg.bus.bitrate,
                   **bus_options(cfg.bus.interface, None))
    try:
        start = time.monotonic()
        mon = BusMonitor(cfg, window, source=f"bus {cfg.bus.interface}:{cfg.bus.channel}",
                         start_s=start)
        mon.count(ERROR_FRAMES, 0)
        mon.count("receive errors", 0)
        end = start + window if once else math.inf
        next_draw = start + period
        while (now := time.monotonic()) < end:
            if now >= next_draw and not once:
                screen.show(mon.snapshot(now))
                next_draw = max(next_draw + period, now)
            wait = max(min(end, next_draw) - now, 0.0)
            try:
                msg = bus.recv(wait if screen.keys is None else min(wait, KEY_POLL_S))
            except (can.CanError, OSError) as err:
                mon.count("receive errors")
                click.echo(f"monitor: receiving from {cfg.bus.channel} failed: {err}", err=True)
                time.sleep(min(period, 0.1))
                continue
            screen.wait(0.0)
            if msg is None:
                continue
            t = time.monotonic()
            if msg.is_error_frame:
                mon.count(ERROR_FRAMES)
                error = ErrorFrame.decode(msg.arbitration_id, bytes(msg.data))
                for flag, name in CLASS_COUNTERS.items():
                    if error.classes & flag:
                        mon.count(error_class_counter(name))
            elif msg.is_fd:
                mon.count("CAN FD frames (ignored)")
            else:
                mon.feed(to_frame(msg, t), t)
        screen.final(mon.snapshot(time.monotonic()))
    finally:
        bus.shutdown()


def _status(client: ControlClient) -> GatewayStatus:
    """The daemon's status.

    :raises click.ClickException: if the daemon refuses the request.
    :raises ProtocolError: naming the key of a malformed reply.
    """
    reply = client.request({"op": "status"})
    if not reply.get("ok"):
        error = reply.get("error") or {}
        raise click.ClickException(f"the daemon at {client.path} refused the status request: "
                                   f"{error.get('message', reply)}")
    return status_from_json(reply)


def watch_daemon(cfg: GatewayConfig, client: ControlClient, screen: Screen, period: float,
                 window: float, once: bool) -> None:
    """Poll the daemon's status through a :class:`StatusMonitor`."""
    mon = StatusMonitor(cfg, window, source=f"daemon {client.path}")
    mon.update(_status(client))
    if once:
        time.sleep(window)
        mon.update(_status(client))
        screen.final(mon.snapshot())
        return
    next_poll = time.monotonic()
    while True:
        next_poll = max(next_poll + period, time.monotonic())
        screen.wait(max(next_poll - time.monotonic(), 0.0))
        mon.update(_status(client))
        screen.show(mon.snapshot())
