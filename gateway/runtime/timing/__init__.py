"""Timing of the fixed-rate control loop: deadlines, statistics and real-time set-up.

* :class:`Scheduler` (:mod:`gateway.runtime.timing.scheduler`) keeps **absolute** deadlines
  ``origin + k * period`` (no drift from ``sleep(period)``), waits with sleep-then-spin, and
  after an overrun **skips** the deadlines that are a whole period or more in the past instead
  of bursting through them.
* :class:`LoopTimer` (:mod:`gateway.runtime.timing.stats`) records lateness, cost, skipped
  cycles and twist-to-frame latency into fixed-size ring buffers (no allocation per cycle) and
  summarises them on demand in a frozen :class:`~gateway.core.status.TimingReport`.
* :class:`MissProbe` (:mod:`gateway.runtime.timing.misses`) tells, for every late start,
  whether the loop thread was running, waiting for a CPU or asleep (its schedstat), and counts
  each cause (:class:`MissCause`, :mod:`gateway.runtime.timing.cause`).

The modules import one way only: ``misses`` -> ``scheduler`` -> ``stats`` -> ``cause``.
* :func:`realtime_setup` (:mod:`gateway.runtime.timing.realtime`) applies ``gc.freeze()``,
  ``SCHED_FIFO``, CPU pinning and ``mlockall`` as far as the process is allowed to, and reports
  what it did.

Background: ``gc.freeze()`` (https://docs.python.org/3/library/gc.html#gc.freeze) keeps the
start-up objects out of every later collection, so no full collection lands in a cycle;
``SCHED_FIFO`` and ``mlockall`` are described in sched(7) and mlock(2)
(https://man7.org/linux/man-pages/man7/sched.7.html); ``tools/bench_loop.py`` measures the
lateness, cost and misses this gives at 1 kHz.

The loop in the daemon::

    scheduler = Scheduler(rate_hz=200.0, spin_s=200e-6)
    while running:
        now = scheduler.wait_next(server.poll)   # socket traffic is served while waiting
        step(now)                                # read feedback, compute, send frames
        scheduler.end_cycle()                    # records the cost of the work
    stats = scheduler.timer.snapshot()
"""

from __future__ import annotations

from gateway.runtime.timing.cause import MissCause
from gateway.runtime.timing.misses import MissProbe
from gateway.runtime.timing.realtime import realtime_setup
from gateway.runtime.timing.scheduler import Scheduler
from gateway.runtime.timing.stats import DEFAULT_CAPACITY, LoopTimer

__all__ = ["DEFAULT_CAPACITY", "LoopTimer", "MissCause", "MissProbe", "Scheduler",
           "realtime_setup"]
