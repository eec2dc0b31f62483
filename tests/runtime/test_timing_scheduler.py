"""Loop timing: the scheduler against a fake clock, and the statistics (LoopTimer)."""

from __future__ import annotations

import math
import tracemalloc
from dataclasses import FrozenInstanceError

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gateway.core.errors import ConfigError
from gateway.core.status import TimingReport
from gateway.runtime.timing import LoopTimer, Scheduler
from gateway.runtime.timing import stats as timing_stats
from tests.runtime.timing_helpers import TICK, FakeClock, make

# --- the scheduler --------------------------------------------------------------------------


def test_steady_loop_starts_on_absolute_deadlines() -> None:
    clock = FakeClock()
    sched = make(clock)
    starts = []
    for _ in range(50):
        starts.append(sched.wait_next())
        clock.work(0.002)
    origin = starts[0]
    for k, start in enumerate(starts):
        deadline = origin + k * 0.01
        assert deadline <= start < deadline + 5 * TICK  # on the grid: no drift
    assert sched.timer.missed == 0
    assert sched.timer.cycles == 50


def test_sleeps_until_spin_margin_then_spins() -> None:
    clock = FakeClock()
    sched = make(clock, spin_s=200e-6)
    sched.wait_next()
    clock.work(0.003)
    reads_before = clock.reads
    start = sched.wait_next()
    [slept] = clock.sleeps
    assert slept == pytest.approx(0.01 - 0.003 - 200e-6, abs=5 * TICK)
    # the last 200 us are spent reading the clock (one read per 1 us tick)
    assert clock.reads - reads_before == pytest.approx(200, abs=5)
    assert start >= sched.deadline_s


def test_zero_spin_sleeps_only() -> None:
    clock = FakeClock()
    sched = make(clock, spin_s=0.0)
    sched.wait_next()
    clock.work(0.003)
    reads_before = clock.reads
    sched.wait_next()
    assert clock.sleeps[0] == pytest.approx(0.007, abs=5 * TICK)
    assert clock.reads - reads_before < 5


def test_early_waking_wait_never_returns_before_the_deadline() -> None:
    clock = FakeClock()
    sched = make(clock)
    calls: list[float] = []

    def poll(timeout: float) -> None:  # a socket poll woken by traffic after 1 ms
        calls.append(timeout)
        clock.work(min(timeout, 0.001))

    sched.wait_next(poll)
    for _ in range(5):
        clock.work(0.0005)
        start = sched.wait_next(poll)
        assert start >= sched.deadline_s
        assert start - sched.deadline_s < 5 * TICK
    assert clock.sleeps == []  # the given wait replaces the default sleep
    assert len(calls) >= 5 * 9  # ~9.3 ms in 1 ms slices per cycle
    assert all(t > 0 for t in calls)


def test_overrun_skips_missed_deadlines_instead_of_bursting() -> None:
    clock = FakeClock()
    sched = make(clock)  # 10 ms period
    origin = sched.wait_next()
    clock.work(0.035)  # deadlines at +10 and +20 ms are more than a period late
    late_start = sched.wait_next()
    assert sched.timer.missed == 2
    assert sched.deadline_s == pytest.approx(origin + 0.030, abs=5 * TICK)
    assert 0.004 < late_start - sched.deadline_s < 0.0051  # runs once, late by < 1 period
    clock.work(0.001)
    next_start = sched.wait_next()  # back on the original grid, after a wait
    assert next_start == pytest.approx(origin + 0.040, abs=5 * TICK)
    assert len(clock.sleeps) == 1


def test_late_by_less_than_a_period_runs_without_skipping() -> None:
    clock = FakeClock()
    sched = make(clock)
    origin = sched.wait_next()
    clock.work(0.015)
    start = sched.wait_next()
    assert sched.timer.missed == 0
    assert sched.deadline_s == pytest.approx(origin + 0.010, abs=5 * TICK)
    assert start - sched.deadline_s == pytest.approx(0.005, abs=5 * TICK)
    clock.work(0.001)
    assert sched.wait_next() == pytest.approx(origin + 0.020, abs=5 * TICK)


def test_oversleeping_wait_is_also_skipped() -> None:
    clock = FakeClock(oversleep=0.025)  # the OS wakes us 25 ms late
    sched = make(clock)
    origin = sched.wait_next()
    clock.work(0.001)
    sched.wait_next()
    assert sched.timer.missed == 2
    assert sched.deadline_s == pytest.approx(origin + 0.030, abs=5 * TICK)


@pytest.mark.parametrize("now", [0.009, 0.011, 0.014, 0.0305])
def test_skip_lands_on_the_last_passed_grid_point_despite_rounding(now: float) -> None:
    # 1 ms grid from 0.0.  From deadline 1, the estimate 1 + (now - 0.001) // 0.001 is off by
    # one for 0.009 (9 * 0.001 > 0.009) and for 0.011 (floor gives 9, yet 11 * 0.001 <= 0.011).
    clock = FakeClock(now=0.0, tick=0.0)
    sched = make(clock, rate_hz=1000.0)
    sched.wait_next()
    clock.now = now
    start = sched.wait_next()
    assert start == now
    index = sched.timer.missed + 1
    assert sched.deadline_s == index * 0.001  # a grid point, computed as the grid computes it
    assert sched.deadline_s <= start < sched.next_deadline_s() == (index + 1) * 0.001


def test_timer_records_lateness_and_cost() -> None:
    clock = FakeClock(oversleep=0.0)
    sched = make(clock, rate_hz=200.0)
    for i in range(100):
        sched.wait_next()
        clock.work(0.001 if i % 2 else 0.002)
        assert sched.end_cycle() == pytest.approx(0.001 if i % 2 else 0.002, abs=2 * TICK)
        assert sched.end_cycle() == 0.0  # once per cycle
    stats = sched.timer.snapshot()
    assert stats.cycles == 100
    assert stats.missed == 0
    assert stats.rate_hz == 200.0
    assert stats.achieved_hz == pytest.approx(200.0, rel=1e-3)
    assert stats.cost_p50_us == pytest.approx(1000.0, abs=5)
    assert stats.cost_max_us == pytest.approx(2000.0, abs=5)
    assert 0.0 <= stats.lateness_max_us < 5.0


def test_remaining_and_due() -> None:
    clock = FakeClock(tick=0.0)
    sched = make(clock)
    sched.start(now=10.0)
    clock.now = 9.996
    assert sched.remaining_s() == pytest.approx(0.004)
    assert not sched.due()
    clock.now = 10.0
    assert sched.due()
    assert sched.next_deadline_s() == 10.0
    clock.tick = TICK
    sched.wait_next()
    assert sched.next_deadline_s() == pytest.approx(10.01)


@pytest.mark.parametrize(
    ("rate_hz", "spin_s", "message"),
    [
        (0.0, 0.0, "rate_hz: expected a finite number > 0, got 0.0"),
        (math.nan, 0.0, "rate_hz"),
        (-5.0, 0.0, "rate_hz"),
        (1000.0, 0.001, r"spin_s: expected 0 <= spin_s < the period \(0.001 s\), got 0.001"),
        (100.0, -1e-6, "spin_s"),
    ],
)
def test_scheduler_rejects_bad_parameters(rate_hz: float, spin_s: float, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        Scheduler(rate_hz, spin_s=spin_s)


@settings(max_examples=200, deadline=None)
@given(
    rate_hz=st.sampled_from([50.0, 200.0, 1000.0]),
    cycles=st.lists(
        st.tuples(
            st.floats(0.0, 5.0),  # work, in periods
            st.floats(0.0, 3.0),  # oversleep, in periods
            st.integers(0, 4),  # early wake-ups of the wait
        ),
        min_size=1,
        max_size=30,
    ),
)
def test_schedule_invariants(rate_hz: float, cycles: list[tuple[float, float, int]]) -> None:
    """Starts never precede deadlines, stay within a period of them, and stay on the grid."""
    period = 1.0 / rate_hz
    clock = FakeClock()
    sched = make(clock, rate_hz=rate_hz, spin_s=min(200e-6, period / 4))
    origin = sched.wait_next()
    index = 0
    for work, oversleep, wakeups in cycles:
        clock.work(work * period)
        early = [wakeups]

        def wait(timeout: float, early: list[int] = early, oversleep: float = oversleep) -> None:
            if early[0] > 0:
                early[0] -= 1
                clock.work(timeout / 3)
            else:
                clock.work(timeout + oversleep * period)

        before_missed = sched.timer.missed
        start = sched.wait_next(wait)
        skipped = sched.timer.missed - before_missed
        index += 1 + skipped
        assert sched.deadline_s == pytest.approx(origin + index * period, abs=1e-9)
        assert sched.deadline_s <= start < sched.deadline_s + period
    assert sched.timer.cycles == len(cycles) + 1


# --- LoopTimer ------------------------------------------------------------------------------


def test_percentiles_nearest_rank() -> None:
    timer = LoopTimer(250.0, capacity=100)
    for i in range(1, 101):
        timer.record_start(start_s=i * 0.005, lateness_s=i * 1e-6)
        timer.record_cost((101 - i) * 2e-6)
        timer.record_latency(i * 10e-6)
    stats = timer.snapshot()
    late = (stats.lateness_p50_us, stats.lateness_p99_us, stats.lateness_max_us)
    assert late == pytest.approx((50.0, 99.0, 100.0))
    cost = (stats.cost_p50_us, stats.cost_p99_us, stats.cost_max_us)
    assert cost == pytest.approx((100.0, 198.0, 200.0))
    latency = (stats.latency_p50_us, stats.latency_p99_us, stats.latency_max_us)
    assert latency == pytest.approx((500.0, 990.0, 1000.0))
    assert stats.latency_samples == 100
    assert stats.achieved_hz == pytest.approx(200.0)
    assert stats.rate_hz == 250.0
    assert stats.cycles == 100


def test_ring_keeps_only_the_last_window() -> None:
    timer = LoopTimer(capacity=4)
    for i in range(10):  # starts 0..9 ms apart by 1 ms; lateness i us
        timer.record_start(start_s=i * 0.001, lateness_s=i * 1e-6)
    timer.record_missed(3)
    stats = timer.snapshot()
    assert stats.cycles == 10
    assert stats.missed == 3
    assert stats.lateness_p50_us == pytest.approx(7.0)  # window is 6, 7, 8, 9
    assert stats.lateness_max_us == pytest.approx(9.0)
    assert stats.achieved_hz == pytest.approx(1000.0)  # 3 intervals over 3 ms
    assert stats.cost_max_us == 0.0  # no costs recorded
    assert stats.latency_samples == 0
    assert timer.capacity == 4


def test_empty_snapshot_is_zero() -> None:
    stats = LoopTimer().snapshot()
    assert stats == TimingReport(0, 0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0, 0.0, 0.0, 0.0)
    with pytest.raises(FrozenInstanceError):
        stats.cycles = 1  # type: ignore[misc]


def test_timer_parameters_are_checked() -> None:
    with pytest.raises(ConfigError, match="capacity: expected at least 2, got 1"):
        LoopTimer(capacity=1)
    with pytest.raises(ConfigError, match=r"rate_hz: expected a finite number >= 0, got -1\.0"):
        LoopTimer(-1.0)


def test_recording_does_not_grow_memory() -> None:
    timer = LoopTimer(capacity=256)
    for i in range(256):  # fill once so every slot is written
        timer.record_start(i * 1e-3, 1e-6)
        timer.record_cost(2e-6)
    tracemalloc.start()
    try:
        before = tracemalloc.take_snapshot()
        for i in range(20_000):
            timer.record_start(i * 1e-3, 1e-6)
            timer.record_cost(2e-6)
            timer.record_latency(3e-6)
        after = tracemalloc.take_snapshot()
    finally:
        tracemalloc.stop()
    grown = sum(
        stat.size_diff
        for stat in after.compare_to(before, "filename")
        if stat.traceback[0].filename == timing_stats.__file__
    )
    assert grown < 1024  # a few counters at most, nothing per cycle


def test_summary_line() -> None:
    stats = TimingReport(
        1000, 2, 200.0, 199.96, 1.0, 42.4, 310.0, 80.0, 120.6, 900.0, 0, 0.0, 0.0, 0.0
    )
    assert stats.summary() == (
        "200.0/200 Hz, 1000 cycles, 2 missed; late p99 42 us max 310 us; cost p99 121 us max 900 us"
    )
