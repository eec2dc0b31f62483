"""``wheelgate twist``: send twists to the running daemon."""

from __future__ import annotations

import time

import click

from gateway.cli import EXIT_INFEASIBLE, config_option
from gateway.cli.commands._common import check_finite, socket_for, twist_options
from gateway.runtime.client import ControlClient


@click.command()
@config_option
@twist_options
@click.option("--duration", type=click.FloatRange(min=0.0), default=0.0, show_default=True,
              help="Keep sending for this many seconds, then send stop (0: send once).")
@click.option("--rate", type=click.FloatRange(min=1.0, max=100.0), default=10.0,
              show_default=True, help="How often to send while --duration lasts (Hz).")
@click.option("--socket", "socket_path", type=click.Path(dir_okay=False), default=None,
              help="Control socket of the daemon.")
@click.pass_context
def command(
    ctx: click.Context,
    config_path: str | None,
    vx: float,
    vy: float,
    wz: float,
    duration: float,
    rate: float,
    socket_path: str | None,
) -> None:
    """Send a twist to the running gateway (repeating while --duration lasts)."""
    check_finite(vx=vx, vy=vy, wz=wz)
    path = socket_for(ctx, config_path, socket_path)
    with ControlClient(path) as client:
        end = time.monotonic() + duration
        period = 1.0 / rate
        while True:
            reply = client.request({"op": "twist", "vx": vx, "vy": vy, "wz": wz})
            if not reply.get("ok"):
                error = reply.get("error") or {}
                click.echo(f"Error: {error.get('message', reply)}", err=True)
                code = error.get("code")
                ctx.exit(EXIT_INFEASIBLE if code == "infeasible_twist" else 1)
            if reply.get("warning"):
                click.echo(f"warning: {reply['warning']}", err=True)
            if time.monotonic() + period > end:
                break
            time.sleep(period)
        if duration > 0:
            client.request({"op": "stop"})
    applied = reply.get("twist")
    click.echo(f"ok: following {applied}")
