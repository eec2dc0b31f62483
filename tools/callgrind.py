"""Exact instruction counts of a process tree with valgrind's callgrind, for benchmarks.

Callgrind counts the instructions a process executes, whatever else the machine does, so
figures repeat from run to run on a shared or throttled machine where CPU time does not.
Python functions cannot be selected by name (callgrind sees the interpreter's C functions),
so the benchmarks built on this module difference whole processes: the same setup followed by
N and by 2N measured iterations; (I(2N) - I(N)) / N is the cost of one iteration.

:func:`run` runs one command under callgrind with ``--trace-children=no`` (the default) and
one output file per process (``%p``), so a command that forks after its setup gets one total
per forked child, each including the parent's instructions up to the fork.
"""

from __future__ import annotations

import os
import shutil
import subprocess
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from pathlib import Path

#: Cache and branch simulation off: only instructions are counted, about 50x slower than native.
OPTIONS = ("--tool=callgrind", "--cache-sim=no", "--branch-sim=no", "--dump-line=no",
           "--dump-instr=no", "--compress-strings=no")


def valgrind() -> str:
    """The valgrind executable, or a SystemExit that says it is missing."""
    found = shutil.which("valgrind")
    if found is None:
        raise SystemExit("valgrind: not found on PATH (needed for instruction counts; "
                         "install the valgrind package)")
    return found


def totals(path: Path) -> int:
    """The total instruction count of one callgrind output file (its ``totals:`` line)."""
    summary: int | None = None
    with path.open(encoding="utf-8", errors="replace") as f:
        for line in f:
            if line.startswith("totals:"):
                return int(line.split()[1])
            if line.startswith("summary:"):
                summary = int(line.split()[1])
    if summary is None:
        raise SystemExit(f"callgrind output {path}: expected a 'totals:' or 'summary:' line, "
                         "found neither")
    return summary


def run(argv: list[str], outdir: Path, env: dict[str, str] | None = None) -> dict[int, int]:
    """Run ``argv`` under callgrind; return {process id: instructions} for every process.

    ``outdir`` must be empty; it receives the output files ``cg.<pid>``.
    """
    cmd = [valgrind(), *OPTIONS, f"--callgrind-out-file={outdir / 'cg.%p'}", *argv]
    proc = subprocess.run(cmd, env={**os.environ, **(env or {})}, capture_output=True,
                          text=True, check=False)
    if proc.returncode != 0:
        tail = "\n".join(proc.stderr.splitlines()[-20:])
        raise SystemExit(f"callgrind run {' '.join(argv)}: expected exit status 0, "
                         f"got {proc.returncode}:\n{tail}")
    return {int(p.name.split(".")[1]): totals(p) for p in outdir.glob("cg.*")}
