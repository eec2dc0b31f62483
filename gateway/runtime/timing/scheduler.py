"""The fixed-rate loop's deadlines: :class:`Scheduler`, absolute deadlines, sleep then spin.

Overruns skip the deadlines that are a whole period or more in the past instead of bursting
through them; starts, skips and costs are recorded in a
:class:`~gateway.runtime.timing.stats.LoopTimer`.
"""

from __future__ import annotations

import math
import time
from typing import TYPE_CHECKING

from gateway.core.errors import ConfigError
from gateway.runtime.timing.stats import LoopTimer

if TYPE_CHECKING:
    from collections.abc import Callable

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
