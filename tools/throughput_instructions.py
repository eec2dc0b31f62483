"""Instructions per cycle of the throughput benchmark, counted by callgrind (``--instructions``).

The method is described in :mod:`bench_throughput` (and printed by it).  This module has two
halves: the measuring process, which runs under callgrind (``main`` below: one per protocol,
it sets up once and forks one child per measured loop), and :func:`run_instructions`, the
driver that starts those processes, differences their counts and prints the table.

With ``anchor=True`` (ODrive and DJI) a fourth loop is measured on the same delivered frames:
the hand-written loop of :mod:`anchor_loop` (:mod:`anchor_dji`), on a bus pair of its own
(:mod:`bench_anchor`).
"""

from __future__ import annotations

import argparse
import copy
import dataclasses
import gc
import json
import os
import queue
import statistics
import sys
import tempfile
import traceback
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import TYPE_CHECKING

import callgrind
import can
from anchor_dji import DjiAnchorLoop
from anchor_loop import AnchorLoop
from can.interfaces.virtual import VirtualBus
from throughput_rig import PERIOD_S, PROTOCOLS, TWIST, Bench, robot_raw

from gateway.core.types import GatewayState

if TYPE_CHECKING:
    from collections.abc import Sequence

MIXES = ("1 kHz mix", "saturated")
#: The measured loops: the gateway's cycle, python-can alone, and the harness common to both
#: (putting the injected frames on the receiving bus's queue), subtracted from each.
SIDES = ("gateway", "python-can", "harness")
#: The hand-written loop's side (``--anchor``): its frames go out on a bus of its own.
ANCHOR = "anchor"
#: The hand-written loop of each protocol that has one.
ANCHOR_LOOPS: dict[str, type[AnchorLoop]] = {"odrive": AnchorLoop, "dji": DjiAnchorLoop}


@dataclasses.dataclass(frozen=True)
class Work:
    """One mix's frames: what is delivered before each cycle, what the gateway sent."""

    slots: list[list[can.Message]]  # delivered copies, one group per cycle
    sent: list[list[can.Message]]  # the gateway's frames of cycles 0..N-1, sent again by pcan


def _delivered(msg: can.Message, channel: str) -> can.Message:
    """The copy a virtual bus puts on a receiver's queue (timestamp fixed, for repeatability)."""
    out = copy.deepcopy(msg)
    out.timestamp, out.channel, out.is_rx = 0.0, channel, True
    return out


def _queue(bus: can.BusABC) -> queue.Queue[can.Message]:
    if not isinstance(bus, VirtualBus):
        raise SystemExit(f"instruction counts: expected a virtual bus, got {type(bus).__name__}")
    return bus.queue


@dataclasses.dataclass(frozen=True)
class Anchor:
    """The hand-written loop on a channel of its own, with one other bus there (as the
    gateway's and python-can's buses have), so each of its sends costs the same copy."""

    loop: AnchorLoop
    peer: can.BusABC

    @classmethod
    def open(cls, bench: Bench) -> Anchor:
        kind = ANCHOR_LOOPS.get(bench.protocol)
        if kind is None:
            raise SystemExit(f"--anchor: the anchor loops drive {', '.join(ANCHOR_LOOPS)}, "
                             f"not {bench.protocol}")
        channel = f"{bench.channel}-anchor"
        loop = kind.from_mapping(robot_raw(bench.protocol, channel),
                                 can.Bus(interface="virtual", channel=channel),
                                 f"<bench {bench.protocol}>")
        loop.set_twist(TWIST.vx_m_s, TWIST.vy_m_s, TWIST.wz_rad_s)
        return cls(loop, can.Bus(interface="virtual", channel=channel))

    def warm(self, slots: list[list[can.Message]]) -> None:
        """Run over ``slots`` once (positions and heartbeats known), then empty the peer."""
        run_anchor(self, slots, len(slots))
        while self.peer.recv(0.0) is not None:
            pass

    def healthy(self) -> bool:
        """The loop's own check (every axis running), and every frame taken."""
        return self.loop.healthy() and _queue(self.loop.bus).empty()

    def close(self) -> None:
        self.loop.bus.shutdown()
        self.peer.shutdown()


def run_anchor(anchor: Anchor, slots: list[list[can.Message]], n: int) -> None:
    """The anchor's measured loop: put each cycle's frames on its bus's queue, one cycle."""
    put, cycle = _queue(anchor.loop.bus).put, anchor.loop.cycle
    for k in range(n):
        for msg in slots[k]:
            put(msg)
        cycle()


def run_loop(bench: Bench, side: str, work: Work, n: int, anchor: Anchor | None = None) -> None:
    """The measured loop: ``n`` cycles of one side, nothing else."""
    slots = work.slots
    if side == ANCHOR:
        if anchor is None:
            raise SystemExit("the anchor side needs the anchor loop (--anchor)")
        run_anchor(anchor, slots, n)
    elif side == "gateway":
        put, cycle, t = _queue(bench.gw.edge.bus).put, bench.gw.cycle, bench.t
        for k in range(n):
            for msg in slots[k]:
                put(msg)
            cycle(t)
            t += PERIOD_S
        bench.t = t
    elif side == "python-can":
        bus, sent = bench.bare, work.sent
        put, send, recv, m = _queue(bus).put, bus.send, bus.recv, len(sent)
        for k in range(n):
            for msg in slots[k]:
                put(msg)
            for msg in sent[k % m]:
                send(msg)
            while recv(0.0) is not None:
                pass
    else:
        sink: queue.Queue[can.Message] = queue.Queue()
        put = sink.put
        for k in range(n):
            for msg in slots[k]:
                put(msg)


def main(argv: list[str] | None = None) -> None:
    """The process under callgrind: set up one protocol once, fork one child per loop."""
    parser = argparse.ArgumentParser()
    parser.add_argument("protocol", choices=sorted(PROTOCOLS))
    parser.add_argument("outdir", type=Path)
    parser.add_argument("--cycles", type=int, required=True)
    parser.add_argument("--multiples", required=True, help="comma-separated, e.g. 1,2")
    parser.add_argument("--anchor", action="store_true", help="also the hand-written loop")
    args = parser.parse_args(argv)
    multiples = [int(m) for m in args.multiples.split(",")]
    n_max = args.cycles * max(multiples)
    bench = Bench(args.protocol, overhead_ns=0.0)
    anchor = Anchor.open(bench) if args.anchor else None
    sides = (*SIDES, ANCHOR) if anchor is not None else SIDES
    # A pool of exactly N cycles: every N-cycle window of the 1 kHz mix holds the same frames.
    # (450: the gateway listens 250 ms before it takes an enable, commanders.LISTEN_S)
    bench.record_pool(args.cycles * PERIOD_S, enable_cycles=450, twist_cycles=300)
    works: dict[str, Work] = {}
    frames: dict[str, dict[int, list[int]]] = {}
    for mix in MIXES:
        schedule = bench.schedule(mix, n_max)
        slots = [[_delivered(m, bench.channel) for m in g] for g in schedule]
        sent = bench.run_gateway(schedule[:args.cycles], None)[3]
        works[mix] = Work(slots, sent)
        if anchor is not None and mix == MIXES[0]:
            anchor.warm(slots[:args.cycles])
        frames[mix] = {n: [sum(len(sent[k % len(sent)]) for k in range(n)),
                           sum(len(slots[k]) for k in range(n))]
                       for n in {args.cycles * m for m in multiples}}
    (args.outdir / "frames.json").write_text(json.dumps(frames))
    plan: list[tuple[str, str, int]] = [("null", "harness", 0)]
    plan += [(mix, side, args.cycles * m) for mix in MIXES for side in sides for m in multiples]
    plan.append(("null", "harness", 0))
    rejected0 = bench.rejected()
    sys.stdout.flush()
    gc.collect()
    gc.freeze()
    for position, (mix, side, n) in enumerate(plan):
        pid = os.fork()
        if pid == 0:
            _child(bench, args.outdir, position, mix, side, works.get(mix), n, rejected0,
                   anchor)
        _, status = os.waitpid(pid, 0)
        if status != 0:
            raise SystemExit(f"{args.protocol} {mix} {side} {n}: child exit status {status}")
    if anchor is not None:
        anchor.close()
    bench.close()


def _child(bench: Bench, outdir: Path, position: int, mix: str, side: str, work: Work | None,
           n: int, rejected0: int, anchor: Anchor | None) -> None:
    """One forked child: the loop, the gateway's checks and counts, then ``os._exit``."""
    status = 0
    try:
        counts = bench.gw.edge.counts
        sent0, recv0 = counts.frames_sent, counts.frames_received
        peer0 = _queue(anchor.peer).qsize() if anchor is not None else 0
        if work is not None:
            run_loop(bench, side, work, n, anchor)
        ok = bench.gw.state is GatewayState.RUNNING and bench.rejected() == rejected0
        if anchor is not None:
            ok = ok and anchor.healthy()
        meta = {"position": position, "mix": mix, "side": side, "n": n, "ok": ok,
                "gw_frames": [counts.frames_sent - sent0, counts.frames_received - recv0],
                "anchor_sent": _queue(anchor.peer).qsize() - peer0 if anchor else 0}
        (outdir / f"meta.{os.getpid()}.json").write_text(json.dumps(meta))
    except BaseException:  # a forked child must never return into the parent's loop
        traceback.print_exc()
        status = 1
    os._exit(status)


@dataclasses.dataclass
class Row:
    """Instructions per cycle for one protocol and mix."""

    protocol: str
    mix: str
    sent: float
    received: float
    per_cycle: dict[str, float]  # side -> (I(2N) - I(N)) / N, harness included
    checks: dict[str, tuple[float, float]]  # side -> (repeat spread, linearity), --verify
    anchor_sent: float = 0.0  # frames the anchor loop sent per cycle (anchor=True)

    def net(self, side: str) -> float:
        return self.per_cycle[side] - self.per_cycle["harness"]


def measure(protocol: str, cycles: int, verify: bool, anchor: bool = False,
            launcher: Sequence[str] | None = None) -> tuple[list[Row], float]:
    """One protocol under callgrind: its rows and the parent's drift per fork.

    :param anchor: also measure the hand-written loop (ODrive: :mod:`anchor_loop`, DJI:
        :mod:`anchor_dji`).
    :param launcher: the command line before :func:`main`'s arguments in the measured
        process (default: this module, run by this interpreter); another script that calls
        :func:`main` with the rest of its arguments (``cycle_ablation.py``).
    """
    multiples = (1, 2, 1, 3) if verify else (1, 2)
    sides = (*SIDES, ANCHOR) if anchor else SIDES
    with tempfile.TemporaryDirectory(prefix="wg-callgrind-") as tmp:
        outdir = Path(tmp)
        start = [sys.executable, str(Path(__file__).resolve())] if launcher is None \
            else list(launcher)
        argv = [*start, protocol, str(outdir),
                "--cycles", str(cycles), "--multiples", ",".join(map(str, multiples)),
                *(["--anchor"] if anchor else [])]
        counts = callgrind.run(argv, outdir, {"PYTHONHASHSEED": "0"})
        metas = []
        for path in outdir.glob("meta.*.json"):
            meta = json.loads(path.read_text())
            meta["ir"] = counts[int(path.name.split(".")[1])]
            metas.append(meta)
        frames = json.loads((outdir / "frames.json").read_text())
    metas.sort(key=lambda m: m["position"])
    if not all(m["ok"] for m in metas):
        raise SystemExit(f"{protocol}: left RUNNING or rejected injected frames"
                         + (", or the anchor loop lost an axis or a frame" if anchor else ""))
    # Each fork comes after the parent's previous fork and wait: a constant drift per
    # position, measured by the empty children at both ends and taken out.
    drift = (metas[-1]["ir"] - metas[0]["ir"]) / metas[-1]["position"]
    ir = {(m["mix"], m["side"], m["n"], i): m["ir"] - drift * m["position"]
          for i, m in enumerate(metas)}
    rows = []
    for mix in MIXES:
        got = {side: [v for (mx, s, _, _), v in sorted(ir.items(), key=lambda kv: kv[0][3])
                      if mx == mix and s == side] for side in sides}
        per_cycle = {side: (v[1] - v[0]) / cycles for side, v in got.items()}
        checks = {}
        if verify:
            for side, v in got.items():
                step = v[1] - v[0]
                checks[side] = ((v[2] - v[0]) / step, (v[3] - v[1]) / step - 1.0)
        gw_meta = next(m for m in metas if m["mix"] == mix and m["side"] == "gateway"
                       and m["n"] == cycles)
        # python-can alone sends the frames of the gateway's first N cycles (before the forks),
        # the measured gateway cycles come later: their publish phases may differ by a frame.
        pcan, gwf = frames[mix][str(cycles)], gw_meta["gw_frames"]
        if pcan[1] != gwf[1] or abs(pcan[0] - gwf[0]) > max(3, pcan[0] // 50):
            raise SystemExit(f"{protocol} {mix}: python-can moved {pcan[0]}+{pcan[1]} frames, "
                             f"the gateway {gwf[0]}+{gwf[1]}")
        anchor_sent = [m["anchor_sent"] for m in metas if m["mix"] == mix
                       and m["side"] == ANCHOR and m["n"] == cycles]
        expected = ANCHOR_LOOPS[protocol].FRAMES_PER_CYCLE * cycles if anchor else 0
        if anchor_sent and anchor_sent[0] != expected:
            raise SystemExit(f"{protocol} {mix}: the anchor loop sent {anchor_sent[0]} frames "
                             f"in {cycles} cycles, expected {expected}")
        rows.append(Row(protocol, mix, gwf[0] / cycles, gwf[1] / cycles, per_cycle, checks,
                        anchor_sent[0] / cycles if anchor_sent else 0.0))
    return rows, drift


def _line(row: Row, verify: bool) -> str:
    gw, pcan = row.net("gateway"), row.net("python-can")
    line = (f"{row.protocol:7} {row.mix:10} {row.sent:5.2f} {row.received:5.2f} "
            f"{gw:9,.0f} {pcan:10,.0f} {row.per_cycle['harness']:10,.0f} {gw / pcan:6.2f}x "
            f"{gw / (row.sent + row.received):12,.0f}")
    if verify:
        line += "  " + "/".join(f"{row.checks[s][0]:+.1e}" for s in SIDES)
        line += "   " + "/".join(f"{row.checks[s][1]:+.1e}" for s in SIDES)
    return line


def run_instructions(protocols: list[str], cycles: int, jobs: int, verify: bool) -> None:
    """Measure every protocol (``jobs`` callgrind processes at a time) and print the table."""
    print("protocol mix        sent  recv   gw Ir/c  pcan Ir/c  harn Ir/c   ratio  gw Ir/frame"
          + ("  repeat gw/pcan/harn        (3N-2N)/(2N-N)-1 gw/pcan/harn" if verify else ""),
          flush=True)
    results: list[tuple[list[Row], float]] = []
    with ThreadPoolExecutor(max_workers=jobs) as pool:
        for future in [pool.submit(measure, p, cycles, verify) for p in protocols]:
            results.append(future.result())
            for row in results[-1][0]:
                print(_line(row, verify), flush=True)
    rows = [row for got, _ in results for row in got]
    ratio = max(r.net("gateway") / r.net("python-can") for r in rows)
    print(f"\nlargest ratio gateway / python-can alone: {ratio:.2f}x (aim 2x); parent drift "
          "per fork (taken out): " + ", ".join(f"{p} {d:,.0f}" for p, (_, d)
                                                in zip(protocols, results, strict=True)))
    print("columns: frames sent and received per cycle; instructions per cycle of the gateway, "
          "of python-can alone (both without the harness) and of the harness; ratio; gateway "
          "instructions per frame moved"
          + ("; --verify: the N-cycle run repeated (difference over I(2N)-I(N)) and the "
             "linearity of the third N cycles" if verify else ""))
    spreads = [abs(c[0]) for r in rows for c in r.checks.values()]
    if spreads:
        print(f"repeatability: largest |repeat difference| / (I(2N)-I(N)) {max(spreads):.1e}, "
              f"median {statistics.median(spreads):.1e}; largest |linearity| "
              f"{max(abs(c[1]) for r in rows for c in r.checks.values()):.1e}")


if __name__ == "__main__":
    main()
