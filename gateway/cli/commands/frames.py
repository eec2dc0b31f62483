"""``wheelgate frames``: the command frames for a twist (wheel speeds, and steering angles for
steering actuators), in cansend syntax."""

from __future__ import annotations

import click

from gateway.cli import config_option
from gateway.cli.commands._common import check_finite, load, twist_options
from gateway.core.kinematics import apply_limits
from gateway.core.types import Twist
from gateway.drive.driveset import DriveSet

#: Drivers whose command frames depend on measured feedback.
_FEEDBACK_DEPENDENT = {"dji": "current for zero measured speed and an empty integrator"}


@click.command()
@config_option
@twist_options
@click.pass_context
def command(ctx: click.Context, config_path: str | None, vx: float, vy: float, wz: float) -> None:
    """Print the command frames for a twist, one per line, as can-utils cansend takes them
    (8 hex digits for extended IDs, R for remote frames): the wheels' speeds, then the
    steering actuators' angles."""
    check_finite(vx=vx, vy=vy, wz=wz)
    cfg = load(ctx, config_path)
    result, report = apply_limits(cfg.model, cfg.model.ik(Twist(vx, vy, wz)), cfg.limits)
    drives = DriveSet(cfg)
    for frame in drives.preview(result.wheel_rad_s, result.steer_rad):
        click.echo(frame.to_cansend())
    if report.speed_scale < 1.0:
        click.echo(
            f"note: speed limits scale this twist by {report.speed_scale:.4f} "
            f"to {result.twist}",
            err=True,
        )
    for name in sorted({m.driver for m in cfg.motors if m is not None}):
        if name in _FEEDBACK_DEPENDENT:
            click.echo(f"note: {name} frames show the {_FEEDBACK_DEPENDENT[name]}", err=True)
