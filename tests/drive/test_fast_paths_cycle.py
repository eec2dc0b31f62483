"""The per-cycle fast paths give the same results as the general code they shortcut.

Issue 6: the drive set's status order, ``drain`` and ``to_message``, and the daemon's wait,
which must never ask epoll (whole milliseconds, rounded up) for more time than is left.
Issue 15: the drive set's per-cycle states and feedback (no status objects) and whether any
motor is in trouble (one comparison while none can be), the tracking check's skip while nothing
changes, the supervisor's reused decisions.
"""

from __future__ import annotations

import math
import random
from typing import Any

import can
import pytest

from gateway.bus.can_bus import drain, to_message
from gateway.config import load_config, parse_config
from gateway.core.control import StatusBoard, Supervisor
from gateway.core.settings import LoopConfig, TrackingLimits
from gateway.core.tracking import TrackingMonitor
from gateway.core.types import (
    DriveFault,
    DriveState,
    Frame,
    GatewayState,
    MotorStatus,
    Twist,
    WheelFeedback,
)
from gateway.drive.driveset import DriveSet
from gateway.drive.liveness import Liveness
from gateway.runtime.daemon import Daemon
from gateway.runtime.sdnotify import SystemdNotifier
from tests.conftest import CONFIG_DIR, MIXED_ROBOT
from tests.e2e_helpers import Rig, virtual_config


def test_drive_set_status_in_model_order_across_drivers() -> None:
    cfg = parse_config(MIXED_ROBOT, "<mixed>")
    drives = DriveSet(cfg)
    names = [s.name for s in drives.status(0.0)]
    assert names == [w.name for w in cfg.model.wheels]
    speeds = [1.0, 2.0, 3.0, 4.0]
    assert len(drives.preview(speeds)) == 4


def test_drain_and_to_message(channel: str) -> None:
    tx = can.Bus(interface="virtual", channel=channel)
    rx = can.Bus(interface="virtual", channel=channel)
    try:
        assert drain(rx) == []
        frames = [Frame(0x123, b"\x01\x02"), Frame(0x1ABCDEF, b"", True, True, 4)]
        for f in frames:
            msg = to_message(f)
            assert (msg.arbitration_id, bytes(msg.data), msg.is_extended_id,
                    msg.is_remote_frame, msg.dlc) == tuple(f[:5])
            tx.send(msg)
        assert drain(rx, limit=0) == []  # nothing taken
        assert drain(rx, timestamp_s=7.0) == frames
        assert drain(rx) == []
    finally:
        tx.shutdown()
        rx.shutdown()


class _FakeServer:
    """Records poll timeouts and stands in for the control server."""

    def __init__(self, clock: list[float]) -> None:
        self.clock = clock
        self.timeouts: list[float] = []

    def poll(self, timeout_s: float) -> list[object]:
        self.timeouts.append(timeout_s)
        self.clock[0] += math.ceil(timeout_s * 1e3) * 1e-3  # what epoll does
        return []


def test_wait_never_oversleeps_the_deadline(channel: str, sock_path: str) -> None:
    cfg = load_config(None, {"interface": "virtual", "channel": channel})
    daemon = Daemon(cfg, socket_path=sock_path, notifier=SystemdNotifier(None))
    real_server = daemon.server
    try:
        now = [100.0]
        sched = daemon.scheduler

        def clock() -> float:
            now[0] += 1e-6  # every reading takes a microsecond, so the spin ends
            return now[0]

        sched._clock = clock

        def sleep(seconds: float) -> None:
            now[0] += seconds

        sched._sleep = sleep
        fake = _FakeServer(now)
        daemon.server = fake  # type: ignore[assignment]
        daemon._server_fd = None
        sched.start(now[0])
        for offset in (0.0, 0.0003, 0.0021, 0.0049):
            now[0] = sched.next_deadline_s() - sched.period_s + offset
            deadline = sched.next_deadline_s()
            daemon._wait()
            assert sched.timer.missed == 0
            assert deadline <= now[0] <= deadline + 1e-5
        assert fake.timeouts[-1] == 0.0  # the pass at the deadline
        # Only whole milliseconds minus a half, which epoll rounds up to the whole ones.
        assert all(t == 0.0 or abs(t * 1e3 - math.floor(t * 1e3) - 0.5) < 1e-6
                   for t in fake.timeouts)
        assert any(t > 0.0 for t in fake.timeouts)
    finally:
        daemon.server = real_server
        daemon.close()


def test_drive_set_states_and_feedback_match_the_statuses(channel: str) -> None:
    """The per-cycle accessors give what the statuses would, motor for motor."""
    for robot in ("mecanum.yaml", "swerve.yaml", "ackermann.yaml", "differential_tub.yaml"):
        with Rig(virtual_config(CONFIG_DIR / robot, f"{channel}-{robot}")) as rig:
            drives = rig.gw.drives
            checks = 0
            for k in range(30):
                if k == 5:
                    rig.gw.supervisor.enable(rig.t)
                rig.advance(rig.period)
                statuses = drives.status(rig.t)
                assert drives.states(rig.t) == [s.state for s in statuses]
                assert drives.troubled(rig.t) == any(
                    s.state in (DriveState.FAULT, DriveState.OFFLINE) for s in statuses)
                got = drives.motor_feedback()
                assert all(a is b.feedback for a, b in zip(got, statuses, strict=True))
                assert drives.feedback_by_wheel() == drives._slot_feedback()[:rig.gw.model.n]
                checks += sum(f is not None for f in got)
            assert checks > 0
    cfg = parse_config(MIXED_ROBOT, "<mixed>")
    drives = DriveSet(cfg)
    assert drives._status_order is not None
    assert drives.states(0.0) == [s.state for s in drives.status(0.0)]
    assert drives.motor_feedback() == [s.feedback for s in drives.status(0.0)]


@pytest.mark.parametrize("streams", [("feedback",), ("heartbeat", "encoder")])
@pytest.mark.parametrize("seed", range(4))
def test_all_alive_matches_every_motors_alive(streams: tuple[str, ...], seed: int) -> None:
    """``Liveness.all_alive`` (one comparison while nothing can have gone silent) says what
    ``alive`` of every motor says, over streams heard now and then, late, never, and with
    times that go back (a frame stamped before the one taken just before it)."""
    rng = random.Random(seed)
    limits = [0.05, 0.1, 0.02]
    live = Liveness(len(limits), streams, limits)
    t, shortcuts = 0.0, 0
    for _ in range(20_000):
        t += rng.choice((0.0, 0.001, 0.004, 0.05 * rng.random()))
        if rng.random() < 0.6:
            back = rng.choice((0.0, 0.0, 0.0, 0.003, 1e-12))
            live.heard(rng.randrange(len(limits)), rng.randrange(len(streams)), t - back)
        # Now and then exactly on a limit, where rounding decides.
        now = t if rng.random() < 0.9 else (live.oldest[0] or 0.0) + limits[0]
        calm = now <= live._calm_until
        expected = all(live.alive(i, now) for i in range(len(limits)))
        assert live.all_alive(now) is expected
        shortcuts += calm
    assert shortcuts > 200  # the shortcut was taken


def _monitor_state(mon: TrackingMonitor) -> tuple[object, ...]:
    return (list(mon._count), mon._last_s, list(mon._peak), list(mon._peak_before),
            mon._period_start_s, mon.worst_ratio)


@pytest.mark.parametrize("seed", range(6))
def test_tracking_skip_matches_the_full_check(seed: int) -> None:
    """``check`` (which skips while nothing changes) and the wheel-by-wheel path agree on every
    fault and every piece of state, over commands and feedback that change now and then."""
    rng = random.Random(seed)
    limits = TrackingLimits(tolerance_rad_s=1.0, tolerance_ratio=0.2, time_s=0.2)
    fast, full = TrackingMonitor(limits), TrackingMonitor(limits)
    bands: list[tuple[float, float] | None] = [None, (0.5, 2.0), None] if seed % 2 else []
    fast.dead_bands = full.dead_bands = bands
    n = 3
    command = tuple(rng.uniform(-5, 5) for _ in range(n))
    feedback: list[WheelFeedback | None] = [None] * n
    full_checks = [0]
    check_all = fast._check_all

    def counting(*args: Any) -> Any:
        full_checks[0] += 1
        return check_all(*args)

    fast._check_all = counting  # type: ignore[method-assign,assignment]
    t, steps = 0.0, 3000
    for step in range(steps):
        t += 0.001
        roll = rng.random()
        if roll < 0.004:
            command = tuple(rng.choice((0.0, 1.0, -1.5, rng.uniform(-8, 8))) for _ in range(n))
        elif roll < 0.02:
            command = (*command[:-1], command[-1])  # equal, not the same object
        if rng.random() < 0.1:
            i = rng.randrange(n)
            # Mostly inside the window, so that the check has quiet spells to skip (a wheel
            # that leaves it keeps a count for a while after it is back).
            off = rng.choice((0.0, 0.1, -0.3, 0.5))
            if rng.random() < 0.004:
                off = rng.choice((3.0, -9.0, math.nan))
            band = bands[i] if i < len(bands) else None
            # A controller stops its motor on a command in its dead band.
            speed = 0.0 if band and band[0] < abs(command[i]) < band[1] else command[i]
            feedback[i] = WheelFeedback(0.0, speed + off, t)
        if step % 700 == 699:
            fast.reset()
            full.reset()
        fb = list(feedback)
        a = fast.check(command, fb, t)
        b = full._check_all(command, fb, t)
        assert a == b
        assert _monitor_state(fast) == _monitor_state(full)
    assert full_checks[0] < 0.7 * steps  # the skip was taken


def test_tracking_skip_on_new_feedback_uses_each_wheels_checked_command() -> None:
    """New feedback inside every window is skipped; a wheel whose command is in its dead band
    is checked against zero (the controller stops it), so turning at the command is outside."""
    limits = TrackingLimits(tolerance_rad_s=1.0, tolerance_ratio=0.2, time_s=0.2)
    fast, full = TrackingMonitor(limits), TrackingMonitor(limits)
    bands: list[tuple[float, float] | None] = [(0.5, 2.0), None]
    fast.dead_bands = full.dead_bands = bands
    command = (1.5, 3.0)
    for k, speeds in enumerate([(0.0, 3.0), (0.2, 3.5), (1.5, 3.0), (1.5, 3.0), (0.0, 3.1)]):
        fb = [WheelFeedback(0.0, v, 0.001 * k) for v in speeds]
        assert fast.check(command, fb, 0.01 * k) == full._check_all(command, fb, 0.01 * k)
        assert _monitor_state(fast) == _monitor_state(full), k
    assert fast._count[0] > 0.0  # turning at a command in its band was outside: counted


def test_supervisor_decisions_are_reused_only_while_equal() -> None:
    model = load_config(None).model
    sup = Supervisor(model, LoopConfig(cmd_timeout_s=0.5))
    sup.enable(0.0)
    assert sup.decide(0.0) is sup.decide(0.1)  # ENABLING: one constant decision
    assert sup.take_enable_request()  # (the loop sends the enable frames)
    enabled = [MotorStatus(w.name, k + 1, DriveState.ENABLED, DriveFault.NONE, "", 0.0, None)
               for k, w in enumerate(model.wheels)]
    sup.motors(StatusBoard(enabled), 0.0)
    assert sup.state is GatewayState.RUNNING
    decisions = []
    for k, twist in enumerate((Twist(0.1, 0, 0), Twist(0.1, 0, 0), Twist(0.2, 0, 0))):
        sup.twist(twist, k * 0.1)
        first, again = sup.decide(k * 0.1), sup.decide(k * 0.1 + 0.01)
        assert first is again and first.twist is twist and not first.cmd_timeout
        assert (first.ramp, first.armed) == (True, True)
        decisions.append(first)
    assert decisions[0] is not decisions[1]  # equal twists, new objects: new decisions
    timed_out = sup.decide(5.0)
    assert timed_out.cmd_timeout and timed_out.twist == Twist()
    assert sup.decide(5.1) is timed_out
