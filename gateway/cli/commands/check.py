"""``wheelgate check``: validate a configuration and summarise the robot."""

from __future__ import annotations

import math

import click

from gateway.bus.link import link_warnings
from gateway.cli import config_option
from gateway.cli.commands._common import load, rad_s_to_rpm
from gateway.config.budget import bus_budget, check_bus
from gateway.core.kinematics import PRESETS
from gateway.core.numfmt import fixed, short
from gateway.drive.driveset import DriveSet


def _num(value: float) -> str:
    return "-" if math.isinf(value) else f"{value:.4g}"


@click.command()
@config_option
@click.pass_context
def command(ctx: click.Context, config_path: str | None) -> None:
    """Validate a configuration and print a summary of the robot."""
    from can.interfaces import VALID_INTERFACES  # noqa: PLC0415 - only check pays for it

    cfg = load(ctx, config_path, VALID_INTERFACES)  # the interface among every problem
    drives = DriveSet(cfg)
    warnings = [*cfg.warnings, *check_bus(cfg, drives)]  # (a bus it cannot work on: an error)
    if cfg.bus.interface == "socketcan":  # the interface as this machine has it, if it has it
        warnings += link_warnings(cfg.bus.channel, cfg.bus.bitrate)
    model = cfg.model
    mob = model.mobility
    click.echo(f"config:   {cfg.source}")
    click.echo(f"robot:    {cfg.name}")
    geometry = " ".join(f"{k}={v}" for k, v in cfg.geometry.items())
    click.echo(f"drive:    {cfg.drive}" + (f" ({geometry})" if geometry else ""))
    if cfg.drive in PRESETS:
        click.echo(f"follows:  {PRESETS[cfg.drive].summary}")
    click.echo(
        f"freedom:  mobility {mob.mobility}, steerability {mob.steerability}, "
        f"maneuverability {mob.maneuverability}"
    )
    click.echo(f"slip tolerance: {model.slip_tolerance_m_s:g} m/s")
    click.echo("wheels:")
    header = (
        f"  {'name':<12} {'type':<9} {'alpha':>7} {'l':>7} {'beta':>7} {'radius':>7} "
        f"{'gamma':>7} {'d':>6}  {'steer (rate)':<26} motor"
    )
    click.echo(header)
    for w, m in zip(model.wheels, cfg.motors, strict=True):
        steer = f"[{short(w.steer_min, 2)}, {short(w.steer_max, 2)}]" if w.steered else "-"
        if w.steered and math.isfinite(w.max_steer_rate):
            steer += f" {w.max_steer_rate:.3g} rad/s"
        motor = (
            "passive"
            if m is None
            else f"{m.driver} node {m.node_id}, gear {m.gear_ratio:g}, "
            f"max {m.max_rpm:g} rpm ({rad_s_to_rpm(m.max_wheel_rad_s):.4g} rpm at the wheel)"
            + (", inverted" if m.invert else "")
        )
        click.echo(
            f"  {w.name:<12} {w.type.value:<9} {fixed(w.alpha, 4):>7} {fixed(w.l, 4):>7} "
            f"{fixed(w.beta, 4):>7} {fixed(w.radius, 4):>7} {fixed(w.gamma, 4):>7} "
            f"{fixed(w.d, 3):>6}  {steer:<26} {motor}"
        )
    if cfg.steering:
        click.echo("steering:")
    for a in cfg.steering:
        rate = rad_s_to_rpm(a.max_wheel_rad_s)  # through gear_ratio: of the wheel's plane
        click.echo(
            f"  {', '.join(a.steers)}: {a.driver} node {a.node_id}, gear {a.gear_ratio:g}, "
            f"zero at {a.zero_rad:g} rad, max {a.max_rpm:g} rpm ({rate:.4g} rpm of the wheel's "
            f"plane)" + (", inverted" if a.invert else "")
            + (", through an Ackermann linkage" if a.linkage == "ackermann" else "")
        )
    if cfg.calibration:
        click.echo("calibration: " + ", ".join(f"{k} x{v:g}" for k, v in cfg.calibration.items())
                   + " (applied to the wheels above)")
    lim = cfg.limits
    decel = ("" if lim.max_wheel_decel_rad_s2 is None
             else f" (decel {_num(lim.max_wheel_decel_rad_s2)})")
    click.echo(
        f"limits:   wheel accel {_num(lim.max_wheel_accel_rad_s2)} rad/s^2{decel}, "
        f"linear {_num(lim.max_linear_m_s)} m/s, angular {_num(lim.max_angular_rad_s)} rad/s"
    )
    click.echo(f"bus:      {cfg.bus.interface}:{cfg.bus.channel} at {cfg.bus.bitrate} bit/s")
    budget = bus_budget(cfg, drives)
    click.echo(f"bus load: {budget.summary()}, nominal to worst-case bit stuffing; periodic "
               f"frames:")
    for line in budget.lines():
        click.echo(f"  {line}")
    click.echo(
        f"controller-side stop when wheelgate dies (controller_watchdog: "
        f"{cfg.loop.controller_watchdog.value}):"
    )
    for label, prot in drives.protections():
        click.echo(f"  {label}: {prot.describe()}")
    for w, band in zip(cfg.model.wheels, drives.uncontrolled_bands(), strict=True):
        if band is not None:
            click.echo(
                f"note:     wheel {w.name!r}: |speed| below {band[1]:.4g} rad/s "
                f"({band[1] * w.radius:.3g} m/s) is not speed-controlled by its controller "
                f"(it stops the motor instead); the gateway sends such commands as they are, "
                f"counts them and expects the wheel stopped"
            )
    for warning in warnings:
        click.echo(f"warning:  {warning}")
    click.echo("ok" if not warnings else f"ok, with {len(warnings)} warning(s)")
