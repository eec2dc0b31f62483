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
put in the configuration; nothing is written.

Exit status: 0 fitted; 2 bad usage, a log without odometry, or factors outside 0.5 to 2 (a
measurement in the wrong unit or the wrong frame, most likely).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import click
import yaml

from gateway.apps.calibrate.fit import fit
from gateway.apps.calibrate.runs import end_poses, factors_of, read_run, residual
from gateway.cli import config_option
from gateway.cli.commands._common import load
from gateway.config.keys import MAX_MULTIPLIER, MIN_MULTIPLIER
from gateway.core.errors import ConfigError
from gateway.core.kinematics import Pose

if TYPE_CHECKING:
    from gateway.apps.calibrate.runs import Factors, Run
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
@click.argument("runs", metavar="LOG=X,Y,THETA...", nargs=-1, required=True)
@click.pass_context
def command(ctx: click.Context, config_path: str | None, accuracy_mm: float,
            runs: tuple[str, ...]) -> None:
    """Fit the kinematics: block's factors to logs whose end pose was measured."""
    given = [_measured(item) for item in runs]
    cfg = load(ctx, config_path)
    factors = factors_of(cfg)
    read = []
    for path, pose in given:
        try:
            with open(path, encoding="ascii", errors="replace") as f:
                read.append(read_run(cfg, path, f, pose))
        except OSError as err:
            raise click.UsageError(f"{path}: cannot read the log: {err.strerror}") from err
        except ConfigError as err:
            raise click.UsageError(str(err)) from err
    result = fit(lambda v: residual(cfg, factors, v, read), len(factors.names),
                 accuracy_mm / 1e3)
    total = _totals(cfg, factors, result.factors)
    _report(cfg, read, factors, result.factors)
    click.echo(f"fit: end poses {_rms_mm(result.before):.1f} mm RMS from the measured -> "
               f"{_rms_mm(result.after):.1f} mm (headings weighted by the robot's size, "
               f"{cfg.model.rho:g} m), {result.steps} step(s)")
    for (name, before, after), sigma in zip(total, result.uncertainty, strict=True):
        click.echo(f"  {name:<40} {before:.4f} -> {after:.4f} +- {before * sigma:.4f}")
    short = [*factors.wheels, *(("separation",) if factors.separation else ())]
    for v in result.undetermined:
        terms = " + ".join(f"{c:.2f} {n}" for c, n in zip(v, short, strict=True)
                           if abs(c) >= 0.005)
        click.echo(f"not told by these runs, left as it was: {terms} (a 1 % change moves the "
                   f"ends less than the {accuracy_mm:g} mm accuracy; add a run that changes "
                   f"with it: a straight run of measured length tells the overall size)")
    bad = [f"{n} {a:.4f}" for n, _, a in total if not MIN_MULTIPLIER <= a <= MAX_MULTIPLIER]
    if bad:
        raise click.UsageError(
            f"the runs ask for {', '.join(bad)}, outside {MIN_MULTIPLIER:g} to "
            f"{MAX_MULTIPLIER:g}: check the measured poses (metres and degrees, in the start "
            f"pose's frame: x forward, y left) and that each log is the run measured")
    fitted = [round(a, 4) for _, _, a in total]
    block: dict[str, object] = {}
    if factors.separation:
        block["wheel_separation_multiplier"] = fitted[-1]
    block["wheel_radius_multipliers"] = dict(zip(factors.wheels, fitted, strict=False))
    click.echo("# fitted by wheelgate calibrate: the kinematics: block of the configuration")
    click.echo(yaml.safe_dump({"kinematics": block}, sort_keys=False,
                              default_flow_style=None).rstrip())


def _totals(cfg: GatewayConfig, factors: Factors, values: tuple[float, ...]
            ) -> list[tuple[str, float, float]]:
    """Each factor's key, as configured and as fitted (the fit on top of the file's own)."""
    keys = [f"radius {w}" for w in factors.wheels]
    keys += ["wheel_separation_multiplier"] if factors.separation else []
    return [(name, cfg.calibration.get(key, 1.0), cfg.calibration.get(key, 1.0) * value)
            for name, key, value in zip(factors.names, keys, values, strict=True)]


def _report(cfg: GatewayConfig, runs: list[Run], factors: Factors,
            values: tuple[float, ...]) -> None:
    """Per run: where the odometry ends as configured, as fitted, and the measured end."""
    now = end_poses(cfg, factors, [1.0] * len(values), runs)
    fitted = end_poses(cfg, factors, values, runs)
    width = max(len(r.name) for r in runs)
    click.echo(f"{'run':<{width}}  {'end pose (x m, y m, theta deg)':>28}")
    for run, a, b in zip(runs, now, fitted, strict=True):
        click.echo(f"{run.name:<{width}}  measured  {_pose(run.measured)}")
        click.echo(f"{'':<{width}}  odometry  {_pose(a)}   as configured")
        click.echo(f"{'':<{width}}  odometry  {_pose(b)}   as fitted")
