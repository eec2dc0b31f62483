"""``wheelgate fk``: body twist from wheel speeds (and steering angles).

Every number is bounded (exit 2 naming the wheel, what was expected and what came): a driven
wheel's speed by its motor's ``max_rpm`` at the wheel (through the gear ratio), a passive
wheel's by a rim speed of ``MAX_TWIST_COMPONENT`` m/s (the bound of a twist's component); a
steering angle by the wheel's range, ``steer_min`` to ``steer_max`` (not wrapped: an angle
outside it is no angle the wheel can have).  A wheel not given, when the others fix the twist,
and a steered wheel given without ``--steer`` (taken at 0 rad) are noted on stderr and, with
``--json``, in ``not_given`` and ``steer_taken_as_zero``.

With ``--json`` every outcome is one JSON object on stdout: ``{"ok": true, "twist", ...}``, or
a failure, ``{"ok": false, "error": {"code", "message"}}`` with the exit code it has without
(:func:`~gateway.cli.commands._common.json_failures`).
"""

from __future__ import annotations

import json
import math
from typing import TYPE_CHECKING

import click

from gateway.cli import config_option, json_option
from gateway.cli.commands._common import json_failures, load, twist_json
from gateway.core.errors import KinematicsError
from gateway.core.kinematics.feasibility import LIMIT_SLACK
from gateway.core.numfmt import fixed, short
from gateway.core.types import MAX_TWIST_COMPONENT

if TYPE_CHECKING:
    from gateway.core.settings import GatewayConfig


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


def _check_speed(cfg: GatewayConfig, i: int, value: float) -> None:
    """A wheel speed within the wheel's bound (see the module docstring).

    :raises click.BadParameter: naming the wheel, the bound and the value.
    """
    w, motor = cfg.model.wheels[i], cfg.motors[i]
    if motor is not None:
        cap = motor.max_wheel_rad_s
        why = (f"its motor's max_rpm {short(motor.max_rpm, 3)} through gear ratio "
               f"{short(motor.gear_ratio, 4)}")
    else:
        cap = MAX_TWIST_COMPONENT / w.radius
        why = f"a rim speed of {MAX_TWIST_COMPONENT:g} m/s, the bound of a twist"
    if abs(value) > cap * (1.0 + 1e-9):
        raise click.BadParameter(
            f"wheel {w.name!r}: expected a speed of at most {short(cap, 4)} rad/s either way "
            f"({why}), got {value:g}", param_hint="--wheel")


def _check_steer(cfg: GatewayConfig, i: int, value: float) -> None:
    """A steering angle within the wheel's range (see the module docstring).

    :raises click.BadParameter: naming the wheel, the range and the value.
    """
    w = cfg.model.wheels[i]
    if not w.steer_min - LIMIT_SLACK <= value <= w.steer_max + LIMIT_SLACK:
        raise click.BadParameter(
            f"wheel {w.name!r}: expected a steering angle from {short(w.steer_min, 4)} to "
            f"{short(w.steer_max, 4)} rad (its steer_min to steer_max), got {value:g}",
            param_hint="--steer")


def _inputs(cfg: GatewayConfig, wheels: tuple[str, ...], steers: tuple[str, ...]
            ) -> tuple[list[float | None], list[float | None], set[int]]:
    """The wheel speeds and steering angles given (each checked, see the module), and which
    steering angles were given.

    :raises click.BadParameter: naming the option, what it expects and what came.
    """
    model = cfg.model
    speeds: list[float | None] = [None] * model.n
    for name, value in _pairs(wheels, "--wheel").items():
        try:
            i = model.index(name)
        except ValueError as err:
            raise click.BadParameter(str(err), param_hint="--wheel") from err
        _check_speed(cfg, i, value)
        speeds[i] = value
    steer = list(model.neutral_steer)
    given_steer: set[int] = set()
    for name, value in _pairs(steers, "--steer").items():
        try:
            i = model.index(name)
        except ValueError as err:
            raise click.BadParameter(str(err), param_hint="--steer") from err
        if steer[i] is None:
            raise click.BadParameter(f"wheel {name!r} is not steered", param_hint="--steer")
        _check_steer(cfg, i, value)
        steer[i] = value
        given_steer.add(i)
    if all(s is None for s in speeds):
        raise click.BadParameter("give at least one wheel speed", param_hint="--wheel")
    return speeds, steer, given_steer


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
    with json_failures(ctx, as_json):
        cfg = load(ctx, config_path)
        speeds, steer, given_steer = _inputs(cfg, wheels, steers)
        missing = [w.name for w, s in zip(cfg.model.wheels, speeds, strict=True) if s is None]
        try:
            result = cfg.model.fk(speeds, steer)
        except KinematicsError as err:
            # Too few wheels to fix the twist: a usage error that names what is missing.
            text = str(err)
            raise click.BadParameter(f"{text[:1].lower()}{text[1:]}; not given: "
                                     f"{', '.join(missing)}", param_hint="--wheel") from err
    model = cfg.model
    zeroed = [w.name for i, w in enumerate(model.wheels)
              if steer[i] is not None and speeds[i] is not None and i not in given_steer]
    if missing:
        click.echo(f"note: not given: {', '.join(missing)} (the twist is from the other "
                   f"wheels, which fix it)", err=True)
    if zeroed:
        click.echo(f"note: no --steer for {', '.join(zeroed)}: steering angle taken as 0 rad",
                   err=True)
    if as_json:
        click.echo(json.dumps({
            "ok": True,
            "twist": twist_json(result.twist),
            "residual_m_s": result.residual_m_s,
            "wheels": [
                {"name": w.name, "residual_m_s": r}
                for w, r, s in zip(model.wheels, result.wheel_residual_m_s, speeds, strict=True)
                if s is not None
            ],
            "not_given": missing,
            "steer_taken_as_zero": zeroed,
        }))
        return
    click.echo(f"twist: {result.twist}")
    click.echo(f"residual: {short(result.residual_m_s, 6)} m/s (RMS over rolling and sliding "
               "equations)")
    for w, r, s in zip(model.wheels, result.wheel_residual_m_s, speeds, strict=True):
        if s is not None:
            click.echo(f"  {w.name:<12} measured {fixed(s, 4, sign=True)} rad/s, residual "
                       f"{short(r, 6, sign=True)} m/s")
