"""``wheelgate scan``: the controllers on the bus, by protocol, without moving anything.

It listens to the configuration's bus (or ``--interface``/``--channel``) for ``--timeout``
seconds and, after the first quarter, asks the controllers it heard a few protocol-defined,
read-only questions (which, and why none can move a motor or change a setting:
:mod:`gateway.apps.scan.scanner`): ODrive axes by heartbeat, and their firmware by Get_Version;
VESCs by status frames and PING; CANopen nodes by boot-up and heartbeat, and their device type
(0x1000) and identity (0x1018) by SDO reads; DJI ESCs by their feedback.  The gateway's own
messages (``gateway.can_ids``) are named, and every other identifier is listed with its rate.
With ``-c``, a controller that a motor block names (driver, node ID and identifier type: an
ODrive on 29-bit identifiers is not the block of its node on 11-bit ones, and its row says what
differs) is shown with its wheel, a motor block whose controller was not found is named at the
end, and the frames the configured drivers send to all their controllers (CANopen SYNC and the
gateway's own heartbeat, DJI commands) are named as the gateway's
(:mod:`gateway.apps.scan.own`).  The
identifiers each configured motor's driver declares as that motor's are the motor's: only its
own protocol's probe looks at them, no other protocol's request is sent there, and a motor
heard there that no probe recognises (a DBC controller) is listed as found by ``config``
(a DBC controller's feedback at 0x281 is not taken for the heartbeat of ODrive node 20).  It
may run beside a running gateway.

Output: a table sorted by protocol and node ID (80 columns), then a summary line; ``--json``:
a list of objects, one per row, each with ``protocol`` and ``node_id`` (``null`` for the
gateway's messages and the unknown identifiers) and everything learned.  Exit 0 when the scan
ran, whether or not anything answered (then it says so, with what to check: the empty list is
the scan's result, as ``[]`` with ``--json``, not a failure of the tool); 1 when the bus
cannot be opened or read; 2 for bad usage.
"""

from __future__ import annotations

import json
import math

import click

from gateway.apps.scan import render, report_json, scan, summary, wrap
from gateway.apps.scan.own import motor_claims, own_messages
from gateway.bus.link import read_link
from gateway.cli import config_option, json_option
from gateway.cli.commands._common import VIRTUAL_HINT, bitrate_stated, load
from gateway.cli.commands._guards import fail_json_of
from gateway.core.errors import GatewayError

#: The longest --timeout (s).
MAX_TIMEOUT_S = 3600.0
#: The default --timeout (s): two ODrive heartbeat periods in the listening quarter, every
#: VESC PING (255, 2 ms apart), and a CANopen heartbeat of 1 s.
DEFAULT_TIMEOUT_S = 2.0


def _timeout(ctx: click.Context, param: click.Parameter, value: float) -> float:
    if not (math.isfinite(value) and 0.0 < value <= MAX_TIMEOUT_S):
        raise click.BadParameter(f"expected seconds above 0 and at most {MAX_TIMEOUT_S:g}, "
                                 f"got {value!r}")
    return value


def nothing_found_hint(interface: str, channel: str, bitrate: int | None = None) -> str:
    """What to check when no controller answered (a bitrate other than the controllers' is
    the usual cause at a first power-on, so the one the bus ran at is named).

    :param bitrate: the bitrate the adapter was opened at, ``None``: python-can's default
        (an adapter) or the link's (SocketCAN, read here).
    """
    if interface == "virtual":
        return (f"python-can's virtual bus (channel {channel!r}) exists only inside this "
                f"process, so no controller elsewhere is on it; {VIRTUAL_HINT}")
    return (f"check the bus: --interface/--channel (or the configuration's bus: block; here "
            f"{interface}:{channel}), {_rate_hint(interface, channel, bitrate)}the wiring, the "
            f"termination and the controllers' power; a CANopen node that booted before the "
            f"scan and has no heartbeat (0x1017 = 0) stays silent")


#: python-can interfaces that carry frames over a network, with no bitrate of their own.
_NETWORKED = frozenset({"udp_multicast", "socketcand", "remote"})


def _rate_hint(interface: str, channel: str, bitrate: int | None) -> str:
    if interface in _NETWORKED:
        return ""
    if interface != "socketcan":
        if bitrate is None:
            return (f"that the controllers talk at python-can's default bitrate of its "
                    f"{interface} interface (give theirs with --bitrate), ")
        return f"that the controllers talk at {bitrate} bit/s, the bitrate the scan used, "
    found = read_link(channel)
    if found is None or (found.up and found.bitrate is None):  # (a vcan: no bitrate)
        return (f"that the link is up at the controllers' bitrate (ip -details link show "
                f"{channel}), ")
    if not found.up:
        return (f"the link: it is down (bring it up at the controllers' bitrate: "
                f"{found.up_command(bitrate or found.bitrate or 'N')}), ")
    return (f"that the controllers talk at {found.bitrate} bit/s, the link's (at another "
            f"bitrate N: {found.up_command('N')}), ")


@click.command()
@config_option
@click.option("--timeout", "timeout_s", type=float, default=DEFAULT_TIMEOUT_S,
              show_default=True, callback=_timeout,
              help=f"Seconds to listen and ask, above 0 and at most {MAX_TIMEOUT_S:g} (the "
                   f"first quarter only listens).")
@json_option
@click.pass_context
def command(ctx: click.Context, config_path: str | None, timeout_s: float,
            as_json: bool) -> None:
    """List the controllers on the bus by protocol (ODrive, VESC, CANopen, DJI) and the other
    IDs with their rates, sending only protocol-defined read-only requests."""
    try:
        from can.interfaces import VALID_INTERFACES  # noqa: PLC0415 - as check_interface

        cfg = load(ctx, config_path, VALID_INTERFACES)
        bus = cfg.bus
        own = own_messages(cfg, drivers=config_path is not None)
        known = [*(m for m in cfg.motors if m is not None), *cfg.steering] if config_path else []
        claimed = motor_claims(cfg) if config_path else ()
        report = scan(bus.interface, bus.channel, timeout_s, own, known, claimed,
                      bus.bitrate if bitrate_stated(ctx, config_path) else None)
    except (GatewayError, click.ClickException) as err:
        if not as_json:
            raise
        fail_json_of(ctx, err)
    hint = None if report.controllers else nothing_found_hint(
        bus.interface, bus.channel, bus.bitrate if bitrate_stated(ctx, config_path) else None)
    if as_json:
        click.echo(json.dumps(report_json(report)))
        if hint is not None:
            click.echo(wrap(f"{summary(report)}: {hint}"), err=True)
        return
    click.echo(render(report))
    if hint is not None:
        click.echo(wrap(f"hint: {hint}"))
