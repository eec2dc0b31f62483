"""``wheelgate status``: the running daemon's state, odometry, counters and timing."""

from __future__ import annotations

import json

import click

from gateway.cli import config_option, json_option
from gateway.cli.commands._common import socket_for
from gateway.runtime.client import ControlClient

#: Late-start causes in the status's timing (``late_<key>``), as printed.
_LATE_CAUSES = (("on_cpu", "on CPU"), ("runnable", "runnable"), ("asleep", "asleep"))


@click.command()
@config_option
@click.option("--socket", "socket_path", type=click.Path(dir_okay=False), default=None,
              help="Control socket of the daemon.")
@json_option
@click.pass_context
def command(
    ctx: click.Context, config_path: str | None, socket_path: str | None, as_json: bool
) -> None:
    """Print the running gateway's state, motors, odometry, counters and timing."""
    with ControlClient(socket_for(ctx, config_path, socket_path)) as client:
        reply = client.request({"op": "status"})
    if not reply.get("ok"):
        raise click.ClickException(str((reply.get("error") or {}).get("message", reply)))
    reply.pop("ok", None)
    reply.pop("id", None)
    if as_json:
        click.echo(json.dumps(reply))
        return
    click.echo(f"robot: {reply['robot']}  state: {reply['state']}"
               + (f" ({reply['reason']})" if reply.get("reason") else ""))
    odo = reply["odometry"]
    click.echo(f"odometry: x={odo['x']:.4f} m y={odo['y']:.4f} m theta={odo['theta']:.4f} rad "
               f"v=({odo['vx']:.3f}, {odo['vy']:.3f}, {odo['wz']:.3f}) slip={odo['slip']:.4f} m/s "
               f"distance={odo['distance']:.3f} m")
    width = max([12, *(len(str(m["name"])) for m in reply["motors"])])
    for m in reply["motors"]:
        age = m["feedback_age_s"]
        stop = m.get("controller_stop")  # daemons before issue 14 do not send it
        guard = ""
        if stop:
            timeout = stop["timeout_s"]
            guard = f"stop {stop['guard']}" + (f" {timeout:g} s" if timeout else "") + (
                f" ({stop['state']})" if stop["state"] != "not applicable" else "")
        click.echo(f"  {m['name']:<{width}} node {m['node_id']:<4} {m['state']:<9} "
                   f"age {'-' if age is None else f'{age * 1000:.1f} ms':>9}  {guard:<30} "
                   f"{', '.join(m['faults']) or 'no faults'} {m['detail']}")
    tr = reply.get("tracking")
    if tr:  # daemons before the tracking check do not send it
        click.echo(f"tracking: worst error {tr['worst_ratio']:.2f} of the window "
                   f"({tr['tolerance_rad_s']:g} rad/s + {100 * tr['tolerance_ratio']:g} % of the "
                   f"command, {tr['time_s']:g} s)"
                   + (f"; steering {tr['steer_worst_ratio']:.2f} of "
                      f"{tr['steer_tolerance_rad']:g} rad" if tr.get("steer_worst_ratio") else ""))
    t = reply["timing"]
    causes = [(t.get(f"late_{key}", 0), text) for key, text in _LATE_CAUSES]
    why = (" (late starts: " + ", ".join(f"{text} {n}" for n, text in causes) + ")"
           if any(n for n, _ in causes) else "")
    click.echo(f"timing: {t['cycles']} cycles, {t['missed']} missed{why}; lateness p50/p99/max "
               f"{t['lateness_p50_us']:.0f}/{t['lateness_p99_us']:.0f}/{t['lateness_max_us']:.0f} "
               f"us; cost p50/p99/max {t['cost_p50_us']:.0f}/{t['cost_p99_us']:.0f}/"
               f"{t['cost_max_us']:.0f} us"
               + (f"; longest gap between bursts {t['burst_gap_max_ms']:.1f} ms"
                  if "burst_gap_max_ms" in t else ""))
    counters = {k: v for k, v in reply["counters"].items()
                if v and k not in ("rejected_frames", "commands_not_followed")}
    for driver, counts in (reply["counters"].get("commands_not_followed") or {}).items():
        counters.update({f"{driver}.{k}": v for k, v in counts.items()})
    click.echo("counters: " + ", ".join(f"{k}={v}" for k, v in sorted(counters.items())))
    bus = reply.get("bus") or {}
    if "error_state" in bus:  # daemons before the bus's health was reported do not send it
        errors = {k: v for k, v in bus["error_frames"].items() if v and k != "error_frames"}
        click.echo(f"bus: {bus['interface']}:{bus['channel']} controller {bus['error_state']}"
                   f"{'' if bus['healthy'] else ' (unhealthy: frames do not go out)'}; "
                   f"{bus['error_frames'].get('error_frames', 0)} error frames"
                   + (" (" + ", ".join(f"{k}={v}" for k, v in sorted(errors.items())) + ")"
                      if errors else "")
                   + (f", last: {bus['last_error_frame']}" if bus.get("last_error_frame") else ""))
    if reply.get("last_error"):
        click.echo(f"last error: {reply['last_error']['message']}")
