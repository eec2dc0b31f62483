"""The fake clock of the loop-timing tests (test_timing_*, test_misses)."""

from __future__ import annotations

from dataclasses import dataclass, field

from gateway.runtime.timing import Scheduler

TICK = 1e-6  # the fake clock advances this much on every read, so spinning terminates


@dataclass
class FakeClock:
    """A deterministic clock; ``sleep`` advances it by what was asked plus ``oversleep``."""

    now: float = 100.0
    tick: float = TICK
    oversleep: float = 0.0
    reads: int = 0
    sleeps: list[float] = field(default_factory=list)

    def __call__(self) -> float:
        self.reads += 1
        self.now += self.tick
        return self.now

    def sleep(self, seconds: float) -> None:
        assert seconds > 0, f"asked to sleep {seconds}"
        self.sleeps.append(seconds)
        self.now += seconds + self.oversleep

    def work(self, seconds: float) -> None:
        self.now += seconds


def make(clock: FakeClock, rate_hz: float = 100.0, spin_s: float = 200e-6) -> Scheduler:
    return Scheduler(rate_hz, spin_s=spin_s, clock=clock, sleep=clock.sleep)
