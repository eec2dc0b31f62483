"""Why the loop started late, as far as the kernel can tell: :class:`MissProbe`.

A late start (a deadline a whole period or more in the past, so deadlines were skipped) has
one of three causes, told apart by the loop thread's own scheduler statistics
(``/proc/thread-self/schedstat``: time on a CPU, time runnable but waiting for one) over the
interval from the previous cycle's start to the late one:

* :attr:`MissCause.ON_CPU`: the thread ran for more than a period (its spin before each
  deadline not counted): its own work did not fit -- or, on a virtual machine, the
  hypervisor slowed it down in a way the guest cannot see;
* :attr:`MissCause.RUNNABLE`: it was runnable but not running for at least half of the time
  it was late by: other threads of the same or a higher real-time priority had its CPU (or
  its virtual CPU was not running when it woke);
* :attr:`MissCause.ASLEEP`: neither: it was woken late (timer latency of the kernel or the
  machine).

On a robot that tells what to change: the loop's work or rate (``ON_CPU``), its priority or
CPU (``RUNNABLE``: ``gateway.rt_priority``, ``rt_cpu``, ``isolcpus``), or the kernel
(``ASLEEP``: a ``PREEMPT_RT`` kernel, no deep C-states).  Reading the statistics costs one
``pread`` (about 1 us) per cycle, between cycles.  Where the file does not exist (not
Linux), nothing is classified.
"""

from __future__ import annotations

import collections
import math
import os
from dataclasses import dataclass
from typing import TYPE_CHECKING

from gateway.runtime.timing.cause import MissCause

if TYPE_CHECKING:
    from collections.abc import Callable

    from gateway.runtime.timing.scheduler import Scheduler

__all__ = ["RECENT", "REPORT_INTERVAL_S", "Miss", "MissCause", "MissProbe", "SchedStat",
           "classify"]

#: Late starts kept in :attr:`MissProbe.recent`.
RECENT = 64

#: Least time between two :meth:`MissProbe.report` lines (s).
REPORT_INTERVAL_S = 10.0


def classify(late_s: float, on_cpu_s: float, runnable_s: float, period_s: float,
             spin_s: float) -> MissCause:
    """The cause of one late start.

    :param late_s: how late the start was past the deadline it was due at.
    :param on_cpu_s: the loop thread's CPU time since the previous cycle's start.
    :param runnable_s: its time runnable but not running over the same interval.
    :param period_s: the loop period.
    :param spin_s: how long the loop spins before each deadline (CPU time that is not work).

    >>> classify(1.5e-3, 1.4e-3, 0.0, 1e-3, 2e-4).value
    'on_cpu'
    >>> classify(1.2e-3, 3e-4, 9e-4, 1e-3, 2e-4).value
    'runnable'
    >>> classify(5e-3, 2.5e-4, 1e-5, 1e-3, 2e-4).value
    'asleep'
    """
    if on_cpu_s - spin_s > period_s:
        return MissCause.ON_CPU
    if runnable_s >= 0.5 * late_s:
        return MissCause.RUNNABLE
    return MissCause.ASLEEP


class SchedStat:
    """The calling thread's ``/proc/thread-self/schedstat``.

    Opened once (the descriptor stays bound to the thread that opened it) and re-read with
    ``pread``.  :meth:`read` gives ``None`` where the file does not exist.
    """

    def __init__(self) -> None:
        try:
            self._fd: int | None = os.open("/proc/thread-self/schedstat", os.O_RDONLY)
        except OSError:
            self._fd = None

    def read(self) -> tuple[int, int] | None:
        """``(on-CPU ns, runnable-but-not-running ns)`` of the thread since it started."""
        if self._fd is None:
            return None
        try:
            fields = os.pread(self._fd, 128, 0).split()
            return int(fields[0]), int(fields[1])
        except (OSError, ValueError, IndexError):
            return None

    def close(self) -> None:
        """Release the descriptor (reads then give ``None``)."""
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None


@dataclass(frozen=True, slots=True)
class Miss:
    """One late start.

    :param late_s: how late it was past the deadline it was due at.
    :param skipped: deadlines skipped.
    :param on_cpu_s: the loop thread's CPU time since the previous cycle's start.
    :param runnable_s: its time runnable but not running over the same interval.
    :param cause: the verdict of :func:`classify`.
    """

    late_s: float
    skipped: int
    on_cpu_s: float
    runnable_s: float
    cause: MissCause


class MissProbe:
    """Classifies every late start of a :class:`~gateway.runtime.timing.Scheduler`'s loop.

    Create it in the loop's thread; call :meth:`before_wait` just before waiting for the next
    deadline and :meth:`after_wait` as soon as the wait returns.  Each late start is counted
    in the scheduler's :class:`~gateway.runtime.timing.LoopTimer` by cause and kept in
    :attr:`recent`.

    :param scheduler: the loop's scheduler.
    :param read: the thread's ``(on-CPU ns, runnable ns)``; this thread's schedstat when
        omitted (tests pass their own).

    >>> from gateway.runtime.timing import Scheduler
    >>> times = iter([0.0, 0.0025])  # the first deadline at 0, the loop woken 2.5 ms later
    >>> sched = Scheduler(1000.0, spin_s=0.0, clock=lambda: next(times))
    >>> probe = MissProbe(sched, read=iter([(0, 0), (300_000, 0)]).__next__)
    >>> probe.before_wait()
    >>> probe.after_wait(sched.wait_next())
    >>> miss = probe.recent[-1]
    >>> round(miss.late_s * 1e6), miss.skipped, miss.cause.value, sched.timer.late_by_cause
    (2500, 2, 'asleep', {'on_cpu': 0, 'runnable': 0, 'asleep': 1})
    """

    def __init__(self, scheduler: Scheduler,
                 read: Callable[[], tuple[int, int] | None] | None = None) -> None:
        self._sched = scheduler
        self._stat: SchedStat | None = None
        if read is None:
            self._stat = SchedStat()
            read = self._stat.read
        self._read = read
        self._woke = read()
        self._due = 0.0
        self._missed = 0
        #: The last :data:`RECENT` late starts.
        self.recent: collections.deque[Miss] = collections.deque(maxlen=RECENT)
        #: The largest of each figure over every late start (s): late, on CPU, runnable.
        self.worst = (0.0, 0.0, 0.0)
        #: Late starts classified so far.
        self.count = 0
        #: The latest start since the last :meth:`report` (s late: of all of them, not only the
        #: last :data:`RECENT`: a freeze of seconds among many small ones is its worst).
        self._worst_since = 0.0
        self._reported = 0
        self._reported_by = dict(scheduler.timer.late_by_cause)
        self._next_report_s = -math.inf

    @property
    def available(self) -> bool:
        """Whether the thread's statistics can be read here."""
        return self._woke is not None

    def before_wait(self) -> None:
        """Note the deadline the loop is about to wait for."""
        self._due = self._sched.next_deadline_s()
        self._missed = self._sched.timer.missed

    def after_wait(self, woke_s: float) -> None:
        """Note the start at ``woke_s`` (the scheduler's clock); classify it if it was late."""
        now = self._read()
        timer = self._sched.timer
        skipped = timer.missed - self._missed
        if skipped > 0 and now is not None and self._woke is not None:
            late = woke_s - self._due
            on_cpu = (now[0] - self._woke[0]) * 1e-9
            runnable = (now[1] - self._woke[1]) * 1e-9
            cause = classify(late, on_cpu, runnable, self._sched.period_s, self._sched.spin_s)
            timer.record_late_start(cause)
            self.count += 1
            self.recent.append(Miss(late, skipped, on_cpu, runnable, cause))
            w = self.worst
            self.worst = (max(w[0], late), max(w[1], on_cpu), max(w[2], runnable))
            self._worst_since = max(self._worst_since, late)
        self._woke = now

    def report(self, now_s: float) -> str | None:
        """A line on the late starts since the last one, for the log: at once after the first,
        then at most one every :data:`REPORT_INTERVAL_S` (the rest accumulate); ``None``
        when there is nothing (yet) to say.  Cheap enough to call every cycle."""
        if self.count == self._reported or now_s < self._next_report_s:
            return None
        new = self.count - self._reported
        by = self._sched.timer.late_by_cause
        delta = {key: by[key] - self._reported_by.get(key, 0) for key in by}
        worst, self._worst_since = self._worst_since, 0.0
        self._reported, self._reported_by = self.count, dict(by)
        self._next_report_s = now_s + REPORT_INTERVAL_S
        return (f"{new} late start{'s' if new != 1 else ''} (on CPU {delta['on_cpu']}, runnable "
                f"{delta['runnable']}, asleep {delta['asleep']}; worst {worst * 1e3:.1f} ms late)"
                f"; {self._sched.timer.missed} deadlines skipped since start-up")

    def describe(self) -> str:
        """One line: late starts by cause and the worst figures (for benchmarks and logs)."""
        timer = self._sched.timer
        if not self.available:
            return "no per-thread scheduler statistics here: late starts not classified"
        by = timer.late_by_cause
        starts = sum(by.values())
        if not starts:
            return "no late starts"
        late, on_cpu, runnable = self.worst
        return (f"{starts} late starts ({timer.missed} deadlines skipped): on CPU over a period "
                f"{by['on_cpu']}, runnable but not running {by['runnable']}, asleep past the "
                f"deadline {by['asleep']}; worst: {late * 1e6:.0f} us late, {on_cpu * 1e6:.0f} us "
                f"on CPU since the cycle before (spin included), {runnable * 1e6:.0f} us "
                f"runnable")

    def close(self) -> None:
        """Release the statistics file."""
        if self._stat is not None:
            self._stat.close()
