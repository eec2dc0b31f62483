"""``wheelgate ik``: wheel speeds and steering angles for a twist.

With ``--json`` every outcome is one JSON object on stdout: ``{"ok": true, "twist", "wheels",
"speed_scale"}``, or a failure, ``{"ok": false, "error": {"code", "message", ...}}``
(:func:`~gateway.cli.commands._common.json_failures`; an infeasible twist: exit 3, ``"code":
"infeasible_twist"`` with the wheel, constraint, residual and nearest twist).
"""

from __future__ import annotations

import json
import math
from typing import Any

import click

from gateway.cli import config_option, json_option
from gateway.cli.commands._common import (
    check_finite,
    json_failures,
    load,
    rad_s_to_rpm,
    twist_json,
    twist_options,
)
from gateway.core.kinematics.limits import speed_scale
from gateway.core.numfmt import fixed, short
from gateway.core.types import Twist
from gateway.drive.driveset import DriveSet


@click.command()
@config_option
@twist_options
@json_option
@click.pass_context
def command(
    ctx: click.Context,
    config_path: str | None,
    vx: float,
    vy: float,
    wz: float,
    as_json: bool,
) -> None:
    """Inverse kinematics: per wheel its speed (rad/s, wheel and motor RPM) and steering."""
    twist = Twist(vx, vy, wz)
    with json_failures(ctx, as_json):
        check_finite(vx=vx, vy=vy, wz=wz)
        cfg = load(ctx, config_path)
        result = cfg.model.ik(twist)
        scale = speed_scale(cfg.model, result, cfg.limits)
        bands = DriveSet(cfg).uncontrolled_bands()
    rows: list[dict[str, Any]] = []
    for i, w in enumerate(cfg.model.wheels):
        speed = result.wheel_rad_s[i]
        motor = cfg.motors[i]
        row: dict[str, Any] = {
            "name": w.name,
            "speed_rad_s": speed,
            "wheel_rpm": rad_s_to_rpm(speed),
            "motor_rpm": None if motor is None else rad_s_to_rpm(motor.wheel_to_motor_rad_s(speed)),
        }
        if result.steer_rad[i] is not None:
            row["steer_rad"] = result.steer_rad[i]
        if result.steer_rate_rad_s[i] is not None:
            row["steer_rate_rad_s"] = result.steer_rate_rad_s[i]
        band = bands[i]
        if band is not None and band[0] < abs(speed) < band[1]:
            row["not_speed_controlled"] = {"below_rad_s": band[1]}
        rows.append(row)
    if as_json:
        click.echo(json.dumps({"ok": True, "twist": twist_json(twist), "wheels": rows,
                               "speed_scale": scale}))
        return
    click.echo(f"twist: {twist}")
    click.echo(
        f"  {'wheel':<12} {'rad/s':>10} {'wheel rpm':>10} {'motor rpm':>10}  steer"
    )
    for row in rows:
        motor_rpm = "passive" if row["motor_rpm"] is None else fixed(row["motor_rpm"], 2)
        steer = ""
        if "steer_rad" in row:
            steer = (f"{fixed(row['steer_rad'], 4, sign=True)} rad "
                     f"({fixed(math.degrees(row['steer_rad']), 1, sign=True)} deg)")
        if "steer_rate_rad_s" in row:
            steer += f", swivel {fixed(row['steer_rate_rad_s'], 4, sign=True)} rad/s"
        click.echo(
            f"  {row['name']:<12} {fixed(row['speed_rad_s'], 4):>10} "
            f"{fixed(row['wheel_rpm'], 2):>10} {motor_rpm:>10}  {steer}".rstrip()
        )
    for row, w in zip(rows, cfg.model.wheels, strict=True):
        if "not_speed_controlled" in row:
            high = row["not_speed_controlled"]["below_rad_s"]
            at = short(abs(row["speed_rad_s"]), 4)
            click.echo(
                f"note: wheel {row['name']!r} at {at} rad/s is below "
                f"its controller's slowest controlled speed ({high:.4g} rad/s, "
                f"{high * w.radius:.3g} m/s): not "
                f"speed-controlled, the controller stops the motor instead"
            )
    if scale < 1.0:
        click.echo(
            f"note: this twist exceeds a speed limit; the gateway scales it by {scale:.4f} "
            f"to {twist.scaled(scale)}"
        )
