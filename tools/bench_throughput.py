"""Benchmark: frames per second the gateway processes (sends and decodes) on one core.

Target (issue 6): at least 9,000 frames/s, the most a 1 Mbit/s bus carries with 8-byte
standard frames, so the bus and not wheelgate is the limit; and the gateway within 2x of
python-can alone moving the same frames on the same virtual bus.

Method, per protocol (ODrive, VESC, CiA 402, DJI, DBC), on one robot (the embedded 4-wheel
mecanum demo with that protocol's motors), single-threaded, on the python-can ``virtual`` bus:

1. The gateway (:class:`gateway.runtime.loop.Gateway`, the daemon's cycle) is enabled against its
   device simulators on simulated time (1 kHz cycles, two simulator steps per cycle), then
   follows a constant twist.  For 2 s of simulated time every frame the simulators emit is
   recorded, cycle by cycle: that is the feedback pool.
2. The simulators leave the bus.  A second bus, the injector, puts pool frames on the bus
   before each cycle, either as recorded ("1 kHz mix": the simulators' own rates) or a fixed
   number per cycle so that sent + received is 9 frames per 1 ms cycle ("saturated": a full
   1 Mbit/s bus at 1 kHz).  The injector's own cost and the draining of what the gateway sent
   happen outside the timed region; only ``Gateway.cycle`` is timed (``process_time_ns`` by
   default: CPU time of the process, so time the scheduler gives to other processes does not
   count; ``--clock perf`` for ``perf_counter_ns``; the cost of an empty timed region is
   measured and subtracted):
   drain the bus, decode every frame in its driver, supervise, inverse kinematics and limits,
   encode every wheel's frame, send the burst, integrate odometry, publish odometry/status
   frames at their rates.
3. python-can alone, same run, same frames: a fresh pair of buses on another channel; per
   cycle the injector puts the same received frames, then the timed part sends the very
   ``can.Message`` objects the gateway sent in that cycle and drains the bus with ``recv(0)``
   until it is empty.  Both sides have exactly one other bus on their channel, so every
   send costs one python-can ``deepcopy``.
4. ``--cycles`` cycles make one repeat; gateway and python-can repeats alternate,
   ``--repeats`` times; the figures are the median (and best) over the repeats.  Garbage
   collection stays on, after ``gc.freeze()`` as the daemon does.

Frames/s = (frames sent + frames received) / time spent in the timed region: the throughput of
one core.  The gateway's state is checked to be RUNNING, and the drivers' rejection counters
to be unchanged, at the end (so the frames were decoded, not dropped).

Instructions (``--instructions``): valgrind's callgrind (``--cache-sim=no``) counts the same
work in instructions, exact and repeatable where CPU time on a shared machine swings.  One
process per protocol runs under callgrind: the setup above, shortened (0.2 s to enable, 0.3 s
of twist, a pool of exactly N cycles, so every N-cycle window of the 1 kHz mix holds the same
frames; hash seed 0), then, garbage
collector frozen, it forks one child per loop and length (N, 2N cycles), that loop only:
gateway = put each cycle's frames on the gateway bus's receive queue, ``Gateway.cycle``;
python-can = put them on the bare bus's queue, send the gateway's frames of that cycle (of the
first N, recorded in the setup), ``recv(0)`` until empty; harness = only the puts (on a queue
nobody reads), the part common to both.  Instructions per cycle = (I(2N) - I(N)) / N, so
setup, fork and exit cancel; the harness's is subtracted from the other two.  The parent's
fork and wait between children add a constant drift per child, measured by empty children at
both ends and taken out.  ``--verify`` repeats every N-cycle child and adds a 3N one, to show
the counts repeat and (I(3N) - I(2N)) / (I(2N) - I(N)) - 1 is near 0.  ``bench_anchor.py``
adds a fourth loop on the ODrive frames, counted the same way: the hand-written loop a robot
builder would write instead (``anchor_loop.py``).

Run: ``.venv/bin/python tools/bench_throughput.py [--cycles N] [--repeats R]
[--protocol NAME ...] [--profile NAME] [--instructions [--instr-cycles N] [--verify]]``.
"""

from __future__ import annotations

import argparse
import cProfile
import gc
import os
import platform
import pstats
import statistics
import time

import throughput_instructions
from throughput_rig import PERIOD_S, PROTOCOLS, Bench, Result

__all__ = ["PERIOD_S", "PROTOCOLS", "Bench", "main", "profile_one"]


def _line(r: Result) -> str:
    gw, bare = statistics.median(r.gateway_us), statistics.median(r.bare_us)
    return (f"{r.protocol:7} {r.mix:10} {r.sent_per_cycle:5.2f} {r.received_per_cycle:5.2f} "
            f"{gw:8.1f} {min(r.gateway_us):7.1f} {r.rate(gw):10,.0f} "
            f"{bare:8.1f} {r.rate(bare):10,.0f} {gw / bare:6.2f}x "
            f"{r.rate(gw) / 9000:6.1f}x")


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cycles", type=int, default=2000, help="cycles per repeat")
    parser.add_argument("--repeats", type=int, default=7, help="alternating repeats")
    parser.add_argument("--protocol", action="append", choices=sorted(PROTOCOLS),
                        help="only these protocols (repeatable)")
    parser.add_argument("--clock", choices=("process", "perf"), default="process",
                        help="process CPU time (default; robust on a shared machine) or "
                             "perf_counter wall time (for an otherwise idle machine)")
    parser.add_argument("--profile", choices=sorted(PROTOCOLS),
                        help="cProfile the gateway cycles of one protocol (see --mix)")
    parser.add_argument("--mix", choices=("1 kHz mix", "saturated"), default="saturated",
                        help="the feedback mix of --profile")
    parser.add_argument("--sort", default="tottime",
                        help="pstats sort key of --profile (tottime, cumulative, ncalls)")
    parser.add_argument("--instructions", action="store_true",
                        help="count instructions per cycle with callgrind instead of CPU time")
    parser.add_argument("--instr-cycles", type=int, default=200,
                        help="N of --instructions (pool and differencing length)")
    parser.add_argument("--verify", action="store_true",
                        help="--instructions: also check repeatability and linearity")
    parser.add_argument("--jobs", type=int, default=2, help="callgrind processes at a time")
    args = parser.parse_args(argv)
    method = __doc__.split("\n\n", 2)[2].split("\n\nRun:")[0]
    if args.instructions:
        print("Instructions" + method.split("\n\nInstructions", 1)[1])
        print(f"\nPython {platform.python_version()} on {platform.machine()}, "
              f"N = {args.instr_cycles} cycles, {args.jobs} callgrind processes at a time\n")
        throughput_instructions.run_instructions(args.protocol or list(PROTOCOLS),
                                                 args.instr_cycles, args.jobs, args.verify)
        return
    print(method.split("\n\nInstructions", 1)[0])
    print(f"\nPython {platform.python_version()} on {platform.machine()}, "
          f"{args.cycles} cycles x {args.repeats} repeats, clock {args.clock}, "
          f"load average {os.getloadavg()[0]:.2f}\n")
    if args.profile:
        profile_one(args.profile, args.cycles * args.repeats, args.sort, args.mix)
        return
    print("protocol mix        sent  recv  gw us/c    best    gw fr/s  pcan us/c  pcan fr/s "
          " ratio  vs 9k")
    clock = time.process_time_ns if args.clock == "process" else time.perf_counter_ns
    results: list[Result] = []
    for protocol in args.protocol or list(PROTOCOLS):
        bench = Bench(protocol, clock)
        try:
            bench.record_pool()
            gc.collect()
            gc.freeze()
            for mix in ("1 kHz mix", "saturated"):
                r = bench.measure(mix, args.cycles, args.repeats)
                if mix == "1 kHz mix":
                    bench.sent_estimate = r.sent_per_cycle
                results.append(r)
                print(_line(r), flush=True)
        finally:
            bench.close()
            gc.unfreeze()
    worst = min(results, key=lambda r: r.rate(statistics.median(r.gateway_us)))
    ratio = max(statistics.median(r.gateway_us) / statistics.median(r.bare_us)
                for r in results)
    print(f"\nslowest: {worst.protocol} {worst.mix}: "
          f"{worst.rate(statistics.median(worst.gateway_us)):,.0f} frames/s per core "
          f"(target 9,000); largest ratio gateway / python-can alone: {ratio:.2f}x (aim 2x)")
    print("columns: frames sent and received per cycle; gateway us per cycle (median, best of "
          "repeats); frames/s; python-can alone us per cycle and frames/s; ratio of medians; "
          "gateway frames/s over 9,000")


def profile_one(protocol: str, cycles: int, sort: str = "tottime",
                mix: str = "saturated") -> None:
    """Print the 30 most expensive functions of the cycles of ``mix``."""
    bench = Bench(protocol)
    try:
        bench.record_pool()
        bench.sent_estimate = bench.measure("1 kHz mix", 200, 1).sent_per_cycle
        prof = cProfile.Profile()
        bench.measure(mix, cycles, 1, prof)
    finally:
        bench.close()
    stats = pstats.Stats(prof)
    stats.sort_stats(sort).print_stats(30)
    if sort == "tottime":
        stats.print_callers(r"enum\.py")


if __name__ == "__main__":
    main()
