"""``wheelgate run``: the gateway daemon."""

from __future__ import annotations

import logging
import sys
import threading
from typing import TYPE_CHECKING

import click

from gateway.cli import FilePath, config_option
from gateway.cli.commands._common import check_finite, load
from gateway.cli.commands._guards import MAX_DURATION_S
from gateway.cli.stderr import point_at_devnull, pump_logging
from gateway.config.budget import check_bus
from gateway.drive.driveset import DriveSet
from gateway.runtime.daemon import Daemon
from gateway.runtime.report import motors_text

if TYPE_CHECKING:
    from collections.abc import Callable

log = logging.getLogger("gateway.run")


def tell(line: str) -> None:
    """A line for the person who started the daemon, on stderr -- best effort, as logging is:
    a stderr that went away (a pipe whose reader closed, a terminal gone) must not end the
    daemon, nor fail its exit.  It is then pointed at ``/dev/null`` (the recipe of Python's
    :mod:`signal` documentation, "Note on SIGPIPE"), so that the lines still queued, the log
    lines and the interpreter's last flush go nowhere instead of failing."""
    try:
        click.echo(line, err=True)
    except OSError:
        point_at_devnull(sys.stderr)


@click.command()
@config_option
@click.option("--sim", is_flag=True,
              help="Simulate every motor controller on a virtual bus in this process.")
@click.option("--record", type=FilePath(dir_okay=False, writable=True), default=None,
              help="Log every frame sent and received, candump format (.log).")
@click.option("--socket", "socket_path", type=FilePath(dir_okay=False), default=None,
              help="Control socket path (default: the config's gateway.socket, else "
                   "$WHEELGATE_SOCKET, else /run/wheelgate/wheelgate.sock when that directory "
                   "is writable, else $XDG_RUNTIME_DIR/wheelgate.sock, else one in /tmp).")
@click.option("--record-mcap", type=FilePath(dir_okay=False, writable=True), default=None,
              help="Record odometry, transforms, wheel speeds, state and errors to an MCAP "
                   "file (needs wheelgate[foxglove]; `wheelgate odom FILE.mcap` replays it).")
@click.option("--duration", type=click.FloatRange(min=0.0, min_open=True, max=MAX_DURATION_S),
              default=None,
              help=f"Stop after this many seconds (above 0, at most {MAX_DURATION_S:g}), as on "
                   f"SIGTERM (default: run until stopped).")
@click.pass_context
def command(
    ctx: click.Context,
    config_path: str | None,
    sim: bool,
    record: str | None,
    socket_path: str | None,
    record_mcap: str | None,
    duration: float | None,
) -> None:
    """Run the gateway: twists in, wheel frames out, odometry back (SIGTERM or Ctrl-C stops
    it, leaving every motor at zero and disarmed)."""
    if duration is not None:
        check_finite(duration=duration)
    pump = pump_logging()  # (the loop never waits for a stderr nobody reads)
    try:
        _run(ctx, config_path, sim, record, socket_path, record_mcap, duration,
             pump.put if pump is not None else tell)
    finally:
        if pump is not None:
            pump.close()


def _run(ctx: click.Context, config_path: str | None, sim: bool, record: str | None,
         socket_path: str | None, record_mcap: str | None, duration: float | None,
         tell: Callable[[str], None]) -> None:
    """:func:`command`, saying its lines with ``tell``."""
    cfg = load(ctx, config_path)
    drives = DriveSet(cfg)
    for warning in (*cfg.warnings, *check_bus(cfg, drives)):  # (a bus it cannot work on: raises)
        log.warning("%s", warning)
    for label, prot in drives.protections():
        log.info("controller-side stop of %s: %s", label, prot.describe())
    daemon = Daemon(cfg, sim=sim, record=record, socket_path=socket_path,
                    record_mcap=record_mcap or "")
    bus = daemon.config.bus  # --sim moves the robot onto the virtual bus
    motors = motors_text(cfg)
    if daemon.latch.read() is not None:  # the daemon starts e-stopped (it logs the latch)
        plan = f"{motors} held e-stopped until an enable"
    elif not cfg.loop.enable_on_start:
        plan = f"{motors} disabled until an enable (gateway.enable_on_start: false)"
    else:
        plan = f"enabling {motors}"
    tell(f"wheelgate: {cfg.name} ({cfg.drive}, {cfg.model.n} wheels) at {cfg.loop.rate_hz:g} "
         f"Hz: bus {bus.interface} {bus.channel} open"
         f"{' with simulated controllers' if sim else ''}; {plan}")
    daemon.announce = tell
    remote = daemon.remote
    if remote.bridge is not None:
        tell(f"wheelgate: Zenoh bridge on keys {remote.bridge.keys.root}/..., listening "
             f"on {', '.join(remote.bridge.settings.zenoh.listen) or 'nothing'}")
    if remote.view is not None:
        parts = [f"Foxglove WebSocket on {remote.view.url}"] if remote.view.url else []
        if remote.view.mcap_path:
            parts.append(f"recording to {remote.view.mcap_path}")
        tell(f"wheelgate: live view: {', '.join(parts)}")
    timer = None
    if duration is not None:
        timer = threading.Timer(duration, daemon.request_stop)
        timer.daemon = True
        timer.start()
    try:
        code = daemon.run()
    finally:
        if timer is not None:
            timer.cancel()
    why = f" ({daemon.stop_signal})" if daemon.stop_signal else ""
    unstopped = daemon.gateway.drives.unstopped
    tell(f"wheelgate: stopped{why}; " + (
        f"nothing was sent to the motors: {daemon.left_to}" if daemon.left_to else
        "every motor was sent zero and disarm" if daemon.stop_sent else
        f"no stop could be built for {', '.join(map(repr, unstopped))}: only their "
        "controllers' own timeouts stop them (see the log)" if unstopped else
        "the zero and disarm did NOT all go out: only the controllers' own timeouts stop the "
        "motors (see the log)"))
    ctx.exit(code)
