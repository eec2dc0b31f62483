"""What the parts of a gateway cycle cost in instructions: the cycle with each part a no-op.

:mod:`cycle_bytecodes` maps a cycle's bytecodes by function; bytecodes are not instructions (a
tuple hashed into a ``Counter`` is one bytecode and about two thousand instructions).  This tool
measures instructions, by ablation: the throughput benchmark's count of one gateway cycle
(:func:`throughput_instructions.measure`: callgrind, the embedded robot on one protocol, the same
delivered frames, I(2N) - I(N) over N cycles, the harness taken out), once as the gateway is and
once with each part below replaced by a no-op in the measured process, then with every check and
tally at once (the work a hand-written loop does not do: :mod:`anchor_dji`, :mod:`anchor_loop`).
What a part costs is the difference.  Python-can alone is measured in every run, and for ODrive
and DJI the hand-written loop in the first.

A measurement device only: a gateway without a part is not a safe one.  The patched process
checks what every throughput measurement checks (the gateway still RUNNING, no injected frame
rejected), which the parts below keep.

Run: ``.venv/bin/python tools/cycle_ablation.py [--protocol NAME] [--cycles N] [--jobs J]``.
"""

from __future__ import annotations

import argparse
import contextlib
import sys
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import throughput_instructions
from throughput_instructions import ANCHOR, ANCHOR_LOOPS, MIXES, Row
from throughput_rig import PROTOCOLS

from gateway.bus.edge import BusEdge
from gateway.core.control import Supervisor
from gateway.core.kinematics.lsq import FkPlan
from gateway.core.odom_feed import OdomFeed
from gateway.core.tracking import TrackingMonitor
from gateway.drive.liveness import Liveness
from gateway.runtime.loop import Gateway

if TYPE_CHECKING:
    from collections.abc import Callable, Iterable, Iterator, Sequence

    from gateway.core.types import WheelFeedback


def _nothing(self: object, *args: object) -> None:
    """The no-op of a part whose result the cycle does not need (``None``: no fault)."""


def _heard_oldest_only(self: Liveness, index: int, stream: int, t: float) -> None:
    self.oldest[index] = t


def _positions_as_they_are(self: OdomFeed, feedback: Sequence[WheelFeedback | None]
                           ) -> list[float | None]:
    return [None if fb is None else fb.position_rad for fb in feedback]


def _fit_without_residual(self: FkPlan, n: int, rhs: list[float], per_wheel: bool
                          ) -> tuple[float, float, float, float, list[float] | None]:
    # FkPlan._fit's first loop, as written there (the same work, so the difference is the
    # residual's alone), without the residual's loops.
    vx = vy = wz = 0.0
    for px, py, pw, b in zip(self.pinv_x, self.pinv_y, self.pinv_w, rhs, strict=True):
        vx += px * b
        vy += py * b
        wz += pw * b
    return vx, vy, wz, 0.0, [0.0] * n if per_wheel else None


@dataclass(frozen=True)
class Part:
    """One part of the cycle and the no-op that replaces it.

    :param what: what the cycle leaves out without it.
    :param owner: the class whose method is replaced.
    :param method: the method's name.
    :param replacement: the function put in its place.
    """

    what: str
    owner: type
    method: str
    replacement: Callable[..., Any]


PARTS: dict[str, Part] = {
    "supervision": Part("the supervisor's checks of the running motors (faults, liveness, "
                        "the tracking check)", Supervisor, "_running_check", _nothing),
    "tracking": Part("the tracking check alone (part of supervision)", TrackingMonitor, "check",
                     _nothing),
    "liveness": Part("the liveness bookkeeping per feedback frame (the newest time kept)",
                     Liveness, "heard", _heard_oldest_only),
    "jumps": Part("the odometry's position-jump test", OdomFeed, "positions",
                  _positions_as_they_are),
    "residual": Part("the odometry's slip residual", FkPlan, "_fit", _fit_without_residual),
    "tallies": Part("the frame tallies per identifier (monitor, bus load)", BusEdge, "_tally",
                    _nothing),
    "odometry": Part("the whole odometry (feed and integration)", Gateway, "_integrate",
                     _nothing),
}

#: What the gateway does every cycle and a hand-written loop does not: removed together.
CHECKS = ("supervision", "liveness", "jumps", "residual", "tallies")


@contextlib.contextmanager
def removed(names: Iterable[str]) -> Iterator[None]:
    """Replace the named :data:`PARTS` by their no-ops until the block ends."""
    kept: list[tuple[type, str, object]] = []
    try:
        for name in names:
            part = PARTS[name]
            kept.append((part.owner, part.method, part.owner.__dict__[part.method]))
            setattr(part.owner, part.method, part.replacement)
        yield
    finally:
        for owner, method, original in reversed(kept):
            setattr(owner, method, original)


def _child(argv: list[str]) -> None:
    """The measured process: ``--child NAMES`` (comma-separated, may be empty) and then
    :func:`throughput_instructions.main`'s arguments."""
    names = [n for n in argv[1].split(",") if n]
    with removed(names):
        throughput_instructions.main(argv[2:])


@dataclass(frozen=True)
class Variant:
    """One measured cycle: its removed parts and what it measured."""

    removed: tuple[str, ...]
    rows: list[Row]

    def row(self, mix: str) -> Row:
        return next(r for r in self.rows if r.mix == mix)

    @property
    def label(self) -> str:
        if not self.removed:
            return "as it is"
        if self.removed == CHECKS:
            return "without all the checks and tallies"
        return "without " + ", ".join(self.removed)


def measure(protocol: str, cycles: int, names: tuple[str, ...], anchor: bool) -> Variant:
    """One variant under callgrind."""
    launcher = [sys.executable, str(Path(__file__).resolve()), "--child", ",".join(names)]
    rows, _ = throughput_instructions.measure(protocol, cycles, False, anchor, launcher)
    return Variant(names, rows)


def report(protocol: str, cycles: int, variants: list[Variant]) -> list[str]:
    """The table: per variant and mix, the gateway's instructions per cycle, what the removed
    parts cost, and the ratio to python-can alone (of the same run)."""
    base = variants[0]
    head = "".join(f" | {mix}: gateway, saved, / python-can" for mix in MIXES)
    lines = [f"== {protocol}: instructions per cycle ({cycles} cycles, callgrind; python-can "
             "alone " + ", ".join(f"{base.row(m).net('python-can'):,.0f} ({m})"
                                  for m in MIXES) + ")",
             f"{'variant':40}{head}"]
    for v in variants:
        cells = []
        for mix in MIXES:
            gw, pcan = v.row(mix).net("gateway"), v.row(mix).net("python-can")
            saved = base.row(mix).net("gateway") - gw
            cells.append(f" | {gw:11,.0f} {saved:8,.0f} {gw / pcan:6.2f}x")
        lines.append(f"{v.label:40}{''.join(cells)}")
    if ANCHOR in base.row(MIXES[0]).per_cycle:
        cells = []
        for mix in MIXES:
            row = base.row(mix)
            cells.append(f" | {row.net(ANCHOR):11,.0f} {'':8} "
                         f"{row.net(ANCHOR) / row.net('python-can'):6.2f}x")
        lines.append(f"{'hand-written loop':40}{''.join(cells)}")
        everything = next((v for v in variants if v.removed == CHECKS), None)
        if everything is not None:
            row, bare = base.row(MIXES[0]), everything.row(MIXES[0])
            lines.append(
                f"{MIXES[0]}: without its checks and tallies the gateway is "
                f"{bare.net('gateway') / row.net(ANCHOR):.2f}x the hand-written loop; 2x "
                f"python-can alone ({2 * row.net('python-can'):,.0f}) less what they cost "
                f"({row.net('gateway') - bare.net('gateway'):,.0f}) leaves "
                f"{2 * row.net('python-can') - row.net('gateway') + bare.net('gateway'):,.0f} "
                f"for the rest, which the hand-written loop does in {row.net(ANCHOR):,.0f}")
    lines += ["parts: " + "; ".join(f"{n}: {p.what}" for n, p in PARTS.items()),
              "saved: the variant's instructions below the gateway as it is (same mix)"]
    return lines


def main(argv: list[str] | None = None) -> None:
    args_in = sys.argv[1:] if argv is None else argv
    if args_in[:1] == ["--child"]:
        _child(args_in)
        return
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--protocol", choices=sorted(PROTOCOLS), default="dji")
    parser.add_argument("--cycles", type=int, default=200)
    parser.add_argument("--jobs", type=int, default=2, help="callgrind processes at a time")
    parser.add_argument("--parts", default=",".join(PARTS),
                        help=f"comma-separated, of {', '.join(PARTS)}")
    args = parser.parse_args(args_in)
    names = [n for n in args.parts.split(",") if n]
    unknown = [n for n in names if n not in PARTS]
    if unknown:
        parser.error(f"--parts: expected names of {', '.join(PARTS)}, got {', '.join(unknown)}")
    plan = [(), *((n,) for n in names), CHECKS]
    anchor = args.protocol in ANCHOR_LOOPS
    print(__doc__.split("\n\n")[1].replace("\n", " "), flush=True)
    with ThreadPoolExecutor(max_workers=max(args.jobs, 1)) as pool:
        futures = [pool.submit(measure, args.protocol, args.cycles, v, anchor and not v)
                   for v in plan]
        variants = [f.result() for f in futures]
    print("\n".join(report(args.protocol, args.cycles, variants)))


if __name__ == "__main__":
    main()
