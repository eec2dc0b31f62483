"""``wheelgate status``: the running daemon's state, odometry, counters and timing."""

from __future__ import annotations

import json
import math
from typing import TYPE_CHECKING

import click

from gateway.cli import FilePath, config_option, json_option
from gateway.cli.commands._common import daemon_runs, socket_for
from gateway.cli.commands._guards import fail_json_of
from gateway.core.errors import GatewayError
from gateway.core.numfmt import fixed, short
from gateway.core.protection import stop_text
from gateway.core.status import fault_names, state_name
from gateway.runtime.client import ControlClient
from gateway.wire.socket.status import status_from_json, status_to_json

if TYPE_CHECKING:
    from gateway.core.status import GatewayStatus


@click.command()
@config_option
@click.option("--socket", "socket_path", type=FilePath(dir_okay=False), default=None,
              help="Control socket of the daemon.")
@json_option
@click.pass_context
def command(
    ctx: click.Context, config_path: str | None, socket_path: str | None, as_json: bool
) -> None:
    """Print the running gateway's state, motors, odometry, counters and timing (with --json,
    a failure too is a JSON object on stdout: ``{"ok": false, "error": {...}}``; a warning,
    such as a daemon running another robot than -c names, or this robot from a text other
    than the file's, is also in its "warnings" list)."""
    try:
        with ControlClient(socket_for(ctx, config_path, socket_path)) as client:
            reply = client.request({"op": "status"})
    except GatewayError as err:
        if not as_json:
            raise
        fail_json_of(ctx, err)
    if not reply.get("ok"):
        if as_json:
            click.echo(json.dumps({"ok": False, "error": reply.get("error")}))
            ctx.exit(1)
        raise click.ClickException(str((reply.get("error") or {}).get("message", reply)))
    why, note = daemon_runs(ctx, config_path, reply)
    why = why or note
    if why is not None:
        click.echo(f"warning: {why}", err=True)
    status = status_from_json(reply)
    if as_json:
        doc = status_to_json(status)
        click.echo(json.dumps(doc if why is None else {**doc, "warnings": [why]}))
        return
    for line in status_lines(status):
        click.echo(line)


def _finite_nonzero(value: float) -> bool:
    return math.isfinite(value) and value != 0.0


def status_lines(status: GatewayStatus) -> list[str]:
    """What ``wheelgate status`` prints, a line each."""
    s = status
    lines = [f"robot: {s.robot}  state: {state_name(s.state)}"
             + (f" ({s.reason})" if s.reason else "")
             + (f"  config: {s.config.path}" if s.config is not None else "")]
    odo = s.odometry
    pose, vel = odo.pose, odo.twist
    lines.append(
        f"odometry: x={fixed(pose.x_m, 4)} m y={fixed(pose.y_m, 4)} m "
        f"theta={fixed(pose.theta_rad, 4)} rad v=({fixed(vel.vx_m_s, 3)}, "
        f"{fixed(vel.vy_m_s, 3)}, {fixed(vel.wz_rad_s, 3)}) slip={fixed(odo.slip_m_s, 4)} m/s "
        f"distance={fixed(odo.distance_m, 3)} m")
    width = max([12, *(len(m.name) for m in s.motors)])
    for m in s.motors:
        age = m.feedback_age_s
        stop = m.controller_stop  # daemons before issue 14 do not send it
        guard = "" if stop is None else (
            f"stop {stop_text(stop.guard, stop.timeout_s, stop.state)}")
        lines.append(
            f"  {m.name:<{width}} node {m.node_id:<4} {state_name(m.state):<9} "
            f"age {'-' if age is None else f'{age * 1000:.1f} ms':>9}  {guard:<30} "
            f"{', '.join(fault_names(m.faults)) or 'no faults'} {m.detail}")
    tr = s.tracking
    if tr is not None:  # daemons before the tracking check do not send it
        lim = tr.limits
        # steer_worst_ratio: the largest steering-angle error seen, over the tolerance.
        steer = ""
        if _finite_nonzero(tr.steer_worst_ratio) and lim.steer_tolerance_rad > 0.0:
            steer = (f"; steering off by up to "
                     f"{fixed(tr.steer_worst_ratio * lim.steer_tolerance_rad, 2)} rad "
                     f"(tolerance {short(lim.steer_tolerance_rad, 3)} rad)")
        lines.append(
            f"tracking: worst error {tr.worst_ratio:.2f} of the window "
            f"({lim.tolerance_rad_s:g} rad/s + {100 * lim.tolerance_ratio:g} % of the "
            f"command, {lim.time_s:g} s)"
            + steer)
    t = s.timing
    causes = [(t.late_on_cpu, "on CPU"), (t.late_runnable, "runnable"),
              (t.late_asleep, "asleep")]
    why = (" (late starts: " + ", ".join(f"{text} {n}" for n, text in causes) + ")"
           if any(n for n, _ in causes) else "")
    lines.append(
        f"timing: {t.cycles} cycles, {t.missed} missed{why}; lateness p50/p99/max "
        f"{t.lateness_p50_us:.0f}/{t.lateness_p99_us:.0f}/{t.lateness_max_us:.0f} "
        f"us; cost p50/p99/max {t.cost_p50_us:.0f}/{t.cost_p99_us:.0f}/{t.cost_max_us:.0f} us"
        + (f"; longest gap between bursts {t.burst_gap_max_ms:.1f} ms"
           if t.burst_gap_max_ms is not None else ""))
    counters = {k: v for k, v in s.counters.events.items() if v}
    for driver, counts in s.counters.commands_not_followed.items():
        counters.update({f"{driver}.{k}": v for k, v in counts.items()})
    lines.append("counters: " + ", ".join(f"{k}={v}" for k, v in sorted(counters.items())))
    bus, health = s.bus, s.bus.health
    if health is not None:  # daemons before the bus's health was reported do not send it
        frames = health.error_frames
        errors = {k: v for k, v in frames.items() if v and k != "error_frames"}
        lines.append(
            f"bus: {bus.interface}:{bus.channel} controller {health.error_state.value}"
            f"{'' if health.healthy else ' (unhealthy: frames do not go out)'}; "
            f"{frames.get('error_frames', 0)} error frames"
            + (" (" + ", ".join(f"{k}={v}" for k, v in sorted(errors.items())) + ")"
               if errors else "")
            + (f", last: {health.last_error_frame}" if health.last_error_frame else ""))
    if s.last_error is not None:
        lines.append(f"last error: {s.last_error.message}")
    return lines
