"""``wheelgate fk``: body twist from wheel speeds (and steering angles)."""

from __future__ import annotations

import json
import math

import click

from gateway.cli import config_option, json_option
from gateway.cli.commands._common import load, twist_json
from gateway.core.errors import KinematicsError
from gateway.core.numfmt import fixed, short


def _pairs(values: tuple[str, ...], option: str) -> dict[str, float]:
    out: dict[str, float] = {}
    for item in values:
        name, sep, number = item.partition("=")
        try:
            value = float(number)
        except ValueError:
            value = math.nan
        if not sep or not name or not math.isfinite(value):
            raise click.BadParameter(
                f"expected NAME=NUMBER with a finite number, got {item!r}", param_hint=option
            )
        if name in out:
            raise click.BadParameter(f"wheel {name!r} given twice", param_hint=option)
        out[name] = value
    return out


@click.command()
@config_option
@click.option("--wheel", "wheels", multiple=True, metavar="NAME=RAD_S",
              help="A wheel's angular speed in rad/s (repeat for each wheel).")
@click.option("--steer", "steers", multiple=True, metavar="NAME=RAD",
              help="A steered wheel's steering angle in rad.")
@json_option
@click.pass_context
def command(
    ctx: click.Context,
    config_path: str | None,
    wheels: tuple[str, ...],
    steers: tuple[str, ...],
    as_json: bool,
) -> None:
    """Forward kinematics: the body twist (least squares) and the slip residual."""
    cfg = load(ctx, config_path)
    model = cfg.model
    speeds: list[float | None] = [None] * model.n
    for name, value in _pairs(wheels, "--wheel").items():
        try:
            speeds[model.index(name)] = value
        except ValueError as err:
            raise click.BadParameter(str(err), param_hint="--wheel") from err
    steer = list(model.neutral_steer)
    for name, value in _pairs(steers, "--steer").items():
        try:
            i = model.index(name)
        except ValueError as err:
            raise click.BadParameter(str(err), param_hint="--steer") from err
        if steer[i] is None:
            raise click.BadParameter(f"wheel {name!r} is not steered", param_hint="--steer")
        steer[i] = value
    if all(s is None for s in speeds):
        raise click.BadParameter("give at least one wheel speed", param_hint="--wheel")
    try:
        result = model.fk(speeds, steer)
    except KinematicsError as err:
        # Too few wheels to fix the twist: a usage error that names what is missing.
        missing = [w.name for w, s in zip(model.wheels, speeds, strict=True) if s is None]
        raise click.BadParameter(f"{err}; not given: {', '.join(missing)}",
                                 param_hint="--wheel") from err
    if as_json:
        click.echo(json.dumps({
            "twist": twist_json(result.twist),
            "residual_m_s": result.residual_m_s,
            "wheels": [
                {"name": w.name, "residual_m_s": r}
                for w, r, s in zip(model.wheels, result.wheel_residual_m_s, speeds, strict=True)
                if s is not None
            ],
        }))
        return
    click.echo(f"twist: {result.twist}")
    click.echo(f"residual: {short(result.residual_m_s, 6)} m/s (RMS over rolling and sliding "
               "equations)")
    for w, r, s in zip(model.wheels, result.wheel_residual_m_s, speeds, strict=True):
        if s is not None:
            click.echo(f"  {w.name:<12} measured {fixed(s, 4, sign=True)} rad/s, residual "
                       f"{short(r, 6, sign=True)} m/s")
