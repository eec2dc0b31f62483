"""Late starts classified by cause (:class:`gateway.runtime.timing.MissProbe`), and where they
show."""

from __future__ import annotations

import json
import logging
import os
import re
import threading
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING

import pytest

from gateway.cli import main
from gateway.config import load_config
from gateway.runtime.daemon import Daemon
from gateway.runtime.sdnotify import SystemdNotifier
from gateway.runtime.timing import MissCause, MissProbe, Scheduler
from gateway.runtime.timing.misses import RECENT, REPORT_INTERVAL_S, SchedStat
from tests.runtime.timing_helpers import FakeClock

if TYPE_CHECKING:
    from click.testing import CliRunner

PERIOD_S = 0.010  # 100 Hz
SPIN_S = 200e-6


@dataclass
class FakeThread:
    """What the kernel would say of the loop thread: CPU time and run-queue wait, in ns."""

    on_cpu_ns: int = 0
    runnable_ns: int = 0
    readable: bool = True

    def read(self) -> tuple[int, int] | None:
        return (self.on_cpu_ns, self.runnable_ns) if self.readable else None


def loop(clock: FakeClock, thread: FakeThread) -> tuple[Scheduler, MissProbe]:
    sched = Scheduler(1 / PERIOD_S, spin_s=SPIN_S, clock=clock, sleep=clock.sleep)
    probe = MissProbe(sched, read=thread.read)
    probe.before_wait()
    probe.after_wait(sched.wait_next())
    return sched, probe


def next_cycle(sched: Scheduler, probe: MissProbe) -> None:
    probe.before_wait()
    probe.after_wait(sched.wait_next())


@pytest.mark.parametrize("cause", list(MissCause))
def test_each_cause_is_told_apart(cause: MissCause) -> None:
    clock = FakeClock(oversleep=0.0 if cause is MissCause.ON_CPU else 0.025)
    thread = FakeThread()
    sched, probe = loop(clock, thread)
    if cause is MissCause.ON_CPU:
        clock.work(0.035)  # the cycle itself ran 3.5 periods
        thread.on_cpu_ns += 35_000_000
    else:
        clock.work(0.001)
        thread.on_cpu_ns += 1_000_000
        if cause is MissCause.RUNNABLE:  # woken in time, but another thread had the CPU
            thread.runnable_ns += 25_000_000
    next_cycle(sched, probe)
    assert sched.timer.missed == 2
    miss = probe.recent[-1]
    assert (miss.cause, miss.skipped) == (cause, 2)
    stats = sched.timer.snapshot()
    late = {c: getattr(stats, f"late_{c.value}") for c in MissCause}
    assert late == {c: int(c is cause) for c in MissCause}
    assert probe.describe().startswith("1 late starts (2 deadlines skipped)")


def test_on_time_and_slightly_late_starts_are_not_classified() -> None:
    clock = FakeClock()
    thread = FakeThread()
    sched, probe = loop(clock, thread)
    clock.work(0.015)  # late by half a period: no deadline skipped
    thread.on_cpu_ns += 15_000_000
    next_cycle(sched, probe)
    next_cycle(sched, probe)
    assert sched.timer.missed == 0
    assert not probe.recent and sum(sched.timer.late_by_cause.values()) == 0
    assert probe.describe() == "no late starts"


def test_the_interval_starts_at_the_previous_start() -> None:
    """CPU time of earlier cycles does not count against a later late start."""
    clock = FakeClock(oversleep=0.0)
    thread = FakeThread()
    sched, probe = loop(clock, thread)
    for _ in range(5):  # busy but on time: 8 ms of a 10 ms period each
        clock.work(0.008)
        thread.on_cpu_ns += 8_000_000
        next_cycle(sched, probe)
    clock.oversleep = 0.025
    clock.work(0.001)
    thread.on_cpu_ns += 1_000_000
    next_cycle(sched, probe)
    assert probe.recent[-1].cause is MissCause.ASLEEP
    assert probe.recent[-1].on_cpu_s == pytest.approx(0.001)


def test_reports_come_at_once_then_at_most_every_interval() -> None:
    clock = FakeClock(oversleep=0.025)  # every wait wakes 2.5 periods late: asleep
    thread = FakeThread()
    sched, probe = loop(clock, thread)
    assert probe.report(clock.now) is None  # nothing yet
    next_cycle(sched, probe)
    first = probe.report(clock.now)
    assert first is not None
    assert first.startswith("1 late start (on CPU 0, runnable 0, asleep 1; worst 24.8 ms late)")
    for _ in range(3):
        next_cycle(sched, probe)
        assert probe.report(clock.now) is None  # within the interval: held back
    clock.work(REPORT_INTERVAL_S)
    thread.on_cpu_ns += int(REPORT_INTERVAL_S * 1e9)  # and a long stretch of work: on CPU
    next_cycle(sched, probe)
    second = probe.report(clock.now)
    assert second is not None
    assert second.startswith("4 late starts (on CPU 1, runnable 0, asleep 3; worst ")
    assert second.endswith(f"; {sched.timer.missed} deadlines skipped since start-up")
    assert probe.report(clock.now + 2 * REPORT_INTERVAL_S) is None  # nothing new


def test_the_report_names_the_worst_start_even_among_many() -> None:
    """A freeze of seconds followed by more small late starts than the probe keeps: the next
    line's "worst" is the freeze (it was the worst of the last 64 only, and said 25 ms)."""
    clock = FakeClock(oversleep=0.025)
    thread = FakeThread()
    sched, probe = loop(clock, thread)
    next_cycle(sched, probe)
    assert probe.report(clock.now) is not None  # the first line, at once
    clock.oversleep = 2.0  # SIGSTOP for two seconds
    next_cycle(sched, probe)
    clock.oversleep = 0.025
    for _ in range(2 * RECENT):
        next_cycle(sched, probe)
    line = probe.report(clock.now + REPORT_INTERVAL_S)
    assert line is not None and "; worst 1999.8 ms late)" in line, line
    assert int(line.split()[0]) > RECENT  # (more than the probe keeps)


def test_the_daemon_logs_the_reports(daemon: Daemon, monkeypatch: pytest.MonkeyPatch,
                                     caplog: pytest.LogCaptureFixture) -> None:
    probe = daemon.miss_probe
    assert probe is not None
    lines = iter(["3 late starts (as if)"])
    monkeypatch.setattr(probe, "report", lambda now_s: next(lines, None))
    with caplog.at_level(logging.INFO, logger="gateway.runtime.daemon"):
        deadline = time.monotonic() + 5.0
        while "control loop: 3 late starts (as if)" not in caplog.text:
            assert time.monotonic() < deadline, caplog.text
            time.sleep(0.01)
    # This daemon runs its simulators in-process (--sim): late starts are INFO there, a
    # WARNING only with real controllers.
    record = next(r for r in caplog.records if "3 late starts" in r.getMessage())
    assert daemon.sim is not None and record.levelno == logging.INFO


def test_without_statistics_nothing_is_classified() -> None:
    clock = FakeClock()
    thread = FakeThread(readable=False)
    sched, probe = loop(clock, thread)
    clock.work(0.035)
    next_cycle(sched, probe)
    assert sched.timer.missed == 2  # still counted as missed, just not classified
    assert not probe.available and not probe.recent
    assert "not classified" in probe.describe()


@pytest.mark.skipif(not os.path.exists("/proc/thread-self/schedstat"), reason="Linux only")
def test_this_threads_statistics_are_read_and_grow() -> None:
    stat = SchedStat()
    try:
        first = stat.read()
        assert first is not None
        sum(i * i for i in range(200_000))  # some CPU time
        second = stat.read()
        assert second is not None and second[0] > first[0] and second[1] >= first[1]
    finally:
        stat.close()
    assert stat.read() is None


def test_status_prints_late_starts_by_cause(runner: CliRunner, daemon: Daemon,
                                            sock_path: str) -> None:
    result = runner.invoke(main, ["status", "--socket", sock_path, "--json"])
    assert result.exit_code == 0, result.output
    timing = json.loads(result.stdout)["timing"]
    assert {"late_on_cpu", "late_runnable", "late_asleep"} <= set(timing)
    assert daemon.miss_probe is not None  # made by run(), in the loop's thread
    # As if the loop had started late this often (the real loop may add its own).
    for cause, n in (("on_cpu", 300), ("runnable", 200), ("asleep", 500)):
        daemon.scheduler.timer.late_by_cause[cause] += n
    result = runner.invoke(main, ["status", "--socket", sock_path])
    assert result.exit_code == 0, result.output
    found = re.search(r"missed \(late starts: on CPU (\d+), runnable (\d+), asleep (\d+)\);",
                      result.stdout)
    assert found is not None, result.stdout
    assert all(int(n) >= k for n, k in zip(found.groups(), (300, 200, 500), strict=True))


def test_with_real_controllers_late_starts_are_a_warning(
        sock_path: str, channel: str, monkeypatch: pytest.MonkeyPatch,
        caplog: pytest.LogCaptureFixture) -> None:
    """No simulators in the process: a late start is the machine's or the loop's, a WARNING."""
    cfg = load_config(None, {"channel": channel})
    d = Daemon(cfg, sim=False, socket_path=sock_path, notifier=SystemdNotifier(None))
    thread = threading.Thread(target=d.run, daemon=True)
    with caplog.at_level(logging.INFO, logger="gateway.runtime.daemon"):
        thread.start()
        try:
            deadline = time.monotonic() + 5.0
            while d.miss_probe is None:
                assert time.monotonic() < deadline
                time.sleep(0.01)
            lines = iter(["2 late starts (as if)"])
            monkeypatch.setattr(d.miss_probe, "report", lambda now_s: next(lines, None))
            while "control loop: 2 late starts (as if)" not in caplog.text:
                assert time.monotonic() < deadline + 5.0, caplog.text
                time.sleep(0.01)
        finally:
            d.request_stop()
            thread.join(timeout=10)
    record = next(r for r in caplog.records if "2 late starts" in r.getMessage())
    assert record.levelno == logging.WARNING
