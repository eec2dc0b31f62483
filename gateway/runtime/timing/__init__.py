"""Timing of the fixed-rate control loop: deadlines, statistics and real-time set-up.

* :class:`Scheduler` (:mod:`gateway.runtime.timing.scheduler`) keeps **absolute** deadlines
  ``origin + k * period`` (no drift from ``sleep(period)``), waits with sleep-then-spin, and
  after an overrun **skips** the deadlines that are a whole period or more in the past instead
  of bursting through them.
* :class:`LoopTimer` (:mod:`gateway.runtime.timing.stats`) records lateness, cost, skipped cycles
  and
  twist-to-frame latency into fixed-size ring buffers (no allocation per cycle) and summarises
  them on demand in a frozen :class:`TimingStats`.
* :class:`MissProbe` (:mod:`gateway.runtime.timing.misses`) tells, for every late start, whether the
  loop thread was running, waiting for a CPU or asleep (its schedstat), and counts each cause.
* :func:`realtime_setup` (:mod:`gateway.runtime.timing.realtime`) applies ``gc.freeze()``,
  ``SCHED_FIFO``, CPU pinning and ``mlockall`` as far as the process is allowed to, and reports
  what it did.

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

from gateway.runtime.timing.misses import MissCause, MissProbe
from gateway.runtime.timing.realtime import realtime_setup
from gateway.runtime.timing.scheduler import Scheduler
from gateway.runtime.timing.stats import DEFAULT_CAPACITY, LoopTimer, TimingStats

__all__ = ["DEFAULT_CAPACITY", "LoopTimer", "MissCause", "MissProbe", "Scheduler", "TimingStats",
           "realtime_setup"]
