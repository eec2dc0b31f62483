"""The loop's hand-over to a worker: newest snapshot and state win, errors and replies keep
their order, nothing waits on the worker, and a closed mailbox wakes it."""

from __future__ import annotations

import threading

from gateway.core.events import StatusEvent
from gateway.core.kinematics.odometry import OdometryState, Pose
from gateway.core.status import LastError
from gateway.core.types import ErrorCode, GatewayState, Twist
from gateway.runtime.mailbox import MAX_ERRORS, Mailbox, Snapshot, WheelSample
from tests.wire.status_samples import sample_status


def snap(x: float) -> Snapshot:
    odom = OdometryState(Pose(x, 0.0, 0.0), Twist(), 0.0, x, 0.0)
    return Snapshot(1, odom, GatewayState.RUNNING, "", (WheelSample("a", 1.0, None),))


def test_the_newest_snapshot_and_state_win_errors_and_replies_keep_order() -> None:
    box: Mailbox[str] = Mailbox()
    box.post(snap(1.0), StatusEvent(GatewayState.ENABLING, ""), (LastError(ErrorCode.ESTOP, "a"),),
             ("r1",))
    box.post(snap(2.0), StatusEvent(GatewayState.RUNNING, ""), (LastError(ErrorCode.ESTOP, "b"),),
             ("r2",))
    got = box.take(0.0)
    assert got.snapshot is not None and got.snapshot.odometry.pose.x_m == 2.0
    assert got.status == StatusEvent(GatewayState.RUNNING, "")
    assert [e.message for e in got.errors] == ["a", "b"]
    assert got.replies == ("r1", "r2")
    assert not got.closed and got.errors_dropped == 0
    empty = box.take(0.0)
    assert empty.snapshot is None and empty.status is None and not empty.errors
    assert empty.report is None


def test_the_newest_full_report_wins_and_wakes_the_worker() -> None:
    box: Mailbox[str] = Mailbox()
    box.post(report=sample_status(robot="old"))
    box.post(report=sample_status(robot="new"))
    got = box.take(5.0)  # (returns at once: a report is news)
    assert got.report is not None and got.report.robot == "new"
    assert box.take(0.0).report is None


def test_errors_beyond_the_bound_drop_the_oldest_and_are_counted() -> None:
    box: Mailbox[str] = Mailbox()
    for i in range(MAX_ERRORS + 5):
        box.post(errors=(LastError(ErrorCode.BAD_COMMAND, str(i)),))
    got = box.take(0.0)
    assert len(got.errors) == MAX_ERRORS and got.errors_dropped == 5
    assert got.errors[0].message == "5"


def test_a_worker_waits_for_news_and_close_wakes_it() -> None:
    box: Mailbox[str] = Mailbox()
    taken: list[object] = []
    ready = threading.Event()

    def work() -> None:
        ready.set()
        while True:
            got = box.take(5.0)
            taken.append(got.snapshot)
            if got.closed:
                return

    worker = threading.Thread(target=work)
    worker.start()
    ready.wait(5.0)
    box.post(snap(3.0))
    box.close()
    worker.join(5.0)
    assert not worker.is_alive()
    assert any(s is not None for s in taken)


def test_posting_nothing_does_not_wake_the_worker() -> None:
    box: Mailbox[str] = Mailbox()
    box.post()
    got = box.take(0.01)
    assert got.snapshot is None and not got.errors and not got.replies and not got.closed
