"""``wheelgate calibrate``: fit the odometry's calibration factors to runs measured on the floor.

Each run is a log of the robot driving from a marked start (``wheelgate run --record
run.log``, driven with ``twist`` or ``jog``) and where it ended, measured in the start pose's
frame: ``run.log=X,Y,THETA`` (metres forward and to the left, degrees counter-clockwise).  The
factors are those of the ``kinematics:`` block (every driven wheel's radius, and the track's
on a preset drive with a track), fitted so the odometry ends each run where it was measured
to end (:mod:`gateway.apps.calibrate`).  Good runs, as Borenstein and Feng's UMBmark has them
(*Measurement and correction of systematic odometry errors in mobile robots*, IEEE
Transactions on Robotics and Automation 12(6), 1996): a square clockwise and one
counter-clockwise (they tell the wheels' size ratio and the track), and a straight run of a
measured length (the overall size).  A combination the runs do not tell is left as it was and
named.  Prints the end poses before and after, the factors, and the ``kinematics:`` block to
put in the configuration; nothing is written.  With ``--json`` one object: ``{"ok": true,
"runs", "rms_mm", "factors", "undetermined", "kinematics"}``, or a failure as every command's
(``{"ok": false, "error": {"code", "message"}}``).

Exit status: 0 fitted; 2 bad usage, a log without odometry, or factors outside 0.5 to 2 (a
measurement in the wrong unit or the wrong frame, most likely).
"""

from __future__ import annotations

import json
import math
from typing import TYPE_CHECKING

import click
import yaml

from gateway.apps.calibrate.fit import fit
from gateway.apps.calibrate.runs import end_poses, factors_of, own_radii, read_run, residual
from gateway.apps.replay.mcap_source import is_mcap
from gateway.cli import config_option, json_option
from gateway.cli.commands._common import json_failures, load
from gateway.config.keys import MAX_MULTIPLIER, MIN_MULTIPLIER
from gateway.core.errors import ConfigError
from gateway.core.kinematics.odometry import Pose

if TYPE_CHECKING:
    from gateway.apps.calibrate.runs import Run
    from gateway.core.settings import GatewayConfig

#: The largest measured distance a run may end at, m (a bound, as every number has one).
MAX_END_M = 1000.0


def _measured(item: str) -> tuple[str, Pose]:
    """``LOG=X,Y,THETA`` as the log's path and the pose (theta in degrees)."""
    path, sep, numbers = item.rpartition("=")
    parts = numbers.split(",")
    try:
        values = [float(p) for p in parts]
    except ValueError:
        values = []
    if (not sep or not path or len(values) != 3 or not all(map(math.isfinite, values))
            or max(abs(values[0]), abs(values[1])) > MAX_END_M or abs(values[2]) > 360.0):
        raise click.BadParameter(
            f"expected LOG=X,Y,THETA (the end pose measured in the start pose's frame: metres "
            f"forward and left within +-{MAX_END_M:g}, degrees counter-clockwise within "
            f"+-360), got {item!r}", param_hint="RUN")
    return path, Pose(values[0], values[1], math.radians(values[2]))


def _pose(pose: Pose) -> str:
    return (f"{pose.x_m:+9.4f} {pose.y_m:+9.4f} {math.degrees(pose.theta_rad):+8.2f}")


def _rms_mm(r: tuple[float, ...]) -> float:
    return 1e3 * math.sqrt(sum(v * v for v in r) / len(r)) if r else 0.0


@click.command()
@config_option
@click.option("--accuracy", "accuracy_mm", type=click.FloatRange(0.1, 1000.0), default=5.0,
              show_default=True,
              help="how well the end poses were measured, mm (a heading: times the robot's size)")
@json_option
@click.argument("runs", metavar="LOG=X,Y,THETA...", nargs=-1, required=True)
@click.pass_context
def command(ctx: click.Context, config_path: str | None, accuracy_mm: float, as_json: bool,
            runs: tuple[str, ...]) -> None:
    """Fit the kinematics: block's factors to logs whose end pose was measured."""
    with json_failures(ctx, as_json):
        given = [_measured(item) for item in runs]
        cfg = load(ctx, config_path)
        factors = factors_of(cfg)
        read = [_read(cfg, path, pose) for path, pose in given]
        result = fit(lambda v: residual(cfg, factors, v, read), len(factors.names),
                     accuracy_mm / 1e3)
        total = [(name, own, own * value) for name, own, value
                 in zip(factors.names, factors.configured(cfg), result.factors, strict=True)]
        fitted = [round(a, 4) for _, _, a in total]
        block: dict[str, object] = {}
        if factors.separation:
            block["wheel_separation_multiplier"] = fitted[-1]
        radii = own_radii(cfg)  # (a passive wheel's kept)
        radii.update(zip(factors.wheels, fitted, strict=False))
        block["wheel_radius_multipliers"] = {w.name: radii[w.name] for w in cfg.model.wheels
                                             if w.name in radii}
        ends = (end_poses(cfg, factors, [1.0] * len(total), read),
                end_poses(cfg, factors, result.factors, read))
        bad = [f"{n} {a:.4f}" for n, _, a in total if not MIN_MULTIPLIER <= a <= MAX_MULTIPLIER]
        if bad and as_json:
            raise _out_of_range(bad)
    if as_json:
        click.echo(json.dumps({
            "ok": True,
            "runs": [{"log": r.name, "measured": _pose_json(r.measured),
                      "as_configured": _pose_json(a), "as_fitted": _pose_json(b)}
                     for r, a, b in zip(read, *ends, strict=True)],
            "rms_mm": {"before": _rms_mm(result.before), "after": _rms_mm(result.after)},
            "factors": [{"key": n, "configured": b, "fitted": a, "sigma": b * sd}
                        for (n, b, a), sd in zip(total, result.uncertainty, strict=True)],
            "undetermined": [dict(zip(factors.labels, v, strict=True))
                             for v in result.undetermined],
            "kinematics": block,
        }))
        return
    _report(read, *ends)
    click.echo(f"fit: end poses {_rms_mm(result.before):.1f} mm RMS from the measured -> "
               f"{_rms_mm(result.after):.1f} mm (headings weighted by the robot's size, "
               f"{cfg.model.rho:g} m), {result.steps} step(s)")
    for (name, before, after), sigma in zip(total, result.uncertainty, strict=True):
        click.echo(f"  {name:<40} {before:.4f} -> {after:.4f} +- {before * sigma:.4f}")
    for v in result.undetermined:
        terms = " + ".join(f"{c:.2f} {n}" for c, n in zip(v, factors.labels, strict=True)
                           if abs(c) >= 0.005)
        click.echo(f"not told by these runs, left as it was: {terms} (a 1 % change moves the "
                   f"ends less than the {accuracy_mm:g} mm accuracy; add a run that changes "
                   f"with it: a straight run of measured length tells the overall size)")
    if bad:
        raise _out_of_range(bad)
    click.echo("# fitted by wheelgate calibrate: these keys in the configuration's kinematics: "
               "block (its other keys as they are)")
    click.echo(yaml.safe_dump({"kinematics": block}, sort_keys=False,
                              default_flow_style=None).rstrip())


def _read(cfg: GatewayConfig, path: str, pose: Pose) -> Run:
    """One run's log, read (a file that cannot be read: a usage error naming it)."""
    if is_mcap(path):
        raise click.UsageError(f"{path}: expected a candump log (`wheelgate run --record`, "
                               f"`candump -l`), got an MCAP recording, which calibrate does "
                               f"not read")
    try:
        with open(path, encoding="ascii", errors="replace") as f:
            return read_run(cfg, path, f, pose)
    except OSError as err:
        raise click.UsageError(f"{path}: cannot read the log: {err.strerror}") from err
    except ConfigError as err:
        raise click.UsageError(str(err)) from err


def _out_of_range(bad: list[str]) -> click.UsageError:
    return click.UsageError(
        f"the runs ask for {', '.join(bad)}, outside {MIN_MULTIPLIER:g} to "
        f"{MAX_MULTIPLIER:g}: check the measured poses (metres and degrees, in the start "
        f"pose's frame: x forward, y left) and that each log is the run measured")


def _pose_json(pose: Pose) -> dict[str, float]:
    return {"x_m": pose.x_m, "y_m": pose.y_m, "theta_deg": math.degrees(pose.theta_rad)}


def _report(runs: list[Run], now: list[Pose], fitted: list[Pose]) -> None:
    """Per run: the measured end, and where the odometry ends as configured and as fitted."""
    width = max(len(r.name) for r in runs)
    click.echo(f"{'run':<{width}}  {'end pose (x m, y m, theta deg)':>28}")
    for run, a, b in zip(runs, now, fitted, strict=True):
        click.echo(f"{run.name:<{width}}  measured  {_pose(run.measured)}")
        click.echo(f"{'':<{width}}  odometry  {_pose(a)}   as configured")
        click.echo(f"{'':<{width}}  odometry  {_pose(b)}   as fitted")
