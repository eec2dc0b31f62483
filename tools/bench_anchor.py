"""Benchmark: wheelgate against the loop a robot builder would write instead (the anchor).

The anchor is :mod:`anchor_loop`: for the embedded default robot (4-wheel mecanum, four ODrive
0.6 axes) it receives and decodes the ODrives' frames, solves the mecanum inverse kinematics,
sends four Set_Input_Vel frames and integrates odometry, with python-can and ``struct`` only.

Per cycle (``--skip-cycle`` leaves it out): instructions counted by valgrind's callgrind
(``--cache-sim=no``), by the machinery of the throughput benchmark (``bench_throughput.py
--instructions``, whose method it prints), with a fourth measured loop, on the SAME delivered
frames:

* gateway: ``Gateway.cycle`` (receive and decode, supervise, inverse kinematics and limits,
  four Set_Input_Vel, odometry, WG odometry and status frames at their rates);
* anchor: ``AnchorLoop.cycle`` on a bus of its own, with one other bus on its channel as the
  gateway's and python-can's buses have (each send costs python-can's one copy), its twist
  the gateway's (0.3 m/s, 0.1 m/s, 0.2 rad/s), warmed over the first N cycles before the forks
  (every axis's position and heartbeat known); checked at the end of every child: every frame
  taken, every axis error-free in CLOSED_LOOP_CONTROL, four frames sent per cycle;
* python-can alone: the gateway's sent frames sent again and the delivered frames received.

The frames: "1 kHz mix" is what four simulated ODrives send per 1 ms cycle while the robot
drives (encoder estimates every 10 ms, heartbeats every 100 ms per axis), recorded from the
device simulators; "saturated" fills the bus to 9 frames per cycle.  The harness (putting
each cycle's frames on a queue) is subtracted from every side.  The ratios are gateway /
anchor and gateway / python-can alone.

Start-up (``--skip-startup`` leaves it out): ``wheelgate ik --vx 0.1`` (the installed console
script, run by this interpreter) against ``python -c "import numpy, yaml, click"`` (the
libraries the CLI stands on), ``python -c "import can, yaml"`` (the anchor's) and ``python -c
pass`` (the interpreter alone): instructions of
the whole process under callgrind (hash seed 0, after one untimed run so the bytecode caches
exist; the median of ``--instr-runs`` runs, as a whole interpreter start-up varies by a few
per cent from run to run even so), and the median and best wall time of ``--runs`` runs each,
interleaved.  What varies is numpy's OpenBLAS: it starts a worker thread per further CPU at
import, and what they execute while the start-up lasts depends on the scheduler (on this 2-CPU
VM about 40 million instructions, give or take 5 million).  So every command is also counted
with ``OPENBLAS_NUM_THREADS=1`` (no worker threads; OpenBLAS's documented variable), twice:
those counts repeat to the instruction, and their difference is each command's own cost.

``--protocol dji``: the same robot on four DJI C620 ESCs, against :mod:`anchor_dji` (the
builder's loop with a rotor-speed PI per motor, as the ESCs take a current only): the
feedback is the ESCs' own, every ESC at 1 kHz; the anchor sends one frame a cycle.

Run: ``.venv/bin/python tools/bench_anchor.py [--protocol odrive|dji] [--instr-cycles N]
[--verify] [--runs R] [--instr-runs K] [--skip-cycle] [--skip-startup]``.
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import bench_throughput
import callgrind
import throughput_instructions
from anchor_loop import Robot
from throughput_instructions import ANCHOR, Row
from throughput_rig import robot_raw

#: The start-up commands after the interpreter (``None``: the CLI, see startup_commands).
STARTUP: tuple[tuple[str, tuple[str, ...] | None], ...] = (
    ("wheelgate ik --vx 0.1", None),
    ("import numpy, yaml, click", ("-c", "import numpy, yaml, click")),
    ("import can, yaml (the anchor's)", ("-c", "import can, yaml")),
    ("python -c pass", ("-c", "pass")),
)


def _doc(part: str) -> str:
    """One paragraph group of the docstring, by its first words."""
    return next(p for p in __doc__.split("\n\n") if p.startswith(part))


def check_robot() -> None:
    """The benchmark's robot is the embedded default robot, as the anchor reads it."""
    bench = Robot.from_mapping(robot_raw("odrive", "x"), "<bench odrive>")
    default = Robot.from_file()
    if bench != default:
        raise SystemExit(f"the throughput rig's ODrive robot {bench} differs from the embedded "
                         f"default robot {default}")


def run_cycle(cycles: int, verify: bool, protocol: str = "odrive") -> list[Row]:
    """Instructions per cycle of the four loops; prints the method and the table."""
    print(_doc("Per cycle") + "\n\n" + _doc("The frames") + "\n")
    if protocol == "dji":
        print(_doc("``--protocol dji``") + "\n")
    method = (bench_throughput.__doc__ or "").split("\n\nInstructions", 1)[1]
    print("The throughput benchmark's instruction method:\nInstructions"
          + method.split("\n\nRun:")[0].split("  ``bench_anchor.py``")[0] + "\n")
    print(f"Python {platform.python_version()} on {platform.machine()}, {protocol}, "
          f"N = {cycles} cycles"
          f"{', --verify' if verify else ''}; measured "
          f"{time.strftime('%Y-%m-%d %H:%M:%S %Z')}\n", flush=True)
    rows, drift = throughput_instructions.measure(protocol, cycles, verify, anchor=True)
    print("mix        gw sent  anchor sent  recv   gw Ir/c  anchor Ir/c  pcan Ir/c  harn Ir/c"
          "  gw/anchor  gw/pcan"
          + ("  repeat gw/anchor/pcan       linearity gw/anchor/pcan" if verify else ""))
    for r in rows:
        gw, an, pc = r.net("gateway"), r.net(ANCHOR), r.net("python-can")
        line = (f"{r.mix:10} {r.sent:7.2f} {r.anchor_sent:12.2f} {r.received:5.2f} "
                f"{gw:9,.0f} {an:12,.0f} {pc:10,.0f} {r.per_cycle['harness']:10,.0f} "
                f"{gw / an:9.2f}x {gw / pc:7.2f}x")
        if verify:
            for check in (0, 1):
                line += "  " + "/".join(f"{r.checks[s][check]:+.1e}"
                                        for s in ("gateway", ANCHOR, "python-can"))
        print(line)
    print(f"\nparent drift per fork (taken out): {drift:,.0f} instructions; columns: frames "
          "per cycle sent by the gateway and by the anchor, received by both; instructions "
          "per cycle of the gateway, the anchor and python-can alone (harness subtracted), of "
          "the harness; ratios"
          + ("; --verify: the N-cycle run repeated (difference over I(2N)-I(N)) and "
             "(I(3N)-I(2N))/(I(2N)-I(N))-1" if verify else ""), flush=True)
    return rows


def startup_commands() -> list[tuple[str, list[str]]]:
    """The start-up commands, each run by this interpreter: the installed console script
    ``wheelgate`` beside it, else ``-m gateway``."""
    script = Path(sys.executable).parent / "wheelgate"
    cli = [str(script)] if script.exists() else ["-m", "gateway"]
    out = []
    for label, args in STARTUP:
        if args is None:
            out.append((label if script.exists() else "python -m gateway ik --vx 0.1",
                        [sys.executable, *cli, "ik", "--vx", "0.1"]))
        else:
            out.append((label, [sys.executable, *args]))
    return out


def _run(argv: list[str], env: dict[str, str] | None = None) -> float:
    t0 = time.perf_counter()
    proc = subprocess.run(argv, capture_output=True, check=False, env=env)
    elapsed = time.perf_counter() - t0
    if proc.returncode != 0:
        raise SystemExit(f"{' '.join(argv)}: expected exit status 0, got {proc.returncode}: "
                         f"{proc.stderr.decode(errors='replace')[-600:]}")
    return elapsed


def _instructions(label: str, argv: list[str], env: dict[str, str]) -> int:
    """The instructions of one run of ``argv`` under callgrind (one process expected)."""
    with tempfile.TemporaryDirectory(prefix="wg-callgrind-") as tmp:
        counts = callgrind.run(argv, Path(tmp), env)
    if len(counts) != 1:
        raise SystemExit(f"{label}: expected one process under callgrind, got {len(counts)}")
    return next(iter(counts.values()))


def run_startup(runs: int, instr_runs: int = 5) -> dict[str, tuple[int, float, float]]:
    """Per command: (instructions, median wall s, best wall s); prints the table."""
    print("\n" + _doc("Start-up") + "\n", flush=True)
    commands = startup_commands()
    env = {"PYTHONHASHSEED": "0"}
    # Bytecode caches written, as an installed package has them (PYTHONDONTWRITEBYTECODE in
    # the environment would leave wheelgate's modules compiled from source on every run).
    writes = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    for _, argv in commands:
        _run(argv, writes)
    wall: dict[str, list[float]] = {label: [] for label, _ in commands}
    for _ in range(runs):
        for label, argv in commands:
            wall[label].append(_run(argv))
    instr: dict[str, list[int]] = {label: [] for label, _ in commands}
    for _ in range(instr_runs):
        for label, argv in commands:
            instr[label].append(_instructions(label, argv, env))
    exact: dict[str, list[int]] = {label: [] for label, _ in commands}
    single = {**env, "OPENBLAS_NUM_THREADS": "1"}
    for _ in range(2):
        for label, argv in commands:
            exact[label].append(_instructions(label, argv, single))
    out: dict[str, tuple[int, float, float]] = {
        label: (int(statistics.median(instr[label])), statistics.median(wall[label]),
                min(wall[label]))
        for label, _ in commands
    }
    print(f"command                         instructions (median; range)       median ms   "
          f"best ms   ({instr_runs} / {runs} runs, load average {os.getloadavg()[0]:.2f})")
    for label, (ir, med, best) in out.items():
        spread = f"{min(instr[label]):,}-{max(instr[label]):,}"
        print(f"{label:30} {ir:14,} ({spread:>27}) {med * 1e3:10.1f} {best * 1e3:9.1f}")
    (cli, cli_v), (lib, lib_v) = list(out.items())[:2]
    print(f"\n{cli} / {lib}: {cli_v[0] / lib_v[0]:.2f}x instructions, "
          f"{cli_v[1] / lib_v[1]:.2f}x median wall time", flush=True)
    print("\nwith OPENBLAS_NUM_THREADS=1 (two runs each; they must agree):")
    for label, both in exact.items():
        same = "the same" if len(set(both)) == 1 else f"DIFFER: {both}"
        print(f"{label:30} {both[0]:14,}  ({same})")
    cli_x, lib_x = exact[cli][0], exact[lib][0]
    print(f"{cli} / {lib}: {cli_x / lib_x:.3f}x instructions; wheelgate's own "
          f"{cli_x - lib_x:,}", flush=True)
    return out


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--instr-cycles", type=int, default=200,
                        help="N: cycles per differenced run (and the pool length)")
    parser.add_argument("--verify", action="store_true",
                        help="repeat every N-cycle child and add a 3N one (repeatability)")
    parser.add_argument("--runs", type=int, default=30, help="wall-time runs per command")
    parser.add_argument("--instr-runs", type=int, default=5,
                        help="start-up runs under callgrind per command (median)")
    parser.add_argument("--protocol", choices=("odrive", "dji"), default="odrive",
                        help="the motors of the cycle's robot and anchor (dji: anchor_dji.py)")
    parser.add_argument("--skip-cycle", action="store_true")
    parser.add_argument("--skip-startup", action="store_true")
    args = parser.parse_args(argv)
    callgrind.valgrind()
    check_robot()
    if not args.skip_cycle:
        run_cycle(args.instr_cycles, args.verify, args.protocol)
    if not args.skip_startup:
        run_startup(args.runs, args.instr_runs)


if __name__ == "__main__":
    main()
