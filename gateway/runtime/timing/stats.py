"""Per-cycle timing records of the control loop: :class:`LoopTimer`, summarised in the status
model's :class:`~gateway.core.status.TimingReport`.

Lateness, cost, cycle starts and twist-to-frame latency go into fixed-size ring buffers (no
allocation per cycle) and are summarised on demand.  Reads no clock: callers pass the times.
"""

from __future__ import annotations

import math
from array import array
from typing import TYPE_CHECKING

from gateway.core.errors import ConfigError
from gateway.core.status import TimingReport
from gateway.runtime.timing.cause import MissCause

if TYPE_CHECKING:
    from collections.abc import Sequence

#: Ring-buffer length of :class:`LoopTimer` (about 4 s at 1 kHz, 20 s at 200 Hz).
DEFAULT_CAPACITY = 4096


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
        #: Late starts since start-up by cause (:class:`~gateway.runtime.timing.cause.MissCause`
        #: value), as classified by a :class:`~gateway.runtime.timing.misses.MissProbe`.
        self.late_by_cause = {cause.value: 0 for cause in MissCause}

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

    def record_late_start(self, cause: MissCause) -> None:
        """Count one late start under ``cause``."""
        self.late_by_cause[cause.value] += 1

    def record_latency(self, latency_s: float) -> None:
        """Record one twist-to-frame latency (twist received to its frames sent), s."""
        self._latency.push(latency_s)

    def snapshot(self) -> TimingReport:
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
        return TimingReport(
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
            late_on_cpu=self.late_by_cause["on_cpu"],
            late_runnable=self.late_by_cause["runnable"],
            late_asleep=self.late_by_cause["asleep"],
        )
