"""Loop timing: the scheduler against a fake clock, the statistics, the real-time set-up."""

from __future__ import annotations

import ctypes
import errno
import gc
import logging
import math
import os
import platform
import tracemalloc
from dataclasses import FrozenInstanceError, dataclass, field
from typing import TYPE_CHECKING

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gateway.core.errors import ConfigError
from gateway.core.status import TimingReport
from gateway.runtime.timing import LoopTimer, Scheduler, realtime, realtime_setup
from gateway.runtime.timing import stats as timing_stats

if TYPE_CHECKING:
    from collections.abc import Iterator

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


# --- realtime_setup -------------------------------------------------------------------------


@pytest.fixture
def unfreeze() -> Iterator[None]:
    """Undo gc.freeze() so the rest of the test session collects normally."""
    yield
    gc.unfreeze()


@pytest.fixture
def no_real_rt(monkeypatch: pytest.MonkeyPatch) -> list[tuple[object, ...]]:
    """Record scheduler/affinity calls instead of making the test process real-time."""
    calls: list[tuple[object, ...]] = []
    monkeypatch.setattr(os, "sched_setscheduler", lambda *args: calls.append(args))
    monkeypatch.setattr(os, "sched_setaffinity", lambda *args: calls.append(args))
    return calls


@pytest.mark.usefixtures("unfreeze")
def test_gc_is_collected_and_frozen(no_real_rt: list[tuple[object, ...]]) -> None:
    gc.unfreeze()
    notes = realtime_setup(priority=None, cpu=None, lock_memory=False)
    assert gc.get_freeze_count() > 0
    assert notes == [f"gc: {gc.get_freeze_count()} start-up objects frozen"]
    assert no_real_rt == []


@pytest.mark.usefixtures("unfreeze")
@pytest.mark.parametrize(("priority", "cpu"), [(0, -1), (None, None)])
def test_zero_and_none_mean_leave_alone(
    no_real_rt: list[tuple[object, ...]], priority: int | None, cpu: int | None
) -> None:
    assert len(realtime_setup(priority=priority, cpu=cpu, lock_memory=False)) == 1
    assert no_real_rt == []


@pytest.mark.usefixtures("unfreeze")
def test_fifo_and_affinity_are_applied_to_the_calling_thread(
    no_real_rt: list[tuple[object, ...]],
) -> None:
    notes = realtime_setup(priority=50, cpu=1, lock_memory=False)
    [(pid, policy, param), (pid2, cpus)] = no_real_rt
    assert (pid, policy, pid2, cpus) == (0, os.SCHED_FIFO, 0, {1})
    assert isinstance(param, os.sched_param)
    assert param.sched_priority == 50
    assert notes[1:] == [
        "SCHED_FIFO priority 50 for the loop thread",
        "loop thread pinned to CPU 1",
    ]


@pytest.mark.usefixtures("unfreeze")
def test_fifo_permission_error_falls_back_with_warning(
    monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    def refuse(*_args: object) -> None:
        raise PermissionError(errno.EPERM, "Operation not permitted")

    monkeypatch.setattr(os, "sched_setscheduler", refuse)
    with caplog.at_level(logging.WARNING, logger="gateway.runtime.timing.realtime"):
        notes = realtime_setup(priority=50, cpu=None, lock_memory=False)
    assert len(notes) == 2
    assert notes[1].startswith("SCHED_FIFO 50 refused (Operation not permitted; RLIMIT_RTPRIO")
    assert "LimitRTPRIO=" in notes[1]
    assert notes[1].endswith("staying on SCHED_OTHER")
    assert [r.getMessage() for r in caplog.records] == [notes[1]]


@pytest.mark.usefixtures("unfreeze")
def test_priority_out_of_range_is_a_config_error(no_real_rt: list[tuple[object, ...]]) -> None:
    with pytest.raises(ConfigError, match=r"real-time priority: expected 1\.\.99, got 120"):
        realtime_setup(priority=120, cpu=None, lock_memory=False)
    assert no_real_rt == []


@pytest.mark.usefixtures("unfreeze")
def test_unknown_cpu_is_refused_not_raised(caplog: pytest.LogCaptureFixture) -> None:
    before = os.sched_getaffinity(0)
    with caplog.at_level(logging.WARNING, logger="gateway.runtime.timing.realtime"):
        notes = realtime_setup(priority=None, cpu=100_000, lock_memory=False)
    assert os.sched_getaffinity(0) == before
    assert notes[1].startswith("pinning to CPU 100000 refused (Invalid argument; allowed CPUs")
    assert "pinning to CPU 100000 refused" in caplog.text


class FakeLibc:
    """Stands in for the C library: records mlockall flags, fails with ``err`` if set."""

    def __init__(self, err: int = 0) -> None:
        self.err = err
        self.flags: list[int] = []

    def mlockall(self, flags: int) -> int:
        self.flags.append(flags)
        if self.err:
            ctypes.set_errno(self.err)
            return -1
        return 0


@pytest.mark.usefixtures("unfreeze")
def test_mlockall_success(monkeypatch: pytest.MonkeyPatch) -> None:
    libc = FakeLibc()
    monkeypatch.setattr(realtime, "_libc", lambda: libc)
    monkeypatch.setattr(platform, "machine", lambda: "aarch64")
    notes = realtime_setup(priority=None, cpu=None, lock_memory=True)
    assert libc.flags == [1 | 2]  # MCL_CURRENT | MCL_FUTURE
    assert notes[1] == "memory locked (mlockall MCL_CURRENT|MCL_FUTURE)"


@pytest.mark.usefixtures("unfreeze")
def test_mlockall_flags_differ_on_powerpc(monkeypatch: pytest.MonkeyPatch) -> None:
    libc = FakeLibc()
    monkeypatch.setattr(realtime, "_libc", lambda: libc)
    monkeypatch.setattr(platform, "machine", lambda: "ppc64le")
    realtime_setup(priority=None, cpu=None, lock_memory=True)
    assert libc.flags == [0x2000 | 0x4000]


@pytest.mark.usefixtures("unfreeze")
def test_mlockall_refusal_is_a_warning(
    monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    monkeypatch.setattr(realtime, "_libc", lambda: FakeLibc(errno.EPERM))
    with caplog.at_level(logging.WARNING, logger="gateway.runtime.timing.realtime"):
        notes = realtime_setup(priority=None, cpu=None, lock_memory=True)
    expected = ("mlockall refused (Operation not permitted; set LimitMEMLOCK= in the unit): "
                "memory not locked")
    assert notes[1] == expected
    assert caplog.records[0].getMessage() == expected


@pytest.mark.usefixtures("unfreeze")
def test_everything_refused_still_returns(monkeypatch: pytest.MonkeyPatch) -> None:
    def refuse(*_args: object) -> None:
        raise PermissionError(errno.EPERM, "Operation not permitted")

    def no_libc() -> ctypes.CDLL:
        raise OSError("no C library")

    monkeypatch.setattr(os, "sched_setscheduler", refuse)
    monkeypatch.setattr(os, "sched_setaffinity", refuse)
    monkeypatch.setattr(realtime, "_libc", no_libc)
    notes = realtime_setup(priority=10, cpu=0, lock_memory=True)
    assert [n.split(" ")[0] for n in notes] == ["gc:", "SCHED_FIFO", "pinning", "mlockall"]
    assert all("refused" in n or "unavailable" in n for n in notes[1:])


def test_the_longest_gap_between_bursts_tells_a_stall_as_it_was(channel: str) -> None:
    """A loop held up for a while shows that while in the status's timing, whatever the
    deadline statistics make of the deadlines it skipped."""
    import time

    from gateway.runtime.loop import Gateway
    from tests.e2e_helpers import virtual_config

    gw = Gateway(virtual_config(None, channel, rate_hz=100.0))
    try:
        for k in range(5):
            gw.cycle(k * 0.01)
        time.sleep(0.3)  # the stall (at least this long: a lower bound, not a timing test)
        gw.cycle(0.05)
        assert gw.burst_gap_max_s >= 0.3
    finally:
        gw.close()


def test_the_timing_modules_import_one_way() -> None:
    """No import cycle among the timing modules, imports under ``TYPE_CHECKING`` included."""
    import ast
    from pathlib import Path

    from gateway.runtime import timing

    folder = Path(timing.__file__).parent
    prefix = "gateway.runtime.timing."
    graph: dict[str, set[str]] = {}
    for path in folder.glob("*.py"):
        if path.stem == "__init__":
            continue
        deps = graph.setdefault(path.stem, set())
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and (node.module or "").startswith(prefix):
                deps.add((node.module or "").removeprefix(prefix).split(".")[0])
            elif isinstance(node, ast.Import):
                deps.update(a.name.removeprefix(prefix).split(".")[0] for a in node.names
                            if a.name.startswith(prefix))
    assert {"cause", "misses", "scheduler", "stats"} <= graph.keys()

    def reaches(start: str, goal: str, seen: set[str]) -> bool:
        for dep in graph.get(start, ()):
            if dep == goal or (dep not in seen and reaches(dep, goal, seen | {dep})):
                return True
        return False

    cycles = sorted(m for m in graph if reaches(m, m, {m}))
    assert cycles == [], f"expected no import cycle among the timing modules, got one via {cycles}"
