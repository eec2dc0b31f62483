"""Benchmark: frames per second the gateway processes (sends and decodes) on one core.

Target (issue 6): at least 9,000 frames/s, the most a 1 Mbit/s bus carries with 8-byte
standard frames, so the bus and not wheelgate is the limit; and the gateway within 2x of
python-can alone moving the same frames on the same virtual bus.

Method, per protocol (ODrive, VESC, CiA 402, DJI, DBC), on one robot (the embedded 4-wheel
mecanum demo with that protocol's motors), single-threaded, on the python-can ``virtual`` bus:

1. The gateway (:class:`gateway.loop.Gateway`, the daemon's cycle) is enabled against its
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
the counts repeat and (I(3N) - I(2N)) / (I(2N) - I(N)) - 1 is near 0.

Run: ``.venv/bin/python tools/bench_throughput.py [--cycles N] [--repeats R]
[--protocol NAME ...] [--profile NAME] [--instructions [--instr-cycles N] [--verify]]``.
"""

from __future__ import annotations

import argparse
import cProfile
import dataclasses
import gc
import os
import platform
import pstats
import statistics
import time
from pathlib import Path
from typing import TYPE_CHECKING

import can

from gateway.bus import drain, open_bus, send_frames
from gateway.config import parse_config
from gateway.control import Source
from gateway.loop import Gateway
from gateway.types import GatewayState, Twist

if TYPE_CHECKING:
    from collections.abc import Callable

    from gateway.config import GatewayConfig
    from gateway.sim import DeviceSimulator
    from gateway.types import Frame

ROOT = Path(__file__).resolve().parent.parent
PERIOD_S = 0.001
#: Frames per 1 ms cycle on a saturated 1 Mbit/s bus (8-byte standard frames).
SATURATED_PER_CYCLE = 9
TWIST = Twist(0.3, 0.1, 0.2)

#: Motor blocks per protocol, on the same mecanum robot.
PROTOCOLS: dict[str, dict[str, object]] = {
    "odrive": {"driver": "odrive", "firmware": "0.6", "gear_ratio": 10.0, "max_rpm": 3000},
    "vesc": {"driver": "vesc", "pole_pairs": 7, "gear_ratio": 10.0, "max_rpm": 3000},
    "cia402": {"driver": "cia402", "gear_ratio": 10.0, "max_rpm": 3000},
    "dji": {"driver": "dji", "esc": "c620", "gear_ratio": 19.203208556149733, "max_rpm": 9000},
    "dbc": {
        "driver": "dbc",
        "dbc": str(ROOT / "config" / "example_controller.dbc"),
        "gear_ratio": 10.0,
        "max_rpm": 3000,
        "command_message": "WD_Velocity_Command",
        "command_signal": "Target_Velocity",
        "command_unit": "rpm",
        "feedback_message": "WD_Feedback",
        "velocity_signal": "Actual_Velocity",
        "velocity_unit": "rpm",
        "position_signal": "Position_Count",
        "position_unit": "counts",
        "counts_per_rev": 4096,
        "position_wrap_bits": 32,
        "fault_message": "WD_Feedback",
        "fault_signal": "Fault_Code",
        "enable_message": "WD_Enable",
        "enable_signal": "Enable",
    },
}


def robot_config(protocol: str, channel: str) -> GatewayConfig:
    """The 4-wheel mecanum demo robot with ``protocol`` motors on a virtual channel."""
    raw: dict[str, object] = {
        "name": f"bench_{protocol}",
        "drive": "mecanum",
        "geometry": {"wheel_radius": 0.05, "wheelbase": 0.40, "track": 0.36},
        "motor_defaults": PROTOCOLS[protocol],
        "motors": {
            "front_left": {"node_id": 1},
            "front_right": {"node_id": 2, "invert": True},
            "rear_left": {"node_id": 3},
            "rear_right": {"node_id": 4, "invert": True},
        },
        "limits": {"max_wheel_accel_rad_s2": 60.0, "max_linear_m_s": 1.5,
                   "max_angular_rad_s": 3.0},
        "bus": {"interface": "virtual", "channel": channel, "bitrate": 1_000_000},
        "gateway": {"rate_hz": 1000.0, "cmd_timeout_s": 0.0},
    }
    return parse_config(raw, f"<bench {protocol}>")


def clock_overhead_ns(clock: Callable[[], int], samples: int = 20_000) -> float:
    """The cost of an empty timed region (two clock reads), subtracted from every cycle."""
    runs = []
    for _ in range(5):
        total = 0
        for _ in range(samples):
            t0 = clock()
            total += clock() - t0
        runs.append(total / samples)
    return min(runs)


@dataclasses.dataclass
class Sims:
    """The device simulators on their own bus, stepped by hand (their output recorded)."""

    simulators: list[DeviceSimulator]
    bus: can.BusABC

    def step(self, now_s: float) -> list[Frame]:
        out: list[Frame] = []
        for frame in drain(self.bus):
            for sim in self.simulators:
                out.extend(sim.handle(frame, now_s))
        for sim in self.simulators:
            out.extend(sim.tick(now_s))
        send_frames(self.bus, out)
        return out


@dataclasses.dataclass
class Result:
    """One protocol and one feedback mix."""

    protocol: str
    mix: str
    sent_per_cycle: float
    received_per_cycle: float
    gateway_us: list[float]  # per cycle, one value per repeat
    bare_us: list[float]

    @property
    def frames_per_cycle(self) -> float:
        return self.sent_per_cycle + self.received_per_cycle

    def rate(self, us: float) -> float:
        return self.frames_per_cycle / us * 1e6


class Bench:
    """One protocol's gateway, its feedback pool and the python-can baseline buses."""

    def __init__(self, protocol: str, clock: Callable[[], int] = time.process_time_ns,
                 overhead_ns: float | None = None) -> None:
        self.protocol = protocol
        self.clock = clock
        self.overhead_ns = clock_overhead_ns(clock) if overhead_ns is None else overhead_ns
        self.channel = f"wgtp-{protocol}"
        self.cfg = robot_config(protocol, self.channel)
        self.gw = Gateway(self.cfg, stamp_with_cycle_time=True)
        self.t = 0.0
        self.pool: list[list[Frame]] = []
        self.injector = open_bus("virtual", self.channel)
        self.bare_channel = f"{self.channel}-bare"
        self.bare_injector = open_bus("virtual", self.bare_channel)
        self.bare = open_bus("virtual", self.bare_channel)

    def close(self) -> None:
        for bus in (self.bare, self.bare_injector, self.injector):
            bus.shutdown()
        self.gw.close()

    def record_pool(self, seconds: float = 2.0, enable_cycles: int = 2000,
                    twist_cycles: int = 1000) -> None:
        """Enable against the simulators, then record their output per cycle."""
        sims = Sims(self.gw.drives.simulators(), open_bus("virtual", self.channel))
        try:
            gw = self.gw
            gw.supervisor.enable(self.t)

            def run(cycles: int, record: bool) -> None:
                for _ in range(cycles):
                    gw.cycle(self.t)
                    got: list[Frame] = []
                    got += sims.step(self.t + PERIOD_S / 2)
                    got += sims.step(self.t + PERIOD_S)
                    if record:
                        self.pool.append(got)
                    self.t += PERIOD_S

            run(enable_cycles, False)
            if gw.state is not GatewayState.RUNNING:
                raise SystemExit(f"{self.protocol}: did not enable: {gw.supervisor.reason}")
            gw.twist(TWIST, self.t, Source.SOCKET)
            run(twist_cycles, False)
            sent0 = gw.counts["frames_sent"]
            run(round(seconds / PERIOD_S), True)
            self.sent_estimate = (gw.counts["frames_sent"] - sent0) / len(self.pool)
        finally:
            sims.bus.shutdown()
        self.gw.cycle(self.t)  # takes what the simulators sent after the last cycle
        self.t += PERIOD_S
        while self.injector.recv(0.0) is not None:  # what was sent so far
            pass

    def schedule(self, mix: str, cycles: int) -> list[list[can.Message]]:
        """The frames to inject before each cycle."""
        flat = [f for group in self.pool for f in group]
        if not flat:
            raise SystemExit(f"{self.protocol}: the simulators sent nothing")
        msgs = {id(f): can.Message(arbitration_id=f.arbitration_id, data=f.data,
                                   is_extended_id=f.is_extended_id,
                                   is_remote_frame=f.is_remote_frame, dlc=f.dlc)
                for f in flat}
        if mix == "1 kHz mix":
            groups = [self.pool[k % len(self.pool)] for k in range(cycles)]
            return [[msgs[id(f)] for f in g] for g in groups]
        sent = self.sent_estimate
        per = max(1, SATURATED_PER_CYCLE - round(sent))
        return [[msgs[id(flat[(k * per + j) % len(flat)])] for j in range(per)]
                for k in range(cycles)]

    sent_estimate = 4.0

    def run_gateway(self, schedule: list[list[can.Message]], profile: cProfile.Profile | None
                    ) -> tuple[float, int, int, list[list[can.Message]]]:
        """Time ``Gateway.cycle`` over the schedule; return (ns, sent, received, sent msgs)."""
        gw, inj = self.gw, self.injector
        sent0, recv0 = gw.counts["frames_sent"], gw.counts["frames_received"]
        total = 0.0
        sent_msgs: list[list[can.Message]] = []
        clock = self.clock
        for group in schedule:
            for msg in group:
                inj.send(msg)
            if profile is not None:
                profile.enable()
            t0 = clock()
            gw.cycle(self.t)
            total += clock() - t0 - self.overhead_ns
            if profile is not None:
                profile.disable()
            self.t += PERIOD_S
            out = []
            while (m := inj.recv(0.0)) is not None:
                out.append(m)
            sent_msgs.append(out)
        return (total, gw.counts["frames_sent"] - sent0,
                gw.counts["frames_received"] - recv0, sent_msgs)

    def run_bare(self, schedule: list[list[can.Message]],
                 sent_msgs: list[list[can.Message]]) -> tuple[float, int, int]:
        """python-can alone: send the gateway's frames, drain the injected ones."""
        bus, inj, total, sent, received = self.bare, self.bare_injector, 0.0, 0, 0
        clock = self.clock
        for group, out in zip(schedule, sent_msgs, strict=True):
            for msg in group:
                inj.send(msg)
            t0 = clock()
            for msg in out:
                bus.send(msg)
            while bus.recv(0.0) is not None:
                received += 1
            total += clock() - t0 - self.overhead_ns
            sent += len(out)
            while inj.recv(0.0) is not None:
                pass
        return total, sent, received

    def rejected(self) -> int:
        return sum(sum(drv.rejected.values()) for drv, _ in self.gw.drives.groups)

    def measure(self, mix: str, cycles: int, repeats: int,
                profile: cProfile.Profile | None = None) -> Result:
        rejected0 = self.rejected()
        gw_us: list[float] = []
        bare_us: list[float] = []
        sent = received = 0
        for _ in range(repeats):
            schedule = self.schedule(mix, cycles)
            ns, s, r, sent_msgs = self.run_gateway(schedule, profile)
            gw_us.append(ns / cycles / 1000.0)
            bns, bs, br = self.run_bare(schedule, sent_msgs)
            bare_us.append(bns / cycles / 1000.0)
            if (bs, br) != (s, r):
                raise SystemExit(f"{self.protocol}: python-can moved {bs}+{br} frames, "
                                 f"the gateway {s}+{r}")
            sent, received = sent + s, received + r
        if self.gw.state is not GatewayState.RUNNING:
            raise SystemExit(f"{self.protocol}: left RUNNING: {self.gw.supervisor.reason}")
        if self.rejected() != rejected0:
            raise SystemExit(f"{self.protocol}: the drivers rejected injected frames")
        n = cycles * repeats
        return Result(self.protocol, mix, sent / n, received / n, gw_us, bare_us)


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
                        help="cProfile the saturated gateway cycles of one protocol")
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
        import throughput_instructions  # noqa: PLC0415 - it imports this module

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
        profile_one(args.profile, args.cycles * args.repeats, args.sort)
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


def profile_one(protocol: str, cycles: int, sort: str = "tottime") -> None:
    """Print the 25 most expensive functions of the saturated cycles."""
    bench = Bench(protocol)
    try:
        bench.record_pool()
        bench.sent_estimate = bench.measure("1 kHz mix", 200, 1).sent_per_cycle
        prof = cProfile.Profile()
        bench.measure("saturated", cycles, 1, prof)
    finally:
        bench.close()
    stats = pstats.Stats(prof)
    stats.sort_stats(sort).print_stats(30)
    if sort == "tottime":
        stats.print_callers(r"enum\.py")


if __name__ == "__main__":
    main()
