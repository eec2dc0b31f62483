"""Benchmark: the whole daemon loop at 1 kHz with four wheels and their simulators.

Method: the embedded default robot (4-wheel mecanum, four ODrive controllers) runs in one
process exactly as ``wheelgate run --sim`` does: the control loop at 1 kHz in the main thread
(absolute deadlines, sleep on the control socket, spin for the last 200 us), the four device
simulators in a background thread at 1 kHz on the same virtual bus, and a client thread that
sends a twist over the control socket every 20 ms.  The daemon's own timing statistics are
read at the end:

* cycle cost: the work of one cycle (receive, decide, IK and limits, encode, send, odometry);
* lateness: when a cycle started minus its deadline (p50/p99/max over the last 4096 cycles);
* missed cycles: deadlines skipped after an overrun (skipped, not burst);
* twist-to-frame latency: from the twist request being read off the socket to the end of the
  send of the cycle that applied it.

Beside them, the same-run cost of python-can alone: one cycle's worth of the same frames (4
velocity commands sent, everything waiting drained) on the same virtual bus with the same
simulators, in a loop of its own, gives the ratio "gateway cycle / bare python-can cycle".

Run: ``python tools/bench_loop.py [seconds]`` (default 10).  Without SCHED_FIFO (root or
LimitRTPRIO) and on a shared machine, tails are dominated by the scheduler; the p50 figures
and the ratio are the comparable ones.
"""

from __future__ import annotations

import dataclasses
import statistics
import sys
import tempfile
import threading
import time

import can

from gateway.bus import drain
from gateway.client import ControlClient
from gateway.config import load_config
from gateway.daemon import Daemon
from gateway.errors import GatewayError
from gateway.sdnotify import SystemdNotifier
from gateway.simbus import SimulatedControllers
from gateway.types import Frame


def bare_python_can_cycle_us(channel: str, cycles: int = 5000) -> float:
    """Median cost of sending 4 Set_Input_Vel frames and draining the bus, per cycle."""
    bus = can.Bus(interface="virtual", channel=channel)
    frames = [Frame(node << 5 | 0x0D, bytes(8)) for node in (1, 2, 3, 4)]
    samples = []
    try:
        for _ in range(cycles):
            t0 = time.perf_counter()
            for f in frames:
                bus.send(can.Message(arbitration_id=f.arbitration_id, data=f.data,
                                     is_extended_id=False))
            drain(bus)
            samples.append(time.perf_counter() - t0)
            time.sleep(0.0005)
    finally:
        bus.shutdown()
    return statistics.median(samples) * 1e6


def client(path: str, stop: threading.Event) -> None:
    try:
        with ControlClient(path) as c:
            k = 0
            while not stop.is_set():
                c.request({"op": "twist", "vx": 0.3 + 0.1 * (k % 3), "vy": 0.1, "wz": 0.2})
                k += 1
                stop.wait(0.02)
    except GatewayError:
        pass  # the daemon closed the socket at the end of the run


def main() -> None:
    seconds = float(sys.argv[1]) if len(sys.argv) > 1 else 10.0
    print(__doc__.split("\n\n")[1].replace("\n", " "))
    cfg = load_config(None)
    cfg = dataclasses.replace(cfg, loop=dataclasses.replace(cfg.loop, rate_hz=1000.0,
                                                            odom_rate_hz=50.0))
    folder = tempfile.mkdtemp(prefix="wgb", dir="/tmp")
    path = f"{folder}/b.sock"
    daemon = Daemon(cfg, sim=True, socket_path=path, notifier=SystemdNotifier(None))
    stop = threading.Event()
    sender = threading.Thread(target=client, args=(path, stop), daemon=True)
    threading.Timer(0.5, sender.start).start()
    threading.Timer(seconds, daemon.request_stop).start()
    try:
        daemon.run()
    finally:
        stop.set()
    stats = daemon.scheduler.timer.snapshot()
    # Same simulators, same bus, python-can alone.
    sims = SimulatedControllers(daemon.gateway.drives.simulators(), "wgb-bare").start()
    try:
        bare = bare_python_can_cycle_us("wgb-bare")
    finally:
        sims.shutdown()
    print(f"\nrun: {seconds:g} s at {stats.rate_hz:g} Hz, achieved {stats.achieved_hz:.1f} Hz, "
          f"{stats.cycles} cycles, {stats.missed} missed")
    print(f"cycle cost    p50 {stats.cost_p50_us:8.1f} us  p99 {stats.cost_p99_us:8.1f} us  "
          f"max {stats.cost_max_us:8.1f} us")
    print(f"lateness      p50 {stats.lateness_p50_us:8.1f} us  p99 {stats.lateness_p99_us:8.1f} us"
          f"  max {stats.lateness_max_us:8.1f} us")
    print(f"twist->frames p50 {stats.latency_p50_us:8.1f} us  p99 {stats.latency_p99_us:8.1f} us"
          f"  max {stats.latency_max_us:8.1f} us  ({stats.latency_samples} twists)")
    print(f"python-can alone, same frames per cycle: p50 {bare:.1f} us")
    print(f"ratio gateway cycle / python-can alone (p50): {stats.cost_p50_us / bare:.2f}x")
    print(f"realtime: {'; '.join(daemon.rt_notes) or 'normal scheduling'}")


if __name__ == "__main__":
    main()
