"""``wheelgate twist``: send twists to the running daemon.

With ``--duration``, SIGINT (Ctrl-C), SIGTERM and SIGHUP end the repetition early, as its end
would: stop is sent, and the command says so on stderr (exit code 0).
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING

import click

from gateway.cli import EXIT_INFEASIBLE, FilePath, config_option
from gateway.cli.commands._common import (
    check_finite,
    refuse_other_robot,
    socket_for,
    twist_options,
)
from gateway.cli.commands._guards import MAX_DURATION_S, caught_signals
from gateway.core.numfmt import short
from gateway.runtime.client import ControlClient

if TYPE_CHECKING:
    from collections.abc import Mapping

#: The longest a caught signal waits for the loop to notice it (s).
SIGNAL_LATENCY_S = 0.05


@click.command()
@config_option
@twist_options
@click.option("--duration", type=click.FloatRange(min=0.0, max=MAX_DURATION_S), default=0.0,
              show_default=True,
              help=f"Keep sending for this many seconds (at most {MAX_DURATION_S:g}), then send "
                   f"stop (0: send once).  Ctrl-C, SIGTERM or SIGHUP end it early, with stop.")
@click.option("--rate", type=click.FloatRange(min=1.0, max=100.0), default=10.0,
              show_default=True, help="How often to send while --duration lasts (Hz).")
@click.option("--socket", "socket_path", type=FilePath(dir_okay=False), default=None,
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
    check_finite(vx=vx, vy=vy, wz=wz, duration=duration, rate=rate)
    path = socket_for(ctx, config_path, socket_path)
    with ControlClient(path) as client:
        note = refuse_other_robot(ctx, config_path, client)
        if note:
            click.echo(note, err=True)
        end = time.monotonic() + duration
        period = 1.0 / rate
        with caught_signals(active=duration > 0) as caught:
            while True:
                reply = client.request({"op": "twist", "vx": vx, "vy": vy, "wz": wz})
                if not reply.get("ok"):
                    error = reply.get("error") or {}
                    click.echo(f"Error: {error.get('message', reply)}", err=True)
                    code = error.get("code")
                    ctx.exit(EXIT_INFEASIBLE if code == "infeasible_twist" else 1)
                if reply.get("warning"):
                    click.echo(f"warning: {reply['warning']}", err=True)
                if caught or time.monotonic() + period > end:
                    break
                _sleep(period, caught)
            if duration > 0:
                client.request({"op": "stop"})
    click.echo(following(reply, {"vx_m_s": vx, "vy_m_s": vy, "wz_rad_s": wz}))
    if caught:
        click.echo(f"twist: {caught[0]}: ended early; stop sent to {path}", err=True)


def _sleep(seconds: float, caught: list[str]) -> None:
    """Sleep ``seconds``, in slices of :data:`SIGNAL_LATENCY_S` so a caught signal ends it
    soon (a handler that returns does not cut ``time.sleep`` short: PEP 475)."""
    end = time.monotonic() + seconds
    while not caught and (left := end - time.monotonic()) > 0.0:
        time.sleep(min(left, SIGNAL_LATENCY_S))


def _twist_text(t: Mapping[str, object]) -> str:
    """``vx 0.3 m/s, vy 0 m/s, wz 0.5 rad/s``: millimetre and milliradian resolution, no ``-0``."""
    def num(key: str) -> str:
        value = t.get(key)
        return "?" if not isinstance(value, (int, float)) else short(value, 3)
    return f"vx {num('vx_m_s')} m/s, vy {num('vy_m_s')} m/s, wz {num('wz_rad_s')} rad/s"


def following(reply: Mapping[str, object], asked: Mapping[str, float]) -> str:
    """What an accepted twist's reply means for the robot, in one line: the twist it follows
    after the speed limits, and why when that is not what was asked."""
    applied = reply.get("applied") or reply.get("twist")
    if not isinstance(applied, dict):
        return f"ok: {reply}"
    text = f"ok: following {_twist_text(applied)}"
    notes = []
    if reply.get("projected"):
        notes.append("the nearest feasible twist to the one asked")
    if reply.get("limited_by"):
        notes.append(f"asked {_twist_text(asked)}; limited by {reply['limited_by']}")
    return text + (f" ({'; '.join(notes)})" if notes else "")
