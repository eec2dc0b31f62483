"""``wheelgate sim``: every motor's and steering actuator's device simulator, as a process of
its own on a bus, where the real controllers would sit.

Run it on a kernel bus (``wheelgate --interface socketcan --channel vcan0 sim``) and the
gateway in another process: ``candump`` and ``wheelgate monitor --bus`` see the whole
conversation, and killing the gateway leaves the simulated controllers running, as real ones
would (they then stop by their own command timeouts, or do not).  The simulators start from
the devices' state at power-on and follow their protocols' device side.  The process also
integrates the robot's true pose from the simulated shafts (:mod:`gateway.sim.truth`) and
reports it in its state lines: every ``--every`` seconds, on SIGUSR1, and on Enter when stdin
is a terminal.  SIGINT or SIGTERM (or SIGHUP) stops it with a last state line; the exit status
is 0.

Output, one line each (``--json``: one JSON object each):

* per device: ``sim: NAME DRIVER node ID (drive motor|steering actuator)``;
  ``{"event": "device", "name", "driver", "node_id", "role": "drive"|"steer"}``;
* then ``sim: ready: N devices on INTERFACE:CHANNEL, stepping at RATE Hz (...)``;
  ``{"event": "ready", "interface", "channel", "devices", "rate_hz"}``.  A robot with steered
  wheels that no simulated actuator turns, and whose other wheels do not fix the twist on
  their own, has no true pose: the text line says which wheels, the JSON object adds
  ``"truth": false`` and ``"unsimulated": [wheel names]``, and the state lines report the
  pose as unknown (``null``);
* state lines (:func:`gateway.sim.truth.state_line`; JSON: ``"event": "state"`` and the
  fields of :meth:`gateway.sim.truth.SimTruth.snapshot`), the last one prefixed
  ``sim stopped:`` (``"event": "stopped"``);
* with ``--json``, a failure (a configuration it cannot load, a bus it cannot open, the
  simulator thread stopping) is the last line, ``{"ok": false, "error": {"code", "message"}}``
  as every command's, with the exit code it has without ``--json``
  (:func:`~gateway.cli.commands._common.json_failures`).
"""

from __future__ import annotations

import json
import os
import select
import signal
import sys
import threading
import time
from typing import TYPE_CHECKING, Any

import click

from gateway.cli import config_option
from gateway.cli.commands._common import VIRTUAL_HINT, check_finite, json_failures, load
from gateway.cli.commands._guards import MAX_DURATION_S
from gateway.core.errors import BusError, GatewayError
from gateway.drive.driveset import DriveSet
from gateway.sim.bus import SimulatedControllers
from gateway.sim.registry import simulators_for
from gateway.sim.truth import SimTruth, state_line

if TYPE_CHECKING:
    from collections.abc import Sequence
    from types import FrameType

    from gateway.core.settings import GatewayConfig
    from gateway.sim.device import DeviceSimulator

#: What the ready line tells an operator about the keys and signals.
CONTROLS = "SIGUSR1 or Enter: state line; Ctrl-C: stop"


def announce_lines(cfg: GatewayConfig, sims: Sequence[DeviceSimulator], truth: SimTruth,
                   rate_hz: float, as_json: bool) -> list[str]:
    """The lines printed once the simulators run: one per device, then the ready line."""
    lines = []
    for sim in sims:
        m = sim.motor
        if as_json:
            lines.append(json.dumps({"event": "device", "name": m.wheel, "driver": m.driver,
                                     "node_id": m.node_id,
                                     "role": "steer" if m.steering else "drive"}))
        else:
            role = "steering actuator" if m.steering else "drive motor"
            lines.append(f"sim: {m.wheel} {m.driver} node {m.node_id} ({role})")
    if as_json:
        ready: dict[str, Any] = {"event": "ready", "interface": cfg.bus.interface,
                                 "channel": cfg.bus.channel, "devices": len(sims),
                                 "rate_hz": rate_hz}
        if not truth.available:
            ready.update(truth=False, unsimulated=list(truth.unsimulated))
        lines.append(json.dumps(ready))
    else:
        note = ("" if truth.available else
                f"; no true pose: wheel(s) {', '.join(truth.unsimulated)} steered without a "
                f"steering actuator")
        lines.append(f"sim: ready: {len(sims)} devices on {cfg.bus.interface}:"
                     f"{cfg.bus.channel}, stepping at {rate_hz:g} Hz{note} ({CONTROLS})")
    return lines


def report_line(event: str, state: dict[str, Any], as_json: bool) -> str:
    """A state line (``event`` ``"state"``) or the last one (``"stopped"``)."""
    if as_json:
        return json.dumps({"event": event, **state})
    return state_line(state, "sim stopped:" if event == "stopped" else "sim")


def open_controllers(cfg: GatewayConfig, sims: Sequence[DeviceSimulator],
                     rate_hz: float) -> SimulatedControllers:
    """The simulators on the configuration's bus.

    :raises BusError: naming the bus, with what to check (:func:`~gateway.bus.can_bus.open_bus`
        says it: no SocketCAN in the kernel, no such interface, a link at another bitrate).
    """
    try:
        return SimulatedControllers(sims, cfg.bus.channel, interface=cfg.bus.interface,
                                    rate_hz=rate_hz, bitrate=cfg.bus.bitrate)
    except BusError as err:
        raise BusError(f"wheelgate sim: {err}") from err


@click.command()
@config_option
@click.option("--rate", "rate_hz", type=click.FloatRange(min=10.0, max=10_000.0), default=1000.0,
              show_default=True,
              help="Simulator steps per second (DJI ESCs need 1 kHz: they report a 13-bit "
                   "rotor angle that must be sampled twice per rotor turn).")
@click.option("--every", "every_s", type=click.FloatRange(min=0.0, max=MAX_DURATION_S),
              default=5.0, show_default=True,
              help="Seconds between state lines (0: only on request).")
@click.option("--json", "as_json", is_flag=True, help="One JSON object per line.")
@click.pass_context
def command(ctx: click.Context, config_path: str | None, rate_hz: float, every_s: float,
            as_json: bool) -> None:
    """Run the configuration's simulated controllers on its bus, as separate devices."""
    with json_failures(ctx, as_json):
        _run(ctx, config_path, rate_hz, every_s, as_json)


def _run(ctx: click.Context, config_path: str | None, rate_hz: float, every_s: float,
         as_json: bool) -> None:
    """The simulators until a signal stops them (see the module)."""
    check_finite(rate=rate_hz, every=every_s)
    cfg = load(ctx, config_path)
    drives = DriveSet(cfg)
    sims = simulators_for(drives.all_motors())
    truth = SimTruth(cfg, drives, sims)
    ctl = open_controllers(cfg, sims, rate_hz)
    ctl.on_step = truth.update
    start = time.monotonic()

    def emit(event: str) -> None:
        state = ctl.snapshot(lambda: truth.snapshot(time.monotonic() - start, ctl.steps,
                                                     ctl.late_steps))
        click.echo(report_line(event, state, as_json))
        sys.stdout.flush()

    stop = threading.Event()
    wanted = threading.Event()

    def on_stop(signum: int, frame: FrameType | None) -> None:
        stop.set()

    def on_usr1(signum: int, frame: FrameType | None) -> None:
        wanted.set()

    old = {s: signal.signal(s, h) for s, h in ((signal.SIGINT, on_stop),
                                               (signal.SIGTERM, on_stop),
                                               (signal.SIGHUP, on_stop),
                                               (signal.SIGUSR1, on_usr1))}
    try:
        ctl.start()
        for line in announce_lines(cfg, sims, truth, rate_hz, as_json):
            click.echo(line)
        sys.stdout.flush()
        if cfg.bus.interface == "virtual":
            click.echo(f"sim: note: python-can's virtual bus exists only inside this process, so "
                       f"no gateway elsewhere hears these devices; {VIRTUAL_HINT}", err=True)
        keys = sys.stdin.fileno() if sys.stdin is not None and sys.stdin.isatty() else None
        next_s = time.monotonic() + every_s if every_s > 0 else float("inf")
        while not stop.is_set():
            timeout = max(0.0, min(next_s - time.monotonic(), 0.2))
            if keys is not None:
                ready, _, _ = select.select([keys], [], [], timeout)
                if ready:
                    typed = os.read(keys, 4096)
                    if typed:
                        wanted.set()
                    else:
                        keys = None  # end of input (Ctrl-D): only the signals are left
            else:
                stop.wait(timeout)
            if wanted.is_set():
                wanted.clear()
                emit("state")
            if time.monotonic() >= next_s:
                next_s = max(next_s + every_s, time.monotonic())
                emit("state")
            if not ctl.is_alive():
                raise GatewayError(f"wheelgate sim: the simulator thread stopped: "
                                   f"{ctl.failure!r}")
        emit("stopped")
    finally:
        ctl.shutdown()
        for s, h in old.items():
            signal.signal(s, h)
