"""``wheelgate odom``: replay a candump log or a live-view recording through the odometry.

The log is read line by line (a line that cannot be read is reported with its number and
skipped, as is a line whose time stamp is out of time with the lines around it; a jump of the
log's time that the log goes on from is bridged and reported:
:mod:`gateway.apps.replay.timeline`), every frame goes to the drivers the configuration names,
stamped with its recorded time, and the odometry integrates the wheels' positions as the
gateway does (:mod:`gateway.apps.replay.replay`).  Prints the final pose, the distance, what
was read and how fast; ``--csv`` writes the trajectory, ``--plot`` draws it (needs
``wheelgate[plot]``).

Exit status: 0 the replay is printed, also when it went on without something: unreadable
lines, lines out of time, breaks in the log's time and the frames the drivers rejected are
counted in the summary and named in warnings on stderr (``--json`` holds them too), as bad
data in a log that still replays; 2 bad usage, a log that gives no odometry (no readable frame,
or none that the configuration's motors can use: the error says why, the rejected frames
included) or ``--plot`` without matplotlib.

An MCAP file (``wheelgate run --record-mcap``; told by its ``.mcap`` suffix or its magic bytes)
is replayed from its ``/wheels`` and ``/steering`` channels instead
(:mod:`gateway.apps.replay.mcap_source`, needs ``wheelgate[foxglove]``), and its end compared
with the recording's own ``/odom`` (:mod:`gateway.apps.replay.mcap_report`).
"""

from __future__ import annotations

import contextlib
import csv
import importlib
import json
import os
import sys
import time
from typing import IO, TYPE_CHECKING, Any, TextIO, cast

import click

from gateway.apps.replay import candump_report, mcap_report
from gateway.apps.replay.candump_report import MAX_REPORTED
from gateway.apps.replay.mcap_source import McapMissingError, McapReplay, RecordingError, is_mcap
from gateway.apps.replay.replay import Replay
from gateway.cli import FilePath, UsageExit, config_option, json_option
from gateway.cli.commands._common import check_finite, load
from gateway.cli.commands._guards import fail_json

if TYPE_CHECKING:
    from collections.abc import Iterable, Iterator
    from types import ModuleType

    from gateway.apps.replay.mcap_source import McapSummary
    from gateway.apps.replay.replay import ReplaySummary, Sample
    from gateway.core.settings import GatewayConfig

#: Lines between two progress bar updates.
PROGRESS_EVERY = 4096
#: CSV columns before the wheels' speeds.
CSV_COLUMNS = ("time_s", "x_m", "y_m", "theta_rad", "vx_m_s", "vy_m_s", "wz_rad_s", "slip_m_s")
#: The largest --every, --robots and --min-interval-ms (ms: a minute of log time).
MAX_EVERY = 1_000_000
MAX_ROBOTS = 100
MAX_INTERVAL_MS = 60_000.0


def _plotting() -> tuple[ModuleType | None, str | None]:
    """:mod:`gateway.apps.replay.plot`, or ``None`` and why not (matplotlib is missing)."""
    try:
        importlib.import_module("matplotlib")
        return importlib.import_module("gateway.apps.replay.plot"), None
    except ImportError as err:
        return None, f"plotting needs matplotlib ({err}): {install_hint('plot')}"


def install_hint(extra: str) -> str:
    """How to install an optional extra into this very environment: from the clone this
    wheelgate was installed from in editable mode (``pip install -e``: PEP 610's
    ``direct_url.json`` says where), from the package index otherwise."""
    pip = f"{sys.executable} -m pip install"
    try:
        from importlib.metadata import distribution  # noqa: PLC0415 - only on this path

        text = distribution("wheelgate").read_text("direct_url.json")
        origin = json.loads(text) if text else {}
    except (ImportError, ValueError, OSError):
        origin = {}
    url = origin.get("url", "") if isinstance(origin, dict) else ""
    editable = isinstance(origin, dict) and origin.get("dir_info", {}).get("editable")
    if editable and url.startswith("file://"):
        return f"{pip} -e '{url.removeprefix('file://')}[{extra}]'"
    return f"{pip} 'wheelgate[{extra}]'"


def _writable(path: str, option: str) -> None:
    """Fail before the replay if ``path`` cannot be created."""
    folder = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(folder):
        raise click.BadParameter(f"expected a file in an existing directory, got {path!r} "
                                 f"({folder} does not exist)", param_hint=option)
    if not os.access(folder, os.W_OK) or (os.path.exists(path) and not os.access(path, os.W_OK)):
        raise click.BadParameter(f"expected a file that can be written, got {path!r}",
                                 param_hint=option)


def _progress(lines: Iterable[str], bar: Any) -> Iterator[str]:
    """``lines``, advancing ``bar`` by the characters read (bytes, for an ASCII log)."""
    pending = 0
    for count, line in enumerate(lines, start=1):
        pending += len(line)
        if count % PROGRESS_EVERY == 0:
            bar.update(pending)
            pending = 0
        yield line
    bar.update(pending)


class _Tty:
    """A stream that says it is a terminal, for ``--progress`` on one that is not (click
    hides its progress bar otherwise)."""

    def __init__(self, stream: IO[str]) -> None:
        self._stream = stream

    def isatty(self) -> bool:
        return True

    def write(self, text: str) -> int:
        return self._stream.write(text)

    def flush(self) -> None:
        self._stream.flush()


def _wheel_columns(config: GatewayConfig) -> list[str]:
    return [f"{name}_rad_s" for name in config.model.names]


def _row(sample: Sample) -> list[str]:
    p, t = sample.pose, sample.twist
    values = [sample.time_s, p.x_m, p.y_m, p.theta_rad, t.vx_m_s, t.vy_m_s, t.wz_rad_s,
              sample.slip_m_s]
    # ``+ 0.0`` makes a negative zero a zero (IEEE 754: -0.0 + 0.0 is +0.0), nothing else.
    out = [f"{v + 0.0:.9g}" for v in values]
    out[0] = f"{sample.time_s + 0.0:.6f}"
    out.extend("" if w is None else f"{w + 0.0:.6g}" for w in sample.wheel_rad_s)
    return out


@click.command()
@config_option
@click.argument("log_path", metavar="LOG",
                type=FilePath(exists=True, dir_okay=False, readable=True))
@click.option("--csv", "csv_path", type=FilePath(dir_okay=False), default=None,
              help="Write the trajectory: time_s (the log's time stamp; where the log's "
                   "clock was set back, it goes on from the time before), x_m, y_m, "
                   "theta_rad, vx_m_s, vy_m_s, wz_rad_s, slip_m_s, then every wheel's speed "
                   "(rad/s).")
@click.option("--every", type=click.IntRange(min=1, max=MAX_EVERY), default=1,
              show_default=True,
              help="Keep every Nth odometry update (and the last) for --csv and --plot.")
@click.option("--plot", "plot_path", type=FilePath(dir_okay=False), default=None,
              help="Draw the trajectory to this image (PNG); needs wheelgate[plot].")
@click.option("--robots", type=click.IntRange(min=0, max=MAX_ROBOTS), default=8,
              show_default=True,
              help="Robot outlines drawn along the path in --plot.")
@click.option("--min-interval-ms", type=click.FloatRange(min=0.0, max=MAX_INTERVAL_MS),
              default=None,
              help="Least log time between odometry updates, ms (default: the config's "
                   "control period, the gateway's own cadence).")
@click.option("--progress", is_flag=True,
              help="Show a progress bar on stderr even when it is not a terminal.")
@click.option("-q", "--quiet", is_flag=True,
              help="No progress bar and no line-by-line list of unreadable lines, lines out "
                   "of time and breaks in the log's time (the summary counts them).")
@json_option
@click.pass_context
def command(
    ctx: click.Context,
    config_path: str | None,
    log_path: str,
    csv_path: str | None,
    every: int,
    plot_path: str | None,
    robots: int,
    min_interval_ms: float | None,
    progress: bool,
    quiet: bool,
    as_json: bool,
) -> None:
    """Replay a candump LOG (candump -l, wheelgate run --record) through the drivers and the
    odometry: final pose, distance, trajectory.

    Steered wheels take their angles from their steering actuators' feedback when the
    configuration gives every one an actuator; otherwise the log has none: see the summary's
    "steering" line.

    A LOG.mcap (wheelgate run --record-mcap) is replayed from its /wheels angles (and
    /steering) and compared with its own /odom; --min-interval-ms and --progress do not apply
    to it.

    Exit 0: the replay, also with unreadable lines, lines out of time, breaks in the log's time
    or frames the drivers rejected (counted in the summary, named in warnings); 2: bad usage,
    or a log that gives no odometry."""
    if min_interval_ms is not None:
        check_finite(**{"min-interval-ms": min_interval_ms})
    plotting, no_plot = _plotting() if plot_path is not None else (None, None)
    if no_plot is not None:  # the rest is still done: the CSV, the summary
        click.echo(f"warning: --plot: {no_plot}; the replay goes on without the plot", err=True)
    if plot_path is not None:
        _writable(plot_path, "--plot")
    if csv_path is not None:
        _writable(csv_path, "--csv")
    cfg = load(ctx, config_path)
    mcap = is_mcap(log_path)
    replay = None if mcap else Replay(cfg, None if min_interval_ms is None
                                      else min_interval_ms / 1000.0)
    recording = McapReplay(cfg) if mcap else None
    stderr = sys.stderr
    bar_file: TextIO | None = None
    if not quiet and not mcap and (progress or stderr.isatty()):
        bar_file = stderr if stderr.isatty() else cast("TextIO", _Tty(stderr))
    sink = _Sink(every, plotting is not None)
    with contextlib.ExitStack() as stack:
        if csv_path is not None:
            sink.start_csv(stack.enter_context(open(csv_path, "w", newline="", encoding="utf-8")),
                           cfg)
        started = time.perf_counter()
        if recording is not None:
            samples = recording.feed_file(log_path)
        else:
            assert replay is not None
            log_file = stack.enter_context(open(log_path, encoding="ascii", errors="replace"))
            lines: Iterable[str] = log_file
            if bar_file is not None:
                bar = stack.enter_context(click.progressbar(
                    length=os.path.getsize(log_path), label="replaying", file=bar_file))
                lines = _progress(log_file, bar)
            samples = replay.feed_lines(lines)
        try:
            for sample in samples:
                sink.take(sample)
        except McapMissingError as err:
            raise UsageExit(str(err)) from err
        except RecordingError as err:  # not a recording at all: bad input
            raise UsageExit(str(err)) from err
        sink.finish()
        wall = time.perf_counter() - started
    plotted = None
    if plotting is not None and plot_path is not None and sink.kept:
        fig = plotting.plot_trajectory(sink.kept, cfg, robots=robots)
        try:
            plotting.save_figure(fig, plot_path)
        except OSError as err:
            raise click.FileError(plot_path, str(err)) from err
        plotted = plot_path
    if recording is not None:
        _finish_mcap(cfg, log_path, recording.summary(), wall, as_json, csv_path, sink.rows,
                     plotted)
        return
    assert replay is not None
    summary = replay.summary()
    _report_errors(replay, quiet)
    foreign = candump_report.foreign_controllers(cfg, replay, summary.motor_frames)
    if summary.updates == 0:  # a log that does not fit the configuration: bad input
        why = _no_odometry(cfg, log_path, summary, foreign)
        if as_json:
            fail_json(ctx, "no_odometry", UsageExit.exit_code, message=why)
        raise UsageExit(why)
    if as_json:
        click.echo(json.dumps({
            **candump_report.summary_json(cfg, log_path, summary, wall, replay),
            "foreign_controllers": None if foreign is None else {
                "share": foreign.share, "devices": [
                    {"protocol": p, "node_id": n, "frames": c} for p, n, c in foreign.devices]},
            "csv": {"path": csv_path, "rows": sink.rows} if csv_path else None,
            "plot": plotted}))
    else:
        for line in candump_report.summary_lines(cfg, log_path, summary, wall,
                                                 replay.min_interval_s):
            click.echo(line)
        if csv_path is not None:
            click.echo(f"csv: {csv_path} ({sink.rows:,} rows)")
        if plotted is not None:
            click.echo(f"plot: {plotted}")
    for warning in candump_report.warnings(cfg, summary, foreign):
        click.echo(f"warning: {warning}", err=True)
    if no_plot is not None:  # why was said up front
        raise UsageExit(f"--plot {plot_path}: not drawn (see the warning above)")


def _no_odometry(cfg: GatewayConfig, log_path: str, summary: ReplaySummary,
                 foreign: candump_report.Foreign | None) -> str:
    """Why a log gave no odometry, with the controllers it holds that ``cfg`` does not name."""
    if summary.entries == 0:
        return (f"{log_path}: no odometry: no readable frames in the log "
                f"({summary.corrupt_lines:,} unreadable lines); expected a candump log "
                f"(candump -l, wheelgate run --record)")
    why = (f"{log_path}: no odometry: {summary.motor_frames:,} of {summary.entries:,} frames "
           f"belong to {cfg.name}'s motors"
           + (f", none from {', '.join(summary.silent_wheels)}"
              if summary.silent_wheels else ""))
    if summary.rejections:
        why += f"; their drivers rejected {summary.rejected_frames:,} of them (" + "; ".join(
            f"{r.driver}, {r.reason}" + (f": {r.last}" if r.last else "")
            for r in summary.rejections) + ")"
    if foreign is not None:
        named = ", ".join(f"{title} node {node}" for title, node, _ in foreign.devices[:8])
        why += f"; the log's controllers are ones {cfg.name}'s configuration does not name " \
               f"({named}{', ...' if len(foreign.devices) > 8 else ''})"
    return why + " (is it the right config?)"


def _finish_mcap(cfg: GatewayConfig, path: str, s: McapSummary, wall: float, as_json: bool,
                 csv_path: str | None, rows: int, plotted: str | None) -> None:
    """Print a recording's replay (:mod:`gateway.apps.replay.mcap_report`); exit 2 when it
    gave no odometry (a recording that does not fit the configuration, or holds nothing)."""
    if as_json:
        click.echo(json.dumps({**mcap_report.summary_json(cfg, path, s, wall),
                               "csv": {"path": csv_path, "rows": rows} if csv_path else None,
                               "plot": plotted}))
    else:
        for line in mcap_report.summary_lines(cfg, path, s, wall):
            click.echo(line)
        if csv_path is not None:
            click.echo(f"csv: {csv_path} ({rows:,} rows)")
        if plotted is not None:
            click.echo(f"plot: {plotted}")
    for warning in mcap_report.warnings(cfg, path, s):
        click.echo(f"warning: {warning}", err=True)
    why = mcap_report.failure(cfg, path, s)
    if why is not None:
        raise UsageExit(why)


class _Sink:
    """Keeps every Nth update (and the last) for the CSV file and the plot."""

    def __init__(self, every: int, plotting: bool) -> None:
        self.every = every
        self.plotting = plotting
        self.kept: list[Sample] = []
        self.rows = 0
        self._writer: Any = None
        self._count = 0
        self._last: Sample | None = None

    def start_csv(self, stream: IO[str], config: GatewayConfig) -> None:
        self._writer = csv.writer(stream)
        self._writer.writerow([*CSV_COLUMNS, *_wheel_columns(config)])

    def take(self, sample: Sample) -> None:
        if self._count % self.every == 0:
            self._keep(sample)
            self._last = None
        else:
            self._last = sample
        self._count += 1

    def finish(self) -> None:
        if self._last is not None:
            self._keep(self._last)
            self._last = None

    def _keep(self, sample: Sample) -> None:
        if self.plotting:
            self.kept.append(sample)
        if self._writer is not None:
            self._writer.writerow(_row(sample))
            self.rows += 1


def _report_errors(replay: Replay, quiet: bool) -> None:
    """The lines the replay skipped or bridged, the first :data:`MAX_REPORTED` of each kind."""
    if quiet:
        return
    timeline = replay.timeline
    for items, prefix, what in ((replay.errors, "skipped ", "unreadable lines"),
                                (timeline.bad, "skipped ", "lines out of time"),
                                (timeline.breaks, "", "breaks in the log's time")):
        for item in items[:MAX_REPORTED]:
            click.echo(f"warning: {prefix}{item}", err=True)
        if len(items) > MAX_REPORTED:
            click.echo(f"warning: ... and {len(items) - MAX_REPORTED:,} more {what}", err=True)
