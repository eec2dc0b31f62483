"""What the machine itself costs a 1 kHz loop: the benchmarks' platform floor.

Three independent readings, none of which runs any wheelgate work:

* :func:`fixed_work_loop`: the daemon's own scheduler (absolute deadlines, sleep then spin)
  doing the same constant arithmetic in every cycle, in the calling thread and so under its
  scheduling policy: every spread of its CPU time and every deadline it misses is the
  machine's;
* :func:`cyclictest`: the same rate and priority in C, with rt-tests' ``cyclictest`` (the
  usual real-time latency test of the Linux RT community, ``apt install rt-tests``), when it
  is on the PATH: deadlines it had to skip (it skips, as the daemon does) and its worst
  wake-up latency;
* :func:`steal_s`: CPU time the hypervisor took from this virtual machine (the ``steal``
  column of ``/proc/stat``), read before and after a run.

A loop that misses deadlines while these show the same misses, or stolen time, is held up by
the machine, not by its own work.  The daemon's own
:class:`~gateway.runtime.timing.MissProbe` classifies each of its late starts from the loop thread's
scheduler statistics (on a CPU, runnable but not running, or asleep); :func:`fixed_work_loop`
runs the same probe, so the two compare directly.  On a virtual machine the guest does not
see every stall: a constant workload's CPU time spreads too, and :func:`fixed_work_loop`
shows by how much.
"""

from __future__ import annotations

import argparse
import gc
import os
import shutil
import subprocess
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from gateway.runtime.timing import LoopTimer, MissProbe, Scheduler

if TYPE_CHECKING:
    from gateway.core.status import TimingReport

#: Width of cyclictest's latency histogram (us); later wake-ups count as overflows.
HISTOGRAM_US = 2000


@dataclass(frozen=True, slots=True)
class WorkLoop:
    """A run of :func:`fixed_work_loop`.

    :param stats: the scheduler's timing statistics (late starts by cause included).
    :param work_us: CPU time (p50, p99, max) of the constant workload, cycle by cycle.
    :param late_starts: the :class:`~gateway.runtime.timing.MissProbe`'s description of its late
        starts.
    """

    stats: TimingReport
    work_us: tuple[float, float, float]
    late_starts: str


def _arithmetic(n: int) -> int:
    total = 0
    for i in range(n):
        total += i * i
    return total


def _calibrate(target_us: float) -> int:
    """Iterations of :func:`_arithmetic` whose median CPU time is about ``target_us``."""
    n = 1000
    for _ in range(3):
        costs = []
        for _ in range(51):
            c0 = time.thread_time_ns()
            _arithmetic(n)
            costs.append(time.thread_time_ns() - c0)
        costs.sort()
        n = max(1, round(n * target_us * 1e3 / max(1, costs[25])))
    return n


def fixed_work_loop(seconds: float, rate_hz: float, spin_s: float,
                    work_us: float) -> WorkLoop:
    """The daemon's scheduler running the same pure-Python arithmetic in every cycle, its
    length set so that its median CPU time is ``work_us``, in this thread (same policy).

    Every cycle does exactly the same work, so every spread in its CPU time and every missed
    deadline is the machine's: the floor of a loop that does this much work per cycle.

    >>> run = fixed_work_loop(0.05, 1000.0, 0.0002, 20.0)
    >>> run.stats.cycles > 0 and run.work_us[0] <= run.work_us[1] <= run.work_us[2]
    True
    """
    n = _calibrate(work_us)
    timer = LoopTimer(rate_hz, capacity=int(seconds * rate_hz) + 100)
    sched = Scheduler(rate_hz, spin_s=spin_s, timer=timer)
    probe = MissProbe(sched)
    costs: list[int] = []
    end = time.perf_counter() + seconds
    try:
        while time.perf_counter() < end:
            probe.before_wait()
            probe.after_wait(sched.wait_next())
            c0 = time.thread_time_ns()
            _arithmetic(n)
            costs.append(time.thread_time_ns() - c0)
            sched.end_cycle()
    finally:
        probe.close()
    costs.sort()
    k = len(costs)
    spread = (costs[k // 2] / 1e3, costs[min(k - 1, int(0.99 * k))] / 1e3, costs[-1] / 1e3)
    return WorkLoop(timer.snapshot(), spread, probe.describe())


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


def main() -> None:
    """Run the constant-work control alone (to alternate with ``tools/bench_loop.py``)."""
    parser = argparse.ArgumentParser(description="The constant-work control loop alone: the "
                                     "daemon's scheduler doing fixed arithmetic every cycle.")
    parser.add_argument("seconds", nargs="?", type=float, default=60.0)
    parser.add_argument("--rt", type=int, default=0, metavar="PRIORITY",
                        help="SCHED_FIFO priority (0: normal scheduling)")
    parser.add_argument("--rate", type=float, default=1000.0, help="loop rate, Hz")
    parser.add_argument("--work-us", type=float, default=100.0,
                        help="median CPU time of the work per cycle, us")
    parser.add_argument("--spin-us", type=float, default=200.0,
                        help="spin before each deadline, us (the daemon's default)")
    args = parser.parse_args()
    gc.freeze()  # as the daemon does
    if args.rt:
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(args.rt))
        except OSError as err:
            raise SystemExit(f"SCHED_FIFO {args.rt} refused: {err.strerror or err}") from err
    start = steal_s()
    run = fixed_work_loop(args.seconds, args.rate, args.spin_us * 1e-6, args.work_us)
    end = steal_s()
    w50, w99, wmax = run.work_us
    stolen = "unknown" if start is None or end is None else f"{(end - start) * 1e3:.0f} ms"
    print(f"constant work ({args.work_us:g} us calibrated), {args.seconds:g} s at {args.rate:g} "
          f"Hz: {run.stats.missed} missed; lateness p99 {run.stats.lateness_p99_us:.1f} us; "
          f"work CPU p50 {w50:.1f} us, p99 {w99:.1f} us, max {wmax:.1f} us; stolen {stolen}")
    print("missed cycles by cause: " + run.late_starts)


if __name__ == "__main__":
    main()
