"""Benchmark: the gateway's CPU per cycle on a quiet and on a busy kernel bus, with and without
the kernel receive filters its drivers declare.

Method: the embedded default robot (four ODrive controllers) on a SocketCAN interface (default
``vcan0``; needs AF_CAN, e.g. the tier's VM).  The gateway and the four device simulators run
in this process on simulated time, paced in real time at ``--rate`` (default 100 Hz) so that a
flood of foreign frames piles up between cycles as it would on a robot: each cycle is
``Gateway.cycle`` then two simulator steps.  Measured per cycle: the loop thread's CPU time in
``Gateway.cycle`` (``time.thread_time``, which a descheduled thread does not accumulate) and
the frames the gateway drained.  Four runs of ``--cycles`` cycles each: quiet and busy (a
``cangen`` process sending 8-byte frames on ID 0x7A0, 0.2 ms apart: about 5,000 frames/s, IDs
the gateway does not consume), each with the bus opened with the filters (as the gateway does
on socketcan) and without.  Printed: median and mean CPU per cycle, frames drained per cycle,
and the machine-independent ratio busy/quiet of the median CPU for each way of opening.
"""

from __future__ import annotations

import argparse
import dataclasses
import socket
import statistics
import subprocess
import time

from gateway.bus import open_bus
from gateway.config import load_config
from gateway.control import Source
from gateway.loop import Gateway
from gateway.simbus import SimulatedControllers
from gateway.types import GatewayState, Twist


def run(channel: str, rate_hz: float, cycles: int, filtered: bool, busy: bool
        ) -> tuple[list[float], float]:
    """CPU seconds of each cycle, and frames drained per cycle."""
    cfg = load_config(None, {"interface": "socketcan", "channel": channel})
    cfg = dataclasses.replace(cfg, loop=dataclasses.replace(cfg.loop, rate_hz=rate_hz))
    probe = Gateway(cfg, stamp_with_cycle_time=True)
    filters = probe.receive_filters
    probe.close()
    kwargs: dict[str, object] = {"fd": True}
    if filtered and filters is not None:
        kwargs["can_filters"] = [f.as_python_can() for f in filters]
    gw = Gateway(cfg, bus=open_bus("socketcan", channel, **kwargs), stamp_with_cycle_time=True)
    ctl = SimulatedControllers(gw.drives.simulators(), channel, "socketcan")
    flood = None
    period = 1.0 / rate_hz
    try:
        t = 0.0
        gw.supervisor.enable(t)
        for _ in range(int(2 * rate_hz)):
            gw.cycle(t)
            ctl.step(t + period / 2)
            ctl.step(t + period)
            t += period
        if gw.state is not GatewayState.RUNNING:
            raise SystemExit(f"the drives did not enable: {gw.supervisor.reason}")
        if busy:
            flood = subprocess.Popen(["cangen", channel, "-g", "0.2", "-I", "7A0", "-L", "8"])
            time.sleep(0.5)
        costs = []
        received0 = gw.counts["frames_received"]
        next_s = time.monotonic()
        for k in range(cycles):
            if k % 20 == 0:
                gw.twist(Twist(0.3), t, Source.SOCKET)
            next_s += period
            time.sleep(max(next_s - time.monotonic(), 0.0))
            c0 = time.thread_time()
            gw.cycle(t)
            costs.append(time.thread_time() - c0)
            ctl.step(t + period / 2)
            ctl.step(t + period)
            t += period
        return costs, (gw.counts["frames_received"] - received0) / cycles
    finally:
        if flood is not None:
            flood.terminate()
            flood.wait()
        ctl.shutdown()
        gw.close()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--channel", default="vcan0")
    parser.add_argument("--rate", type=float, default=100.0)
    parser.add_argument("--cycles", type=int, default=400)
    args = parser.parse_args()
    try:
        socket.socket(socket.AF_CAN, socket.SOCK_RAW, socket.CAN_RAW).close()
    except (AttributeError, OSError) as err:
        raise SystemExit(f"bench_busy_bus: needs a kernel with SocketCAN ({err})") from err
    print(__doc__)
    results = {}
    for filtered in (True, False):
        for busy in (False, True):
            costs, frames = run(args.channel, args.rate, args.cycles, filtered, busy)
            results[filtered, busy] = statistics.median(costs)
            print(f"{'filtered  ' if filtered else 'unfiltered'} {'busy ' if busy else 'quiet'}: "
                  f"CPU per cycle median {statistics.median(costs) * 1e6:7.1f} us, mean "
                  f"{statistics.fmean(costs) * 1e6:7.1f} us; {frames:6.1f} frames drained "
                  f"per cycle")
    for filtered in (True, False):
        ratio = results[filtered, True] / results[filtered, False]
        print(f"ratio busy/quiet, {'with' if filtered else 'without'} the kernel filters: "
              f"{ratio:.2f}x")


if __name__ == "__main__":
    main()
