"""``wheelgate sim``: every motor's and steering actuator's device simulator, as a process of
its own on a bus, where the real controllers would sit.

Run it on a kernel bus (``wheelgate --interface socketcan --channel vcan0 sim``) and the
gateway in another process: ``candump`` and ``wheelgate monitor --bus`` see the whole
conversation, and killing the gateway leaves the simulated controllers running, as real ones
would (they then stop by their own command timeouts, or do not).  The simulators start from
the devices' state at power-on and follow their protocols' device side.  The process also
integrates the robot's true pose from the simulated shafts (:mod:`gateway.simtruth`) and
reports it in its state lines: every ``--every`` seconds, on SIGUSR1, and on Enter when stdin
is a terminal.  SIGINT or SIGTERM stops it with a last state line; the exit status is 0.
"""

from __future__ import annotations

import json
import select
import signal
import sys
import threading
import time
from typing import TYPE_CHECKING

import click

from gateway.cli import config_option
from gateway.commands._common import VIRTUAL_HINT, load
from gateway.drives import DriveSet
from gateway.simbus import SimulatedControllers
from gateway.simtruth import SimTruth, state_line

if TYPE_CHECKING:
    from types import FrameType


@click.command()
@config_option
@click.option("--rate", "rate_hz", type=click.FloatRange(min=10.0, max=10_000.0), default=1000.0,
              show_default=True,
              help="Simulator steps per second (DJI ESCs need 1 kHz: they report a 13-bit "
                   "rotor angle that must be sampled twice per rotor turn).")
@click.option("--every", "every_s", type=click.FloatRange(min=0.0), default=5.0,
              show_default=True, help="Seconds between state lines (0: only on request).")
@click.option("--json", "as_json", is_flag=True, help="One JSON object per line.")
@click.pass_context
def command(ctx: click.Context, config_path: str | None, rate_hz: float, every_s: float,
            as_json: bool) -> None:
    """Run the configuration's simulated controllers on its bus, as separate devices."""
    cfg = load(ctx, config_path)
    drives = DriveSet(cfg)
    sims = drives.simulators()
    truth = SimTruth(cfg, drives, sims)
    ctl = SimulatedControllers(sims, cfg.bus.channel, interface=cfg.bus.interface,
                               rate_hz=rate_hz)
    ctl.on_step = truth.update
    start = time.monotonic()

    def emit(event: str) -> None:
        state = ctl.snapshot(lambda: truth.snapshot(time.monotonic() - start, ctl.steps,
                                                     ctl.late_steps))
        if as_json:
            click.echo(json.dumps({"event": event, **state}))
        else:
            line = state_line(state)
            click.echo(f"sim stopped: {line}" if event == "stopped" else line)
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
        for sim in sims:
            m = sim.motor
            role = "steer" if m.steering else "drive"
            if as_json:
                click.echo(json.dumps({"event": "device", "name": m.wheel, "driver": m.driver,
                                       "node_id": m.node_id, "role": role}))
            else:
                click.echo(f"sim: {m.wheel} {m.driver} node {m.node_id} "
                           f"({'steering actuator' if m.steering else 'drive motor'})")
        bus = f"{cfg.bus.interface}:{cfg.bus.channel}"
        if as_json:
            click.echo(json.dumps({"event": "ready", "interface": cfg.bus.interface,
                                   "channel": cfg.bus.channel, "devices": len(sims),
                                   "rate_hz": rate_hz, "truth": truth.available}))
        else:
            note = ("" if truth.available else
                    f"; no true pose: {', '.join(truth.unsimulated)} steered without an actuator")
            click.echo(f"sim: ready: {len(sims)} devices on {bus}, stepping at {rate_hz:g} Hz"
                       f"{note} (SIGUSR1 or Enter: state line; Ctrl-C: stop)")
        if cfg.bus.interface == "virtual":
            click.echo(f"sim: note: python-can's virtual bus exists only inside this process, so "
                       f"no gateway elsewhere hears these devices; {VIRTUAL_HINT}", err=True)
        sys.stdout.flush()
        tty = sys.stdin.isatty()
        next_s = time.monotonic() + every_s if every_s > 0 else float("inf")
        while not stop.is_set():
            timeout = max(0.0, min(next_s - time.monotonic(), 0.2))
            if tty:
                ready, _, _ = select.select([sys.stdin], [], [], timeout)
                if ready and sys.stdin.readline() is not None:
                    wanted.set()
            else:
                stop.wait(timeout)
            if wanted.is_set():
                wanted.clear()
                emit("state")
            if time.monotonic() >= next_s:
                next_s += every_s
                emit("state")
            if ctl.errors and not ctl.is_alive():
                break
        emit("stopped")
    finally:
        ctl.shutdown()
        for s, h in old.items():
            signal.signal(s, h)
