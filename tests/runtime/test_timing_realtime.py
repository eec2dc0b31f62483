"""Loop timing: the real-time set-up (``realtime_setup``: gc, SCHED_FIFO, affinity, mlockall),
the longest gap between bursts, and the direction of the timing modules' imports."""

from __future__ import annotations

import ctypes
import errno
import gc
import logging
import os
import platform
from typing import TYPE_CHECKING

import pytest

from gateway.core.errors import ConfigError
from gateway.runtime.timing import realtime, realtime_setup

if TYPE_CHECKING:
    from collections.abc import Iterator


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
