"""Timing of the fixed-rate control loop: deadlines, statistics and real-time set-up.

* :class:`Scheduler` keeps **absolute** deadlines ``origin + k * period`` (no drift from
  ``sleep(period)``), waits with sleep-then-spin, and after an overrun **skips** the deadlines
  that are a whole period or more in the past instead of bursting through them.
* :class:`LoopTimer` records lateness, cost, skipped cycles and twist-to-frame latency into
  fixed-size ring buffers (no allocation per cycle) and summarises them on demand in a frozen
  :class:`TimingStats`.
* :func:`realtime_setup` applies ``gc.freeze()``, ``SCHED_FIFO``, CPU pinning and
  ``mlockall`` as far as the process is allowed to, and reports what it did.

Background and measurements: ``python-can-notes.md`` sections 4 to 6 (one full GC costs
20-29 ms; without ``SCHED_FIFO`` tails reach 1-4 ms; sleep+spin with a ~200 us margin gives
sub-microsecond median lateness at 1 kHz).

The loop in the daemon::

    scheduler = Scheduler(rate_hz=200.0, spin_s=200e-6)
    while running:
        now = scheduler.wait_next(server.poll)   # socket traffic is served while waiting
        step(now)                                # read feedback, compute, send frames
        scheduler.end_cycle()                    # records the cost of the work
    stats = scheduler.timer.snapshot()
"""

from __future__ import annotations

import ctypes
import errno
import gc
import logging
import math
import os
import platform
import resource
import time
from array import array
from dataclasses import dataclass
from typing import TYPE_CHECKING

from gateway.errors import ConfigError

if TYPE_CHECKING:
    from collections.abc import Callable, Sequence

log = logging.getLogger(__name__)

#: Ring-buffer length of :class:`LoopTimer` (about 4 s at 1 kHz, 20 s at 200 Hz).
DEFAULT_CAPACITY = 4096


@dataclass(frozen=True, slots=True)
class TimingStats:
    """A summary of the loop's timing over the last ring-buffer window.

    Percentiles are nearest-rank over the window; all times are in microseconds.  Every
    figure is 0.0 when there are no samples.

    :param cycles: cycles started since start-up (not limited to the window).
    :param missed: deadlines skipped after overruns since start-up.
    :param rate_hz: the configured loop rate (0.0 if the timer was not told).
    :param achieved_hz: the cycle rate achieved over the window (0.0 with fewer than 2 cycles).
    :param lateness_p50_us: median of cycle start minus deadline.
    :param lateness_p99_us: 99th percentile of the lateness.
    :param lateness_max_us: largest lateness in the window.
    :param cost_p50_us: median of the work duration of a cycle.
    :param cost_p99_us: 99th percentile of the cost.
    :param cost_max_us: largest cost in the window.
    :param latency_samples: twist-to-frame latency samples in the window.
    :param latency_p50_us: median twist-to-frame latency.
    :param latency_p99_us: 99th percentile of the latency.
    :param latency_max_us: largest latency in the window.
    """

    cycles: int
    missed: int
    rate_hz: float
    achieved_hz: float
    lateness_p50_us: float
    lateness_p99_us: float
    lateness_max_us: float
    cost_p50_us: float
    cost_p99_us: float
    cost_max_us: float
    latency_samples: int
    latency_p50_us: float
    latency_p99_us: float
    latency_max_us: float

    def summary(self) -> str:
        """One line for ``STATUS=`` and logs."""
        return (
            f"{self.achieved_hz:.1f}/{self.rate_hz:g} Hz, {self.cycles} cycles, "
            f"{self.missed} missed; "
            f"late p99 {self.lateness_p99_us:.0f} us max {self.lateness_max_us:.0f} us; "
            f"cost p99 {self.cost_p99_us:.0f} us max {self.cost_max_us:.0f} us"
        )


def _percentiles_us(window: Sequence[float]) -> tuple[float, float, float]:
    """(p50, p99, max) of ``window`` (seconds) in microseconds, nearest rank."""
    if not window:
        return 0.0, 0.0, 0.0
    ordered = sorted(window)
    n = len(ordered)
    return (
        ordered[max(0, math.ceil(0.50 * n) - 1)] * 1e6,
        ordered[max(0, math.ceil(0.99 * n) - 1)] * 1e6,
        ordered[-1] * 1e6,
    )


class _Ring:
    """A fixed-size ring of doubles; the window is the last ``capacity`` values."""

    __slots__ = ("count", "data", "index")

    def __init__(self, capacity: int) -> None:
        self.data = array("d", bytes(8 * capacity))
        self.index = 0
        self.count = 0

    def push(self, value: float) -> None:
        self.data[self.index] = value
        self.index = (self.index + 1) % len(self.data)
        if self.count < len(self.data):
            self.count += 1

    def window(self) -> array[float]:
        """The stored values (in no particular order); a copy."""
        return self.data[: self.count]

    def oldest_newest(self) -> tuple[float, float]:
        """The first and the last value of the window (the ring must not be empty)."""
        oldest = self.data[self.index] if self.count == len(self.data) else self.data[0]
        return oldest, self.data[self.index - 1]


class LoopTimer:
    """Per-cycle timing records for the control loop, summarised by :meth:`snapshot`.

    It reads no clock: callers pass times in seconds.  Each ring holds the last ``capacity``
    samples, preallocated, so recording never allocates; sorting happens only in
    :meth:`snapshot`.  Lateness and cost are recorded separately (at the start and at the end
    of a cycle); :class:`Scheduler` records the starts, the loop (or
    :meth:`Scheduler.end_cycle`) the costs.

    :param rate_hz: the configured loop rate, reported in the snapshot; 0.0 if unknown.
    :param capacity: samples kept per ring, >= 2.
    :raises ConfigError: if ``rate_hz`` is negative or not finite, or ``capacity`` is below 2.
    """

    def __init__(self, rate_hz: float = 0.0, capacity: int = DEFAULT_CAPACITY) -> None:
        if not (math.isfinite(rate_hz) and rate_hz >= 0):
            raise ConfigError(f"LoopTimer rate_hz: expected a finite number >= 0, got {rate_hz}")
        if capacity < 2:
            raise ConfigError(f"LoopTimer capacity: expected at least 2, got {capacity}")
        self.rate_hz = rate_hz
        self._start = _Ring(capacity)
        self._lateness = _Ring(capacity)
        self._cost = _Ring(capacity)
        self._latency = _Ring(capacity)
        #: Cycles started since start-up.
        self.cycles = 0
        #: Deadlines skipped after overruns since start-up (cheap to read every cycle).
        self.missed = 0

    @property
    def capacity(self) -> int:
        """Samples kept per ring."""
        return len(self._start.data)

    def record_start(self, start_s: float, lateness_s: float) -> None:
        """Record the start of a cycle.

        :param start_s: when the cycle started (clock seconds).
        :param lateness_s: start minus deadline, s.
        """
        self._start.push(start_s)
        self._lateness.push(lateness_s)
        self.cycles += 1

    def record_cost(self, cost_s: float) -> None:
        """Record how long a cycle's work took, s."""
        self._cost.push(cost_s)

    def record_missed(self, count: int) -> None:
        """Count ``count`` skipped deadlines."""
        self.missed += count

    def record_latency(self, latency_s: float) -> None:
        """Record one twist-to-frame latency (twist received to its frames sent), s."""
        self._latency.push(latency_s)

    def snapshot(self) -> TimingStats:
        """Summarise the current window.

        This sorts copies of the rings (about 1 ms at the default capacity): call it at status
        rate, ideally outside the control cycle; read :attr:`missed` for a per-cycle check.
        """
        achieved_hz = 0.0
        if self._start.count >= 2:
            oldest, newest = self._start.oldest_newest()
            if newest > oldest:
                achieved_hz = (self._start.count - 1) / (newest - oldest)
        late = _percentiles_us(self._lateness.window())
        cost = _percentiles_us(self._cost.window())
        latency = _percentiles_us(self._latency.window())
        return TimingStats(
            cycles=self.cycles,
            missed=self.missed,
            rate_hz=self.rate_hz,
            achieved_hz=achieved_hz,
            lateness_p50_us=late[0],
            lateness_p99_us=late[1],
            lateness_max_us=late[2],
            cost_p50_us=cost[0],
            cost_p99_us=cost[1],
            cost_max_us=cost[2],
            latency_samples=self._latency.count,
            latency_p50_us=latency[0],
            latency_p99_us=latency[1],
            latency_max_us=latency[2],
        )


class Scheduler:
    """Absolute-deadline scheduler for a fixed-rate loop, with sleep-then-spin waiting.

    Deadline ``k`` is ``origin + k * period``; the origin is the time of the first
    :meth:`wait_next` (or :meth:`start`).  :meth:`wait_next` returns at, never before, the next
    deadline.  A deadline that is a whole period or more in the past when the loop gets to it
    is skipped and counted in :attr:`LoopTimer.missed`; the loop then runs once, late by less
    than a period, and continues on the original grid (skip, don't burst).

    Two ways to wait, both ending in :meth:`wait_next`:

    * ``now = scheduler.wait_next(server.poll)``: the scheduler calls ``wait`` with the time
      left before the spin phase, again after every early return;
    * a loop of its own: ``while (left := scheduler.remaining_s()) > scheduler.spin_s:
      handle(server.poll(left - scheduler.spin_s))``, then ``scheduler.wait_next()``, which
      only spins (and counts skipped deadlines).

    The cost of a cycle is recorded by :meth:`end_cycle` after the work (or by the caller with
    :meth:`LoopTimer.record_cost`).

    :param rate_hz: loop rate, > 0.
    :param spin_s: how long before each deadline to stop sleeping and spin on the clock, >= 0.
        0 means sleep only (accurate to the OS timer slack, ~50-100 us without SCHED_FIFO).
    :param clock: monotonic clock in seconds.
    :param sleep: the default wait, ``time.sleep`` when omitted.
    :param timer: where to record timing; a new :class:`LoopTimer` when omitted.
    :raises ConfigError: if ``rate_hz`` or ``spin_s`` is out of range.
    """

    def __init__(
        self,
        rate_hz: float,
        spin_s: float = 0.0002,
        clock: Callable[[], float] = time.perf_counter,
        sleep: Callable[[float], None] | None = None,
        timer: LoopTimer | None = None,
    ) -> None:
        if not (math.isfinite(rate_hz) and rate_hz > 0):
            raise ConfigError(f"Scheduler rate_hz: expected a finite number > 0, got {rate_hz}")
        self.period_s = 1.0 / rate_hz
        if not (math.isfinite(spin_s) and 0 <= spin_s < self.period_s):
            raise ConfigError(
                f"Scheduler spin_s: expected 0 <= spin_s < the period ({self.period_s:g} s), "
                f"got {spin_s}"
            )
        self.rate_hz = rate_hz
        self.spin_s = spin_s
        self.timer = timer if timer is not None else LoopTimer(rate_hz)
        self._clock = clock
        self._sleep = sleep if sleep is not None else time.sleep
        self._origin: float | None = None
        self._next = 0  # index of the next deadline
        self._in_cycle = False
        self._cycle_start = 0.0
        #: Deadline of the current cycle (clock seconds); meaningful after :meth:`wait_next`.
        self.deadline_s = 0.0

    def start(self, now: float | None = None) -> None:
        """Put the first deadline at ``now`` (the clock when omitted) and forget the past."""
        self._origin = self._clock() if now is None else now
        self._next = 0
        self._in_cycle = False

    def next_deadline_s(self) -> float:
        """The next deadline in clock seconds (starts the schedule if needed)."""
        origin = self._origin
        if origin is None:
            origin = self._clock()
            self.start(origin)
        return origin + self._next * self.period_s

    def remaining_s(self) -> float:
        """Seconds until the next deadline (negative when it has passed)."""
        return self.next_deadline_s() - self._clock()

    def due(self) -> bool:
        """True when the next deadline has been reached."""
        return self.remaining_s() <= 0.0

    def wait_next(self, wait: Callable[[float], None] | None = None) -> float:
        """Wait for the next deadline and start a cycle.

        Waiting is ``wait(remaining - spin_s)``, repeated while more than ``spin_s`` remains
        (so a ``wait`` that returns early, such as a socket poll woken by a request, is simply
        called again), then a spin on the clock for the rest.  Skipped deadlines are counted.

        :param wait: called with a timeout in seconds; may return early.  ``sleep`` (from the
            constructor) when omitted.
        :return: the clock at the start of the new cycle (>= :attr:`deadline_s`).
        """
        now = self._clock()
        origin = self._origin
        if origin is None:
            self.start(now)
            origin = now
        period = self.period_s
        index = self._next
        deadline = origin + index * period
        waiter = self._sleep if wait is None else wait
        spin = self.spin_s
        remaining = deadline - now
        while remaining > spin:
            waiter(remaining - spin)
            now = self._clock()
            remaining = deadline - now
        while now < deadline:
            now = self._clock()
        if origin + (index + 1) * period <= now:
            # Skip every deadline whose successor has passed too; the loops only correct
            # float rounding of the estimate so that deadline <= now < next deadline.
            index += max(1, int((now - deadline) // period))
            while origin + index * period > now:
                index -= 1
            while origin + (index + 1) * period <= now:
                index += 1
            self.timer.record_missed(index - self._next)
            deadline = origin + index * period
        self.deadline_s = deadline
        self._next = index + 1
        self._in_cycle = True
        self._cycle_start = now
        self.timer.record_start(now, now - deadline)
        return now

    def end_cycle(self) -> float:
        """Record the cost of the current cycle: the clock now minus its start.

        :return: the cost in seconds; 0.0 (and nothing recorded) outside a cycle.
        """
        if not self._in_cycle:
            return 0.0
        self._in_cycle = False
        cost = self._clock() - self._cycle_start
        self.timer.record_cost(cost)
        return cost


# --- real-time set-up ---------------------------------------------------------------------

#: mlockall flags (MCL_CURRENT, MCL_FUTURE) by machine prefix; Linux uses 1 and 2 elsewhere.
_MCL_FLAGS = {"ppc": (0x2000, 0x4000), "sparc": (0x2000, 0x4000), "alpha": (0x2000, 0x4000)}


def _mcl_flags() -> int:
    machine = platform.machine().lower()
    for prefix, (current, future) in _MCL_FLAGS.items():
        if machine.startswith(prefix):
            return current | future
    return 1 | 2


def _libc() -> ctypes.CDLL:
    """The C library of this process (patched in tests)."""
    return ctypes.CDLL(None, use_errno=True)


def _refused(notes: list[str], text: str) -> None:
    log.warning("%s", text)
    notes.append(text)


def _set_fifo(priority: int, notes: list[str]) -> None:
    low, high = os.sched_get_priority_min(os.SCHED_FIFO), os.sched_get_priority_max(os.SCHED_FIFO)
    if not low <= priority <= high:
        raise ConfigError(f"real-time priority: expected {low}..{high}, got {priority}")
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except OSError as err:
        limit = resource.getrlimit(resource.RLIMIT_RTPRIO)[0]
        _refused(notes, f"SCHED_FIFO {priority} refused ({err.strerror or err}; RLIMIT_RTPRIO "
                        f"is {limit}; set LimitRTPRIO= in the unit): staying on SCHED_OTHER")
    else:
        notes.append(f"SCHED_FIFO priority {priority} for the loop thread")


def _pin(cpu: int, notes: list[str]) -> None:
    try:
        os.sched_setaffinity(0, {cpu})
    except OSError as err:
        allowed = sorted(os.sched_getaffinity(0))
        _refused(notes, f"pinning to CPU {cpu} refused ({err.strerror or err}; "
                        f"allowed CPUs {allowed}): not pinned")
    else:
        notes.append(f"loop thread pinned to CPU {cpu}")


def _lock_memory(notes: list[str]) -> None:
    try:
        libc = _libc()
        result = libc.mlockall(_mcl_flags())
    except (OSError, AttributeError) as err:
        _refused(notes, f"mlockall unavailable ({err}): memory not locked")
        return
    if result != 0:
        code = ctypes.get_errno()
        reason = os.strerror(code) if code else "unknown error"
        hint = "; set LimitMEMLOCK= in the unit" if code in (errno.EPERM, errno.ENOMEM) else ""
        _refused(notes, f"mlockall refused ({reason}{hint}): memory not locked")
    else:
        notes.append("memory locked (mlockall MCL_CURRENT|MCL_FUTURE)")


def realtime_setup(priority: int | None, cpu: int | None, lock_memory: bool) -> list[str]:
    """Prepare the calling thread and the process for the control loop.

    Call it from the loop thread, after imports, configuration and bus set-up, and after any
    helper thread has been started (threads created later inherit ``SCHED_FIFO``):

    1. ``gc.collect()`` then ``gc.freeze()``: start-up objects leave the collector's view, so
       later collections are short.  Always done.
    2. ``SCHED_FIFO`` at ``priority`` for the calling thread (Linux applies ``pid 0`` to the
       thread).  An unprivileged user needs ``LimitRTPRIO=`` in the unit.
    3. CPU affinity of the calling thread to ``cpu``.
    4. ``mlockall(MCL_CURRENT | MCL_FUTURE)``.  Needs ``LimitMEMLOCK=`` and, to keep the
       locked size sane, ``MALLOC_ARENA_MAX=1`` and small thread stacks.

    Missing privileges or unsupported calls never raise: each refusal is logged as a warning
    and reported in the notes, and the loop runs with normal scheduling.

    :param priority: ``SCHED_FIFO`` priority 1..99; ``None`` or 0 leaves the policy alone.
    :param cpu: CPU number to pin to; ``None`` or negative leaves the affinity alone.
    :param lock_memory: lock all current and future memory of the process.
    :return: human-readable notes of what was applied and what was refused.
    :raises ConfigError: if ``priority`` is outside the range of ``SCHED_FIFO``.
    """
    notes: list[str] = []
    gc.collect()
    gc.freeze()
    notes.append(f"gc: {gc.get_freeze_count()} start-up objects frozen")
    if priority:
        if hasattr(os, "sched_setscheduler"):
            _set_fifo(priority, notes)
        else:
            _refused(notes, "SCHED_FIFO is not supported on this platform")
    if cpu is not None and cpu >= 0:
        if hasattr(os, "sched_setaffinity"):
            _pin(cpu, notes)
        else:
            _refused(notes, "CPU pinning is not supported on this platform")
    if lock_memory:
        _lock_memory(notes)
    return notes
