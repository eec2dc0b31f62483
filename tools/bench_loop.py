"""Benchmark: the whole daemon loop at 1 kHz with four wheels and their simulators.

Method: the embedded default robot (4-wheel mecanum, four ODrive controllers) runs as
``wheelgate run --sim`` does: the control loop at 1 kHz in the main thread (absolute
deadlines, sleep on the control socket, spin for the last 200 us), the four device simulators
on the same virtual bus, and a twist client in a separate process that sends a twist over the
control socket about every 20 ms (15 to 25 ms apart, at random).  Where the simulators run
is chosen with ``--sims``: ``thread`` (default, exactly as ``--sim``: a background thread at
1 kHz in the daemon's process, which competes with the loop for the GIL) or ``inline``
(stepped by the loop thread right after each cycle, outside the measured cost: the closest
in-process stand-in for controllers that sit on the other end of a real bus).  The daemon's
own timing statistics, over the whole run, are read at the end:

* cycle CPU: the loop thread's CPU time (``thread_time``) in each ``Gateway.cycle``: the
  issue's "per-cycle CPU", which time the virtual CPU is taken away does not inflate;
* cycle cost: the wall time of one cycle's work (receive, decide, IK and limits, encode,
  send, odometry), the daemon's own figure;
* lateness: when a cycle started minus its deadline (p50/p99/max);
* missed cycles: deadlines skipped after an overrun (skipped, not burst), each late start
  classed by the daemon's :class:`~gateway.runtime.timing.MissProbe` from the loop thread's
  schedstat
  over the interval before it: on CPU for more than a period, runnable but not running, or
  asleep past its deadline;
* twist-to-frame latency: from the twist being sent to the daemon's socket (the client's
  ``perf_counter`` just before ``sendall``; CLOCK_MONOTONIC, the same clock in both
  processes) to the end of the send of the wheel frames of the cycle that applied it (before
  that cycle's odometry and publishing, ``Gateway.burst_sent_s``); beside it the daemon's
  own figure, which starts when the request is read;
* the same from CAN: a ``WG_Twist_Cmd`` about every 20 ms from a sender thread on the same
  virtual bus (python-can's ``virtual`` bus reaches only its own process), from just before
  its ``send`` to the end of the send of the wheel frames of the cycle that read it.  The
  loop reads the bus once per cycle, so this is up to one period plus the cycle's cost by
  design.

Beside them, the same-run cost of python-can alone: one cycle's worth of the same frames (4
velocity commands sent, everything waiting drained) on a virtual bus with the same
simulators, in a 1 kHz loop of its own with nothing else running (the simulators stepped
between cycles, outside the timed part), gives the ratio "gateway cycle / bare python-can
cycle".  With ``--sims thread`` the gateway's cost also carries the simulator thread's share
of the GIL, so that ratio is the pessimistic one; ``--sims inline`` compares like with like.
``tools/bench_throughput.py`` makes the same comparison in CPU time, frame for frame.

Run: ``python tools/bench_loop.py [seconds] [--rt PRIORITY] [--cpu N] [--lock] [--sims
thread|inline] [--spin-us US] [--platform] [--bridge]`` (default 10 s, normal scheduling;
``--bridge``: with a loopback Zenoh bridge, ROS 2 topics too, and an observer process).
``--platform`` then runs the same scheduler for as long, in the same thread and policy, doing
the same constant arithmetic in every cycle (as much CPU time at the median as the gateway's
cycle took), and rt-tests' ``cyclictest`` (C) at the same rate and priority when it is
installed: the misses and tails the machine causes by itself (on a VM, stalls of the virtual
CPU), and how much the CPU time of a constant workload spreads; CPU
time the hypervisor took (``/proc/stat`` steal) is printed for every part.  ``--rt`` runs
the loop thread with SCHED_FIFO (root or LimitRTPRIO), as ``gateway.rt_priority`` does.
Without SCHED_FIFO and on a shared machine, tails are dominated by the scheduler; the p50
figures and the ratio are the comparable ones.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import os
import random
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from typing import Any

import can
from platform_floor import CyclicTest, cyclictest, fixed_work_loop, steal_s

from gateway.bus.can_bus import drain, to_message
from gateway.config import load_config
from gateway.core.types import Frame, Twist
from gateway.runtime.daemon import Daemon
from gateway.runtime.sdnotify import SystemdNotifier
from gateway.runtime.timing import LoopTimer
from gateway.sim.bus import SimulatedControllers
from gateway.sim.registry import simulators_for
from gateway.wire.can import TwistCommand, WgCodec
from gateway.wire.socket import ProtocolError, Request, TwistRequest, encode_line


def bare_python_can_cycle_us(sims: SimulatedControllers, channel: str,
                             cycles: int = 5000) -> float:
    """Median cost of sending 4 Set_Input_Vel frames and draining the bus, per cycle, with
    nothing else running: the simulators (on ``channel``, not started) are stepped in this
    thread between cycles, outside the timed part, on a 1 ms grid."""
    bus = can.Bus(interface="virtual", channel=channel)
    msgs = [to_message(Frame(node << 5 | 0x0D, bytes(8))) for node in (1, 2, 3, 4)]
    samples = []
    try:
        due = time.monotonic()
        for _ in range(cycles):
            t0 = time.perf_counter()
            for msg in msgs:
                bus.send(msg)
            drain(bus)
            samples.append(time.perf_counter() - t0)
            sims.step(time.monotonic())
            due += 0.001
            time.sleep(max(0.0, due - time.monotonic()))
    finally:
        bus.shutdown()
    return statistics.median(samples) * 1e6


def client(path: str) -> None:
    """Send a twist about every 20 ms until the daemon closes the socket (in its own process);
    at the end print ``request id, perf_counter_ns when sent`` per twist on stdout.

    The sends follow their own schedule, 15 to 25 ms apart at random (seeded), not "20 ms after
    the last reply": replies leave the daemon at its deadlines, so that would lock the client's
    phase to the loop's and every twist would arrive at the same point of the cycle.  The time
    is taken just before ``sendall``, which puts the bytes in the daemon's socket within
    microseconds; after it would be too late, because the daemon, woken by the bytes, may run
    before the client reads the clock.
    """
    deadline = time.monotonic() + 5.0
    while not os.path.exists(path) and time.monotonic() < deadline:
        time.sleep(0.01)
    rng = random.Random(6)
    sent: list[tuple[int, int]] = []
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as sock:
        try:
            sock.connect(path)
            reader = sock.makefile("rb")
            k = 0
            due = time.monotonic()
            while True:
                line = encode_line({"op": "twist", "vx": 0.3 + 0.1 * (k % 3), "vy": 0.1,
                                    "wz": 0.2, "id": k})
                sent.append((k, time.perf_counter_ns()))
                sock.sendall(line)
                if not reader.readline():
                    break  # the daemon closed the socket at the end of the run
                k += 1
                due += rng.uniform(0.015, 0.025)
                time.sleep(max(0.0, due - time.monotonic()))
        except OSError:
            pass  # the daemon closed the socket at the end of the run
    print("\n".join(f"{k} {t}" for k, t in sent), flush=True)


class CanTwister(threading.Thread):
    """Sends a ``WG_Twist_Cmd`` on the daemon's bus about every 20 ms (15 to 25 ms apart at
    random, seeded), noting ``perf_counter_ns`` just before each send.

    python-can's ``virtual`` bus reaches only its own process, so this is a thread of the
    daemon's process, asleep between sends.  It sends through the simulators' bus (a
    ``virtual`` bus is safe to share between threads): a bus of its own would get a copy of
    every frame on the channel and, never read, grow without bound -- and with it the cost of
    every send and of the garbage collector.  Counters run 0, 1, 2, ... (mod 256); twist ``k``
    is the k-th the gateway accepts, so no counter needs to be unique.
    """

    def __init__(self, bus: can.BusABC, codec: WgCodec) -> None:
        super().__init__(name="can-twister", daemon=True)
        self.bus = bus
        self.codec = codec
        self.sent_ns: list[int] = []
        self.stop = threading.Event()

    def run(self) -> None:
        rng = random.Random(7)
        k = 0
        due = time.monotonic() + 0.5
        while not self.stop.wait(max(0.0, due - time.monotonic())):
            cmd = TwistCommand(Twist(0.3 + 0.1 * (k % 3), 0.1, 0.2), k % 256)
            msg = to_message(self.codec.encode_twist(cmd))
            self.sent_ns.append(time.perf_counter_ns())
            self.bus.send(msg)
            k += 1
            due += rng.uniform(0.015, 0.025)


class BenchDaemon(Daemon):
    """The daemon, noting when the frames of each twist (socket: by request id; CAN: in order
    of arrival) went out, and optionally stepping its simulators in the loop thread after
    each cycle."""

    sims: SimulatedControllers | None = None

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.frames_sent_ns: dict[int, int] = {}
        self.can_frames_sent_ns: list[int] = []
        #: CPU time of the loop thread in each ``Gateway.cycle`` (ns).
        self.cycle_cpu_ns: list[int] = []
        self._ids: list[int] = []
        self._can_twists = 0
        gw = self.gateway
        cycle = gw.cycle

        cpu = self.cycle_cpu_ns
        thread_time = time.thread_time_ns

        def timed_cycle(now_s: float) -> None:
            can_before = gw.counts.can_twists
            c0 = thread_time()
            cycle(now_s)
            cpu.append(thread_time() - c0)
            can_new = gw.counts.can_twists - can_before
            if self._ids or can_new:  # the daemon's own "sent": the wheel burst went out
                t = round(gw.burst_sent_s * 1e9)  # perf_counter, as perf_counter_ns
                for i in self._ids:
                    self.frames_sent_ns[i] = t
                self._ids.clear()
                self.can_frames_sent_ns.extend([t] * can_new)

        gw.cycle = timed_cycle  # type: ignore[method-assign]

    def handle(self, client: int, request: Request | ProtocolError, now_s: float) -> None:
        pending = len(self._pending_twists)
        super().handle(client, request, now_s)
        if (isinstance(request, TwistRequest) and isinstance(request.id, int)
                and len(self._pending_twists) > pending):
            self._ids.append(request.id)

    def step(self, now_s: float) -> None:
        super().step(now_s)  # records the cycle's cost before the simulators run
        if self.sims is not None:
            self.sims.step(time.monotonic())


def _percentiles_us(values_ns: list[int]) -> tuple[float, float, float]:
    ordered = sorted(values_ns)
    if not ordered:
        return 0.0, 0.0, 0.0
    n = len(ordered)
    return (ordered[max(0, math.ceil(0.5 * n) - 1)] / 1e3,
            ordered[max(0, math.ceil(0.99 * n) - 1)] / 1e3, ordered[-1] / 1e3)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("seconds", nargs="?", type=float, default=10.0)
    parser.add_argument("--rt", type=int, default=0, metavar="PRIORITY",
                        help="SCHED_FIFO priority of the loop thread (0: normal scheduling)")
    parser.add_argument("--cpu", type=int, default=-1, help="pin the loop thread to this CPU")
    parser.add_argument("--lock", action="store_true", help="mlockall after start-up")
    parser.add_argument("--sims", choices=("thread", "inline"), default="thread",
                        help="simulators in a background thread (as --sim) or stepped inline")
    parser.add_argument("--platform", action="store_true",
                        help="then run the same scheduler with constant work for as long, "
                             "and cyclictest (the machine's own misses and tails)")
    parser.add_argument("--spin-us", type=float, default=None, metavar="US",
                        help="spin this long before each deadline instead of sleeping "
                             "(gateway.spin_us; default: the config's, 200 us)")
    parser.add_argument("--bridge", action="store_true",
                        help="with a Zenoh bridge (loopback, ROS 2 topics too) and an observer "
                             "process subscribed to everything it publishes")
    parser.add_argument("--client", metavar="SOCKET", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.client:
        client(args.client)
        return
    print(__doc__.split("\n\n")[1].replace("\n", " "))
    cfg = load_config(None)
    cfg = dataclasses.replace(cfg, loop=dataclasses.replace(
        cfg.loop, rate_hz=1000.0, odom_rate_hz=50.0, rt_priority=args.rt, rt_cpu=args.cpu,
        lock_memory=args.lock,
        spin_us=cfg.loop.spin_us if args.spin_us is None else args.spin_us))
    observer = None
    if args.bridge:
        from bridge_peer import with_bridge  # noqa: PLC0415 - only with --bridge

        cfg, observer = with_bridge(cfg)
    folder = tempfile.mkdtemp(prefix="wgb", dir="/tmp")
    path = f"{folder}/b.sock"
    inline = args.sims == "inline"
    if "CLOCK_MONOTONIC" not in time.get_clock_info("perf_counter").implementation:
        sys.exit("perf_counter is not CLOCK_MONOTONIC here: cross-process latency impossible")
    daemon = BenchDaemon(cfg, sim=not inline, socket_path=path, notifier=SystemdNotifier(None))
    if inline:
        daemon.sims = SimulatedControllers(
            simulators_for(daemon.gateway.drives.all_motors()), cfg.bus.channel
        )
    # Keep every sample of the run (the daemon's own ring holds the last 4096).
    timer = LoopTimer(cfg.loop.rate_hz, capacity=int(args.seconds * cfg.loop.rate_hz) + 2000)
    daemon.scheduler.timer = daemon.gateway.timer = timer
    sender = subprocess.Popen([sys.executable, __file__, "--client", path],
                              stdout=subprocess.PIPE, text=True)
    sim_bus = daemon.sims.bus if daemon.sims is not None else daemon.sim.bus if (
        daemon.sim is not None) else None
    if sim_bus is None:
        sys.exit("no simulators: nothing to send CAN twists through")
    twister = CanTwister(sim_bus, daemon.gateway.wg)
    twister.start()
    stopper = threading.Timer(args.seconds, daemon.request_stop)
    stopper.start()
    load = os.getloadavg()[0]
    steal_start = steal_s()
    try:
        daemon.run()
    finally:
        stopper.cancel()
        twister.stop.set()
        twister.join()
        if daemon.sims is not None:
            daemon.sims.shutdown()
        try:
            out, _ = sender.communicate(timeout=5.0)
        except subprocess.TimeoutExpired:
            sender.kill()
            out, _ = sender.communicate()
    stats = timer.snapshot()
    steal_end = steal_s()
    if observer is not None:
        seen, _ = observer.communicate("", timeout=10.0)
        print(f"bridge: the observer received {seen.strip().splitlines()[-1]} (odometry at "
              f"{cfg.loop.odom_rate_hz:g} Hz, status at {cfg.loop.status_rate_hz:g} Hz)")
    sent_ns: dict[int, int] = {}
    for line in out.splitlines():
        if line.strip():
            k, t = line.split()
            sent_ns[int(k)] = int(t)
    e2e = [daemon.frames_sent_ns[k] - t for k, t in sent_ns.items() if k in daemon.frames_sent_ns]
    e2e_p50, e2e_p99, e2e_max = _percentiles_us(e2e)
    can_e2e = [out - sent for sent, out in zip(twister.sent_ns, daemon.can_frames_sent_ns,
                                               strict=False)]
    can_p50, can_p99, can_max = _percentiles_us(can_e2e)
    # Same simulators, same bus, python-can alone.
    sims = SimulatedControllers(simulators_for(daemon.gateway.drives.all_motors()), "wgb-bare")
    try:
        bare = bare_python_can_cycle_us(sims, "wgb-bare")
    finally:
        sims.shutdown()
    print(f"\nrun: {args.seconds:g} s at {stats.rate_hz:g} Hz, achieved {stats.achieved_hz:.1f} Hz,"
          f" {stats.cycles} cycles, {stats.missed} missed; simulators: {args.sims}; "
          f"spin {cfg.loop.spin_us:g} us; load average at start {load:.2f}")
    cpu_p50, cpu_p99, cpu_max = _percentiles_us(daemon.cycle_cpu_ns)
    print(f"cycle CPU     p50 {cpu_p50:8.1f} us  p99 {cpu_p99:8.1f} us  max {cpu_max:8.1f} us  "
          "(the loop thread's CPU time in Gateway.cycle, thread_time)")
    print(f"cycle cost    p50 {stats.cost_p50_us:8.1f} us  p99 {stats.cost_p99_us:8.1f} us  "
          f"max {stats.cost_max_us:8.1f} us")
    print(f"lateness      p50 {stats.lateness_p50_us:8.1f} us  p99 {stats.lateness_p99_us:8.1f} us"
          f"  max {stats.lateness_max_us:8.1f} us")
    print(f"twist->frames p50 {e2e_p50:8.1f} us  p99 {e2e_p99:8.1f} us  max {e2e_max:8.1f} us  "
          f"({len(e2e)} of {len(sent_ns)} twists; from the client's send)")
    print(f"CAN twist->frames p50 {can_p50:4.1f} us  p99 {can_p99:8.1f} us  max {can_max:8.1f} us"
          f"  ({len(can_e2e)} of {len(twister.sent_ns)} WG_Twist_Cmd; from the sender's send)")
    print(f"read->frames  p50 {stats.latency_p50_us:8.1f} us  p99 {stats.latency_p99_us:8.1f} us"
          f"  max {stats.latency_max_us:8.1f} us  (the daemon's own figure: from reading "
          f"the request)")
    print(f"python-can alone, same frames per cycle: p50 {bare:.1f} us")
    print(f"ratio gateway cycle / python-can alone (p50): {stats.cost_p50_us / bare:.2f}x")
    print(f"realtime: {'; '.join(daemon.rt_notes) or 'normal scheduling'}")
    fine = getattr(daemon, "_server_fd", None) is not None
    print("socket wait under 1 ms: " + (
        "select on the server's descriptor (requests served on arrival)" if fine else
        "sleep (the server has no fileno(); requests wait for the pass at the deadline)"))
    period_us = 1e6 / stats.rate_hz
    verdict = [
        ("p99 lateness <= 200 us", stats.lateness_p99_us <= 200.0),
        ("no missed cycles", stats.missed == 0),
        ("cycle CPU p50 <= 100 us", cpu_p50 <= 100.0),
        (f"twist->frames p99 <= {period_us + 200:.0f} us (socket)", e2e_p99 <= period_us + 200),
        (f"(CAN) <= {period_us + 200:.0f} us", can_p99 <= period_us + 200),
    ]
    print("targets: " + "; ".join(f"{name}: {'yes' if ok else 'NO'}" for name, ok in verdict))
    print(f"CPU time stolen by the hypervisor during the run: {_stolen(steal_start, steal_end)}")
    probe = daemon.miss_probe
    print("missed cycles by cause (the daemon's MissProbe: the loop thread's schedstat over "
          "each interval from the cycle before): "
          + (probe.describe() if probe is not None else "not classified"))
    if args.platform:
        steal_start = steal_s()
        base = fixed_work_loop(args.seconds, cfg.loop.rate_hz, cfg.loop.spin_us * 1e-6, cpu_p50)
        w50, w99, wmax = base.work_us
        print(f"platform floor, the same scheduler doing the same arithmetic in every cycle "
              f"({cpu_p50:.0f} us of CPU at the median, as the gateway's cycle) for "
              f"{args.seconds:g} s in this thread: {base.stats.missed} missed; lateness p50 "
              f"{base.stats.lateness_p50_us:.1f} us, p99 {base.stats.lateness_p99_us:.1f} us, "
              f"max {base.stats.lateness_max_us:.1f} us; CPU time of the constant work p50 "
              f"{w50:.1f} us, p99 {w99:.1f} us, max {wmax:.1f} us; stolen "
              f"{_stolen(steal_start, steal_s())}")
        print("its missed cycles by cause: " + base.late_starts)
        steal_start = steal_s()
        ct = cyclictest(args.seconds, cfg.loop.rate_hz, args.rt)
        if isinstance(ct, CyclicTest):
            print(f"platform floor in C, cyclictest {ct.command}: {ct.skipped} deadlines skipped "
                  f"({ct.loops} of {ct.expected} wake-ups), {ct.late} a period or more late, "
                  f"worst latency {ct.max_us} us; stolen {_stolen(steal_start, steal_s())}")
        else:
            print(f"platform floor in C: {ct}")


def _stolen(start: float | None, end: float | None) -> str:
    if start is None or end is None:
        return "unknown (no steal column in /proc/stat)"
    return f"{(end - start) * 1e3:.0f} ms (/proc/stat steal, all CPUs, 10 ms resolution)"


if __name__ == "__main__":
    main()
