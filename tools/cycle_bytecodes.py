"""Where a gateway cycle's work goes: Python bytecodes executed per cycle, by function.

Callgrind (``bench_throughput.py --instructions``) counts a cycle's machine instructions, exact
and repeatable, but in CPython's C functions: it cannot say which Python function spent them.
This tool counts the other exact, machine-independent quantity: the bytecodes the interpreter
executes (``sys.settrace`` with ``f_trace_opcodes``), per function, on the throughput
benchmark's frames, so a change to the hot path can be judged function by function.

Method, per protocol: the throughput rig's set-up (:mod:`throughput_instructions`: the embedded
mecanum robot on that protocol, enabled against its simulators, a pool of exactly N cycles of
the "1 kHz mix"), then N cycles of each measured loop traced: the gateway (``Gateway.cycle``),
python-can alone on the same frames, the harness both share (putting the delivered frames on a
queue, subtracted from both), and for ODrive and DJI the hand-written loop
(:mod:`anchor_loop`, :mod:`anchor_dji`).  Every executed bytecode counts for the innermost
Python function (``own``) and once for each distinct function on the stack (``inclusive``);
one that runs inside python-can (its package, and whatever it calls: ``queue``, ``threading``,
``copy``, ``logging``) counts as python-can's.
Hash seed 0 (the process re-executes itself with ``PYTHONHASHSEED=0`` when needed), so the
counts repeat exactly.

What a bytecode count leaves out: work done in C below one bytecode (a ``struct`` unpack, a
``deepcopy`` of a message's fields, a lock) counts once however long it runs, so bytecodes are a
map of the Python side, not a cost: the instruction counts stay the measure.  On the DJI mix
one gateway bytecode was about 60 instructions and one of python-can's about 85.

Run: ``.venv/bin/python tools/cycle_bytecodes.py [--protocol NAME ...] [--cycles N] [--top K]``.
"""

from __future__ import annotations

import argparse
import collections
import gc
import os
import re
import sys
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from throughput_instructions import ANCHOR, ANCHOR_LOOPS, SIDES, Anchor, Work, _delivered, run_loop
from throughput_rig import PERIOD_S, PROTOCOLS, Bench

from gateway.core.types import GatewayState

if TYPE_CHECKING:
    import types


def _is_python_can(filename: str) -> bool:
    """Whether the code is python-can's package (``can/`` in site-packages, not ``cantools``'
    ``database/can/``)."""
    return "/site-packages/can/" in filename


#: The project's root: its files are named from there.
_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
#: A library's path up to its package or module (``.../lib/python3.11/[site-packages/]``).
_LIBRARY = re.compile(r".*/lib/python3\.\d+/(?:site-packages/)?")


def _short(code: types.CodeType) -> str:
    """``file:line qualified-name`` of a function, its file from the project's root or from
    its library directory."""
    name = code.co_filename
    if _LIBRARY.match(name):  # (a venv may live in the project's root)
        name = _LIBRARY.sub("", name, count=1)
    elif name.startswith(_ROOT + os.sep):
        name = os.path.relpath(name, _ROOT)
    # (co_qualname: Python 3.11 on; the function's bare name before)
    return f"{name}:{code.co_firstlineno} {getattr(code, 'co_qualname', code.co_name)}"


@dataclass
class Counts:
    """Bytecodes of one traced loop."""

    total: int = 0
    python_can: int = 0
    own: collections.Counter[str] = field(default_factory=collections.Counter)
    inclusive: collections.Counter[str] = field(default_factory=collections.Counter)
    calls: collections.Counter[str] = field(default_factory=collections.Counter)


class Tracer:
    """Counts bytecodes by function while installed (:meth:`run`)."""

    def __init__(self) -> None:
        self.counts = Counts()
        # One entry per active frame: its key, whether it is python-can's, its inclusive count.
        self._stack: list[list[Any]] = []
        self._depth: collections.Counter[str] = collections.Counter()

    def _trace(self, frame: types.FrameType, event: str, arg: object) -> Any:
        c = self.counts
        if event == "opcode":
            top = self._stack[-1]
            top[2] += 1
            c.total += 1
            c.own[top[0]] += 1
            if top[1]:
                c.python_can += 1
        elif event == "call":
            frame.f_trace_opcodes = True
            key = _short(frame.f_code)
            inside = (bool(self._stack) and self._stack[-1][1]) or _is_python_can(
                frame.f_code.co_filename)
            self._stack.append([key, inside, 0])
            self._depth[key] += 1
            c.calls[key] += 1
        elif event == "return":
            key, _, n = self._stack.pop()
            self._depth[key] -= 1
            if not self._depth[key]:  # a recursive function counts its bytecodes once
                c.inclusive[key] += n
            if self._stack:
                self._stack[-1][2] += n
        return self._trace

    def run(self, fn: Any, *args: Any) -> None:
        """``fn(*args)`` traced (the frame that calls it is not)."""
        sys.settrace(self._trace)
        try:
            fn(*args)
        finally:
            sys.settrace(None)


def measure(protocol: str, cycles: int) -> dict[str, Counts]:
    """Each loop's bytecodes over ``cycles`` cycles of the 1 kHz mix (harness included)."""
    bench = Bench(protocol, overhead_ns=0.0)
    anchor = Anchor.open(bench) if protocol in ANCHOR_LOOPS else None
    try:
        # (450: the gateway listens 250 ms before it takes an enable, commanders.LISTEN_S)
        bench.record_pool(cycles * PERIOD_S, enable_cycles=450, twist_cycles=300)
        schedule = bench.schedule("1 kHz mix", cycles)
        slots = [[_delivered(m, bench.channel) for m in g] for g in schedule]
        work = Work(slots, bench.run_gateway(schedule[:cycles], None)[3])
        if anchor is not None:
            anchor.warm(slots[:cycles])
        sides = (*SIDES, ANCHOR) if anchor is not None else SIDES
        rejected0 = bench.rejected()
        out: dict[str, Counts] = {}
        gc.collect()
        gc.freeze()
        for side in sides:
            tracer = Tracer()
            tracer.run(run_loop, bench, side, work, cycles, anchor)
            out[side] = tracer.counts
        if bench.gw.state is not GatewayState.RUNNING or bench.rejected() != rejected0:
            raise SystemExit(f"{protocol}: left RUNNING or rejected frames: the counts are "
                             "not those of a running cycle")
        if anchor is not None and not anchor.healthy():
            raise SystemExit(f"{protocol}: the anchor loop lost an axis or a frame")
        return out
    finally:
        if anchor is not None:
            anchor.close()
        bench.close()


def report(protocol: str, got: dict[str, Counts], cycles: int, top: int) -> str:
    """The table of one protocol."""
    # The harness's puts are python-can's queue: out of both loops' totals and shares.
    harness = got["harness"].total
    gw, pcan = got["gateway"], got["python-can"]
    lines = [f"== {protocol}: bytecodes per cycle (1 kHz mix, {cycles} cycles, harness "
             f"{harness / cycles:,.0f} per cycle taken out)"]
    gw_net, pcan_net = gw.total - harness, pcan.total - harness
    gw_pcan = gw.python_can - got["harness"].python_can
    lines.append(f"gateway {gw_net / cycles:,.1f}   of which python-can's {gw_pcan / cycles:,.1f}, "
                 f"the gateway's own {(gw_net - gw_pcan) / cycles:,.1f}")
    lines.append(f"python-can alone {pcan_net / cycles:,.1f}   ratio gateway / python-can alone "
                 f"{gw_net / pcan_net:.2f}x")
    if ANCHOR in got:
        anchor = got[ANCHOR].total - harness
        a_pcan = got[ANCHOR].python_can
        lines.append(f"hand-written loop {anchor / cycles:,.1f}   of which python-can's "
                     f"{a_pcan / cycles:,.1f}, its own {(anchor - a_pcan) / cycles:,.1f}   ratio "
                     f"gateway / hand-written {gw_net / anchor:.2f}x")
    if top:
        lines.append(f"-- the gateway's functions, top {top} by inclusive count (per cycle: "
                     "inclusive, own, calls)")
    # (the harness's puts taken out here too: the same frames, so the same calls)
    h = got["harness"]
    inclusive, own, calls = gw.inclusive - h.inclusive, gw.own - h.own, gw.calls - h.calls
    listed = [(key, n) for key, n in inclusive.most_common()
              if not key.startswith("tools/")][:top]  # (not this tool's own loop)
    for key, n in listed:
        lines.append(f"{n / cycles:9,.1f} {own[key] / cycles:8,.1f} "
                     f"{calls[key] / cycles:6.2f}  {key}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n", 1)[0])
    parser.add_argument("--protocol", action="append", choices=sorted(PROTOCOLS),
                        help="only these protocols (repeatable; default: every one)")
    parser.add_argument("--cycles", type=int, default=200, help="traced cycles per loop")
    parser.add_argument("--top", type=int, default=30, help="functions listed per protocol")
    args = parser.parse_args(argv)
    if args.cycles < 1 or args.top < 0:
        parser.error(f"--cycles: expected at least 1, got {args.cycles}; --top: expected at "
                     f"least 0, got {args.top}")
    print(__doc__.split("\n\n", 2)[2].split("\nRun:", 1)[0].strip(), flush=True)
    for protocol in args.protocol or sorted(PROTOCOLS):
        print()
        print(report(protocol, measure(protocol, args.cycles), args.cycles, args.top),
              flush=True)


if __name__ == "__main__":
    if os.environ.get("PYTHONHASHSEED") != "0":
        os.execve(sys.executable, [sys.executable, *sys.argv],
                  {**os.environ, "PYTHONHASHSEED": "0"})
    main()
