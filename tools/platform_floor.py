"""What the machine itself costs a 1 kHz loop: the benchmarks' platform floor.

Three independent readings, none of which runs any wheelgate work:

* :func:`empty_loop`: the daemon's own scheduler (absolute deadlines, sleep then spin) with
  nothing to do, in the calling thread and so under its scheduling policy;
* :func:`cyclictest`: the same rate and priority in C, with rt-tests' ``cyclictest`` (the
  usual real-time latency test of the Linux RT community, ``apt install rt-tests``), when it
  is on the PATH: deadlines it had to skip (it skips, as the daemon does) and its worst
  wake-up latency;
* :func:`steal_s`: CPU time the hypervisor took from this virtual machine (the ``steal``
  column of ``/proc/stat``), read before and after a run.

A loop that misses deadlines while these show the same misses, or stolen time, is held up by
the machine, not by its own work.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from gateway.timing import LoopTimer, Scheduler, TimingStats

#: Width of cyclictest's latency histogram (us); later wake-ups count as overflows.
HISTOGRAM_US = 2000


def empty_loop(seconds: float, rate_hz: float, spin_s: float) -> TimingStats:
    """The daemon's scheduler with no work at all, in this thread (same scheduling policy):
    the misses and tails the machine itself causes."""
    timer = LoopTimer(rate_hz, capacity=int(seconds * rate_hz) + 100)
    sched = Scheduler(rate_hz, spin_s=spin_s, timer=timer)
    end = time.perf_counter() + seconds
    while time.perf_counter() < end:
        sched.wait_next()
        sched.end_cycle()
    return timer.snapshot()


def steal_s() -> float | None:
    """CPU time stolen from this machine by its hypervisor since boot, all CPUs (s).

    ``None`` where ``/proc/stat`` has no steal column (not Linux, or no hypervisor support).
    """
    try:
        with open("/proc/stat", encoding="ascii") as stat:
            fields = stat.readline().split()
    except OSError:
        return None
    if len(fields) < 9 or fields[0] != "cpu":
        return None
    return int(fields[8]) / os.sysconf("SC_CLK_TCK")


@dataclass(frozen=True, slots=True)
class CyclicTest:
    """A cyclictest run: one thread at a fixed interval.

    :param expected: wake-ups the run's duration holds at that interval.
    :param loops: wake-ups it had; ``expected - loops`` deadlines were skipped.
    :param max_us: the worst wake-up latency.
    :param late: wake-ups a whole interval or more late.
    :param command: the command line, for the report.
    """

    expected: int
    loops: int
    max_us: int
    late: int
    command: str

    @property
    def skipped(self) -> int:
        """Deadlines skipped after a late wake-up (never negative)."""
        return max(0, self.expected - self.loops)


def cyclictest(seconds: float, rate_hz: float, priority: int) -> CyclicTest | str:
    """Run cyclictest for ``seconds`` at ``rate_hz`` with SCHED_FIFO ``priority``.

    :return: the reading, or why there is none (not installed, refused, unreadable output).
    """
    exe = shutil.which("cyclictest")
    if exe is None:
        return "cyclictest not installed (apt install rt-tests)"
    if priority <= 0:
        return "cyclictest needs a real-time priority (--rt)"
    interval_us = round(1e6 / rate_hz)
    duration = max(1, round(seconds))
    with tempfile.TemporaryDirectory(prefix="wgct") as folder:
        out = Path(folder) / "histogram.txt"
        shown = (f"--mlockall --priority={priority} --interval={interval_us} "
                 f"--duration={duration} --quiet --histogram={HISTOGRAM_US} --threads=1")
        cmd = [exe, *shown.split(), f"--histfile={out}"]
        try:
            subprocess.run(cmd, check=True, capture_output=True, timeout=duration + 30)
            text = out.read_text(encoding="ascii")
        except (OSError, subprocess.SubprocessError) as err:
            return f"cyclictest failed: {err}"
    return _parse(text, round(duration * 1e6 / interval_us), interval_us, shown)


def _parse(text: str, expected: int, interval_us: int, command: str) -> CyclicTest | str:
    """Read cyclictest's histogram file: ``NNNNNN count`` lines, then ``# Key: value`` lines.

    >>> r = _parse("000009 5\\n001200 1\\n# Total: 000000006\\n# Max Latencies: 02500\\n"
    ...            "# Histogram Overflows: 00002\\n", 10, 1000, "")
    >>> (r.loops, r.skipped, r.max_us, r.late) if isinstance(r, CyclicTest) else r
    (8, 2, 2500, 3)
    """
    loops = max_us = overflows = late = 0
    found = set()
    for line in text.splitlines():
        if line.startswith("#"):
            key, _, rest = line[1:].partition(":")
            key, values = key.strip(), rest.split()
            if key in ("Total", "Max Latencies", "Histogram Overflows") and values:
                found.add(key)
                number = int(values[0])
                if key == "Total":
                    loops = number
                elif key == "Max Latencies":
                    max_us = number
                else:
                    overflows = number
            continue
        parts = line.split()
        if len(parts) >= 2 and parts[0].isdigit() and int(parts[0]) >= interval_us:
            late += int(parts[1])
    if len(found) < 3:
        return f"cyclictest output unreadable (found {sorted(found)})"
    # "Total" counts the histogram's buckets only; the overflows were wake-ups too.
    return CyclicTest(expected, loops + overflows, max_us, late + overflows, command)
