"""Benchmark: the gateway's CPU per cycle on a quiet and on a busy kernel bus, with and without
the kernel receive filters its drivers declare.

Method: the embedded default robot (4-wheel mecanum, four ODrive controllers) moved onto a
SocketCAN interface (default ``vcan0``, ``--channel``; needs a kernel with AF_CAN and the
interface up, e.g. ``ip link add vcan0 type vcan && ip link set vcan0 up``).  The gateway
(:class:`gateway.runtime.loop.Gateway`, the daemon's cycle) and the four device simulators
(:class:`gateway.sim.bus.SimulatedControllers`, a socket of their own) run in this process's
main thread on simulated time, paced in real time at ``--rate`` (default 100 Hz) so that
traffic piles up between cycles as it does on a robot: each cycle is ``Gateway.cycle``, then
two simulator steps (outside the measurement).  The gateway follows a twist sent every 20
cycles.  The simulators stand for controllers at the other end of the bus: their socket always
has the drivers' filters (for ODrive they cover the commands too), so the flood loads only the
gateway.  Measured per cycle: the loop thread's CPU time in ``Gateway.cycle``
(``time.thread_time``, which time the thread spends descheduled does not inflate) and the
frames it drained (``edge.counts.frames_received``: every classical frame the socket delivered,
consumed or not).

Four runs of ``--cycles`` cycles (default 400) each, after 2 s of simulated time to enable:
quiet and busy, each with the gateway's bus opened with the kernel filters (``can_filters=[f.
as_python_can() for f in gateway_filters(...)]``, as the gateway opens socketcan; python-can
sets them as ``CAN_RAW_FILTER``, ``can/interfaces/socketcan/utils.py::pack_filters``; Linux
``Documentation/networking/can.rst``, "RAW socket option CAN_RAW_FILTER") and without
(``fd`` on in both, as the gateway opens socketcan).  Busy: a separate process with its own
raw socket sends ``--flood`` frames/s (default 5,000) of foreign traffic in bursts of ten:
8-byte frames alternately on the 11-bit IDs 0x7A0-0x7BF and on 256 random 29-bit IDs, none of
which the gateway consumes (checked against its filters).  The flood process reports the
rate it achieved.

Printed per run: the median, 90th percentile and mean CPU per cycle (and the median as a
share of the period), the frames drained per cycle, and the cycles that started a period or
more late (the loop fell behind; it then drains more per cycle).  Then, per way of opening,
the ratios busy/quiet of the median CPU per cycle and of the frames drained per cycle (the
machine-independent figures: these machines are shared and noisy), and, without the filters,
the loop's CPU per foreign frame.  With the filters the kernel drops foreign frames in the
sender's context (on vcan the flooder's; with a real controller its receive softirq), so
their cost never reaches the loop thread.

Run: ``python tools/bench_busy_bus.py [--channel vcan0] [--rate HZ] [--cycles N]
[--flood FPS]``.  Without AF_CAN (no SocketCAN in the kernel, or not Linux) it prints why and
exits with status 0, having measured nothing.
"""

from __future__ import annotations

import argparse
import dataclasses
import multiprocessing
import random
import socket
import statistics
import struct
import sys
import time
from typing import TYPE_CHECKING, Any

from gateway.bus.can_bus import open_bus
from gateway.config import load_config
from gateway.core.control import Source
from gateway.core.errors import BusError
from gateway.core.types import GatewayState, Twist
from gateway.drive.driveset import DriveSet
from gateway.drive.filters import CanFilter, matches_any
from gateway.drive.ownership import gateway_filters
from gateway.runtime.loop import Gateway
from gateway.sim.bus import SimulatedControllers
from gateway.sim.registry import simulators_for

if TYPE_CHECKING:
    from collections.abc import Sequence
    from multiprocessing.sharedctypes import Synchronized

    from gateway.core.settings import GatewayConfig

#: ``struct can_frame`` (linux/can.h): can_id, len, padding, 8 data bytes.
_CAN_FRAME = struct.Struct("=IB3x8s")
_CAN_EFF_FLAG = 0x80000000
#: Frames per burst of the flood (one burst every ``_BURST / rate`` s).
_BURST = 10


@dataclasses.dataclass(frozen=True)
class Run:
    """One run's figures."""

    filtered: bool
    busy: bool
    cpu_s: list[float]
    frames_per_cycle: float
    #: Cycles that started a period or more after their deadline (the loop fell behind).
    late: int

    @property
    def median_s(self) -> float:
        return statistics.median(self.cpu_s)


def foreign_ids(filters: Sequence[CanFilter], seed: int = 1) -> list[tuple[int, bool]]:
    """The flood's identifiers: 0x7A0-0x7BF (11-bit) and 256 random 29-bit IDs, none passing
    ``filters``, interleaved.

    :raises SystemExit: if one of 0x7A0-0x7BF is the gateway's.
    """
    rng = random.Random(seed)
    standard = [(i, False) for i in range(0x7A0, 0x7C0)]
    extended: list[tuple[int, bool]] = []
    while len(extended) < 256:
        ident = rng.getrandbits(29)
        if not matches_any(filters, ident, True):
            extended.append((ident, True))
    clash = [hex(i) for i, e in standard if matches_any(filters, i, e)]
    if clash:
        raise SystemExit(f"bench_busy_bus: the gateway consumes {', '.join(clash)}")
    return [ident for pair in zip(standard * 8, extended, strict=True) for ident in pair]


def flood(channel: str, idents: list[tuple[int, bool]], rate: float,
          sent: Synchronized[int]) -> None:
    """Send frames on ``idents`` in turn at ``rate`` frames/s until terminated (the flood
    process's body; a raw socket, so the flood costs little CPU of its own)."""
    sock = socket.socket(socket.AF_CAN, socket.SOCK_RAW, socket.CAN_RAW)
    sock.bind((channel,))
    # The flood does not read: receive nothing, so its socket queue does not fill.
    sock.setsockopt(socket.SOL_CAN_RAW, socket.CAN_RAW_FILTER, b"")
    frames = [_CAN_FRAME.pack(i | (_CAN_EFF_FLAG if ext else 0), 8, bytes([k & 0xFF] * 8))
              for k, (i, ext) in enumerate(idents)]
    period = _BURST / rate
    k = 0
    deadline = time.monotonic()
    while True:
        for _ in range(_BURST):
            try:
                sock.send(frames[k % len(frames)])
            except OSError:
                continue  # a full queue: the frame is lost, as on a bus at its limit
            k += 1
        sent.value = k
        deadline += period
        delay = deadline - time.monotonic()
        if delay > 0:
            time.sleep(delay)
        elif delay < -0.1:
            deadline = time.monotonic()  # fell behind: do not burst to catch up


def run(cfg: GatewayConfig, filters: Sequence[CanFilter], sim_filters: Sequence[CanFilter],
        cycles: int, filtered: bool, busy: bool) -> Run:
    """Enable the gateway against its simulators, then time ``cycles`` cycles.

    :param filters: the gateway's receive filters (applied when ``filtered``).
    :param sim_filters: the simulators' receive filters (always applied).
    """
    kwargs: dict[str, Any] = {"fd": True}
    if filtered:
        kwargs["can_filters"] = [f.as_python_can() for f in filters]
    channel = cfg.bus.channel
    bus = open_bus("socketcan", channel, **kwargs)
    gw = Gateway(cfg, bus=bus, stamp_with_cycle_time=True)
    # The simulators stand for controllers at the other end of the bus: they take only their
    # own frames (the ODrive filters cover the commands too), so the flood loads only the
    # gateway and cannot make a simulator miss a command.
    ctl = SimulatedControllers(simulators_for(gw.drives.all_motors()), channel, "socketcan",
                               can_filters=[f.as_python_can() for f in sim_filters])
    period = 1.0 / cfg.loop.rate_hz
    try:
        t = 0.0
        gw.supervisor.enable(t)
        for _ in range(int(2 * cfg.loop.rate_hz)):
            gw.cycle(t)
            ctl.step(t + period / 2)
            ctl.step(t + period)
            t += period
        if gw.state is not GatewayState.RUNNING:
            raise SystemExit(f"bench_busy_bus: the drives did not enable: {gw.supervisor.reason}")
        gw.edge.receive(t)  # what piled up during the set-up is not this run's
        costs = []
        late = 0
        received0 = gw.edge.counts.frames_received
        next_s = time.monotonic()
        for k in range(cycles):
            if k % 20 == 0:
                gw.twist(Twist(0.3), t, Source.SOCKET)
            next_s += period
            delay = next_s - time.monotonic()
            if delay > 0.0:
                time.sleep(delay)
            elif delay <= -period:
                late += 1
            c0 = time.thread_time()
            gw.cycle(t)
            costs.append(time.thread_time() - c0)
            ctl.step(t + period / 2)
            ctl.step(t + period)
            t += period
        if gw.state is not GatewayState.RUNNING:
            raise SystemExit(f"bench_busy_bus: the gateway left RUNNING: {gw.supervisor.reason}")
        return Run(filtered, busy, costs, (gw.edge.counts.frames_received - received0) / cycles,
                   late)
    finally:
        ctl.shutdown()
        gw.close()
        bus.shutdown()


def _us(seconds: float) -> str:
    return f"{seconds * 1e6:8.1f} us"


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").split("\n")[0])
    parser.add_argument("--channel", default="vcan0", help="SocketCAN interface (default vcan0)")
    parser.add_argument("--rate", type=float, default=100.0, help="cycles/s (default 100)")
    parser.add_argument("--cycles", type=int, default=400, help="cycles per run (default 400)")
    parser.add_argument("--flood", type=float, default=5000.0,
                        help="foreign frames/s while busy (default 5000)")
    args = parser.parse_args()
    try:
        socket.socket(socket.AF_CAN, socket.SOCK_RAW, socket.CAN_RAW).close()
    except (AttributeError, OSError) as err:
        print(f"bench_busy_bus: skipped: needs a kernel with SocketCAN (AF_CAN): {err}",
              file=sys.stderr)
        return
    cfg = load_config(None, {"interface": "socketcan", "channel": args.channel})
    cfg = dataclasses.replace(cfg, loop=dataclasses.replace(cfg.loop, rate_hz=args.rate))
    drives = DriveSet(cfg)
    filters = gateway_filters(cfg, drives)
    sim_filters = drives.receive_filters()
    if filters is None or sim_filters is None:
        raise SystemExit("bench_busy_bus: a driver of the default robot declares no filters")
    try:
        open_bus("socketcan", args.channel).shutdown()
    except BusError as err:
        print(f"bench_busy_bus: skipped: {err} (bring the interface up first, e.g. ip link add "
              f"{args.channel} type vcan && ip link set {args.channel} up)", file=sys.stderr)
        return
    print(__doc__)
    print(f"filters: {' '.join(map(str, filters))}; {args.cycles} cycles at {args.rate:g} Hz "
          f"per run\n")
    results: dict[tuple[bool, bool], Run] = {}
    idents = foreign_ids(filters)
    ctx = multiprocessing.get_context("fork")
    for busy in (False, True):
        proc = None
        sent = ctx.Value("Q", 0)
        if busy:
            proc = ctx.Process(target=flood, args=(args.channel, idents, args.flood, sent),
                               daemon=True)
            proc.start()
            time.sleep(0.5)
        t0, n0 = time.monotonic(), sent.value
        try:
            for filtered in (True, False):
                r = run(cfg, filters, sim_filters, args.cycles, filtered, busy)
                results[filtered, busy] = r
                cpu = sorted(r.cpu_s)
                print(f"{'busy ' if busy else 'quiet'} {'filtered  ' if filtered else 'unfiltered'}"
                      f": CPU per cycle median {_us(r.median_s)}, p90 "
                      f"{_us(cpu[int(0.9 * (len(cpu) - 1))])}, mean "
                      f"{_us(statistics.fmean(cpu))} ({r.median_s * args.rate:.0%} of the "
                      f"period); {r.frames_per_cycle:6.1f} frames drained per cycle; "
                      f"{r.late} cycles a period late")
        finally:
            if proc is not None:
                achieved = (sent.value - n0) / (time.monotonic() - t0)
                proc.terminate()
                proc.join()
                print(f"      (flood achieved {achieved:,.0f} frames/s of {args.flood:,.0f})")
    print()
    for filtered in (True, False):
        quiet, busy_run = results[filtered, False], results[filtered, True]
        print(f"ratio busy/quiet {'with' if filtered else 'without'} the kernel filters: CPU "
              f"per cycle {busy_run.median_s / quiet.median_s:5.2f}x, frames drained "
              f"{busy_run.frames_per_cycle / quiet.frames_per_cycle:5.2f}x")
    quiet, busy_run = results[False, False], results[False, True]
    extra = busy_run.frames_per_cycle - quiet.frames_per_cycle
    if extra > 1.0:
        print(f"without the filters, each foreign frame drained costs the loop "
              f"{_us((busy_run.median_s - quiet.median_s) / extra).strip()} of CPU")


if __name__ == "__main__":
    main()
