"""``wheelgate estop``, ``enable`` and ``disable``: the daemon's state from a shell.

Each sends its request on the control socket (``{"op": "estop"}``, ...) and says what the
gateway does then; with ``--json`` the result is one object on stdout (``{"ok": true,
"state": "running"}``, a failure ``{"ok": false, "error": {"code", "message"}}``), exit 0 or 1.

* ``estop`` always goes out: a configuration naming another robot than the daemon's, or one
  that cannot be read, is a warning, never a reason to hold back a stop.
* ``enable`` drives the motors, so with ``-c`` it refuses a daemon that runs another robot
  (exit 2, as ``twist``).  It waits (``--wait``, 10 s; 0: not at all) for the outcome: RUNNING
  (exit 0), or FAULT, ESTOP or DISABLED with the gateway's reason, or still ENABLING when the
  wait ends (exit 1).  The gateway listens for another commander for 250 ms before it takes
  an enable, so a wait of 0 returns while it is ENABLING.
* ``disable`` ramps to zero and disarms; another robot, or a configuration that cannot be
  read, is a warning as for ``estop``.
"""

from __future__ import annotations

import json
import time
from typing import Any

import click

from gateway.cli import FilePath, config_option, json_option
from gateway.cli.commands._common import (
    daemon_runs,
    json_failures,
    load,
    refuse_other_robot,
    socket_for,
)
from gateway.cli.commands._guards import fail_json
from gateway.config import client_socket_path
from gateway.core.errors import ConfigError, GatewayError
from gateway.runtime.client import ControlClient

#: How often ``enable --wait`` asks for the state (s).
POLL_S = 0.05

_socket = click.option("--socket", "socket_path", type=FilePath(dir_okay=False), default=None,
                       help="Control socket of the daemon.")


class OpFailedError(GatewayError):
    """The gateway refused the request, or the enable did not end in RUNNING."""


def _send(ctx: click.Context, config_path: str | None, socket_path: str | None, op: str,
          refuse: bool) -> tuple[ControlClient, dict[str, Any], list[str]]:
    """Connect, send ``op`` and check the robot: with ``refuse`` first (another robot is a
    usage error), else after the request (another robot is a warning); the open client, the
    reply and the warnings.

    Without ``refuse`` (a stop), a configuration that cannot be read is a warning too: the
    request goes to ``--socket`` or the default socket.
    """
    warnings: list[str] = []
    if not refuse and config_path is not None:
        try:
            load(ctx, config_path)
        except ConfigError as err:
            warnings.append(f"{err}; sent to {socket_path or client_socket_path()} without "
                            f"checking the robot")
            config_path = None
    client = ControlClient(socket_for(ctx, config_path, socket_path))
    try:
        if refuse:
            note = refuse_other_robot(ctx, config_path, client)
            if note:
                warnings.append(note.removeprefix("warning: "))
        reply = client.request({"op": op})  # (a stop first, the robot's check after it)
        if not reply.get("ok"):
            raise OpFailedError(str((reply.get("error") or {}).get("message", reply)))
        if not refuse and config_path is not None:
            said = daemon_runs(ctx, config_path, client.request({"op": "status"}))
            warnings += [w for w in said if w is not None]
    except BaseException:
        client.close()
        raise
    return client, reply, warnings


def _finish(as_json: bool, state: str, text: str, warnings: list[str]) -> None:
    if as_json:
        doc: dict[str, object] = {"ok": True, "state": state}
        if warnings:
            doc["warnings"] = warnings
        click.echo(json.dumps(doc))
        return
    for w in warnings:
        click.echo(f"warning: {w}", err=True)
    click.echo(text)


def _failed(ctx: click.Context, as_json: bool, message: str, warnings: list[str]) -> None:
    if as_json:
        fail_json(ctx, "error", message=message, warnings=warnings)
    for w in warnings:
        click.echo(f"warning: {w}", err=True)
    raise OpFailedError(message)


@click.command()
@config_option
@_socket
@json_option
@click.pass_context
def estop(ctx: click.Context, config_path: str | None, socket_path: str | None,
          as_json: bool) -> None:
    """E-stop the running gateway: zero at once and disarm, held (across restarts) until an
    enable.  Sent whatever robot the daemon runs (another than -c names is a warning)."""
    with json_failures(ctx, as_json):
        client, reply, warnings = _send(ctx, config_path, socket_path, "estop", refuse=False)
        client.close()
    _finish(as_json, str(reply.get("state")), "e-stopped: every motor was sent zero and "
            "disarm; the e-stop holds, across restarts too, until `wheelgate enable`", warnings)


@click.command()
@config_option
@_socket
@json_option
@click.pass_context
def disable(ctx: click.Context, config_path: str | None, socket_path: str | None,
            as_json: bool) -> None:
    """Disable the running gateway: ramp to zero, then disarm (an e-stop stays latched)."""
    with json_failures(ctx, as_json):
        client, reply, warnings = _send(ctx, config_path, socket_path, "disable", refuse=False)
        client.close()
    state = str(reply.get("state"))
    text = ("disabled: the wheels ramp to zero, then every motor is disarmed"
            if state == "disabled" else f"{state}: an e-stop stays until `wheelgate enable`")
    _finish(as_json, state, text, warnings)


@click.command()
@config_option
@_socket
@click.option("--wait", type=click.FloatRange(min=0.0, max=600.0), default=10.0,
              show_default=True,
              help="Wait this long for the motors to enable (s, at most 600; 0: do not wait).")
@json_option
@click.pass_context
def enable(ctx: click.Context, config_path: str | None, socket_path: str | None, wait: float,
           as_json: bool) -> None:
    """Enable the running gateway's motors (also the way out of an e-stop or a fault), and
    wait for the outcome: exit 0 once they run, 1 when they fault, the gateway is e-stopped
    or disabled again, or the wait ends first.  With -c, a daemon that runs another robot is
    refused (exit 2)."""
    with json_failures(ctx, as_json):
        client, reply, warnings = _send(ctx, config_path, socket_path, "enable", refuse=True)
        with client:
            state, reason = str(reply.get("state")), ""
            end = time.monotonic() + wait
            while state == "enabling" and time.monotonic() < end:
                time.sleep(POLL_S)
                status = client.request({"op": "status"})
                state, reason = str(status.get("state")), str(status.get("reason") or "")
    if state == "running" or (state == "enabling" and wait == 0.0):
        _finish(as_json, state, "running: every motor is enabled" if state == "running"
                else "enabling: the gateway enables the motors (not waited for)", warnings)
        return
    if state == "enabling":
        message = (f"the motors did not enable within {wait:g} s: the gateway is still "
                   f"enabling (`wheelgate status` says what each motor reports)")
    else:
        message = f"the motors did not enable: the gateway is {state}" + (
            f": {reason}" if reason else "")
    _failed(ctx, as_json, message, warnings)
