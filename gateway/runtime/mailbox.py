"""Hand-over from the control loop to a worker thread that talks to the network.

The loop must never wait for a network peer: a Zenoh ``put`` costs 50-70 us of the calling
thread, a WebSocket client can stall.  So the loop only *posts* to a :class:`Mailbox` (a lock
held for a few attribute stores) and a worker thread *takes* what is there:

* one slot each for the newest :class:`Snapshot`, the newest state and the newest full status
  report (for ROS 2 diagnostics): a slow worker skips to the latest instead of falling behind
  (old poses are worth nothing);
* the errors, in order and none dropped while fewer than :data:`MAX_ERRORS` wait (beyond that
  the oldest go, counted in :attr:`Delivery.errors_dropped`: a worker that stalled for that
  long has lost its peer anyway);
* the replies to requests that came over the network, in order (never dropped: each answers
  a request the worker admitted, at most one cycle's worth at a time).
"""

from __future__ import annotations

import collections
import threading
from dataclasses import dataclass
from typing import TYPE_CHECKING, Generic, TypeVar

if TYPE_CHECKING:
    from gateway.core.events import StatusEvent
    from gateway.core.kinematics.odometry import OdometryState
    from gateway.core.status import GatewayStatus, LastError
    from gateway.core.types import GatewayState

__all__ = ["MAX_ERRORS", "Delivery", "Mailbox", "Snapshot", "SteerSample", "WheelSample"]

#: Errors kept for a worker that does not take them (the oldest go beyond).
MAX_ERRORS = 256

R = TypeVar("R")


@dataclass(frozen=True, slots=True)
class WheelSample:
    """One driven wheel at a snapshot.

    :param name: the wheel's name.
    :param commanded_rad_s: the speed sent to its motor this cycle (wheel side, rad/s).
    :param measured_rad_s: its last measured speed (``None`` before the first feedback).
    :param position_rad: its last measured angle, unwrapped (``None`` before the first
        feedback): what odometry integrates, so a recording can be replayed.
    """

    name: str
    commanded_rad_s: float
    measured_rad_s: float | None
    position_rad: float | None = None


@dataclass(frozen=True, slots=True)
class SteerSample:
    """One steering actuator at a snapshot.

    :param name: the actuator's name.
    :param commanded_rad: the angle sent to it this cycle (rad).
    :param measured_rad: its last measured angle (``None`` before the first feedback).
    """

    name: str
    commanded_rad: float | None
    measured_rad: float | None


@dataclass(frozen=True, slots=True)
class Snapshot:
    """What the loop shows the world at the odometry rate.

    :param stamp_ns: wall-clock time of the cycle, ns since the Unix epoch (ROS stamps).
    :param odometry: pose, body twist, slip and distance.
    :param state: the gateway's state.
    :param reason: why it is in FAULT or ESTOP ('' otherwise).
    :param wheels: every driven wheel, in model order.
    :param steering: every steering actuator.
    """

    stamp_ns: int
    odometry: OdometryState
    state: GatewayState
    reason: str
    wheels: tuple[WheelSample, ...]
    steering: tuple[SteerSample, ...] = ()


@dataclass(frozen=True, slots=True)
class Delivery(Generic[R]):
    """What a worker takes at once (see :meth:`Mailbox.take`).

    :param snapshot: the newest snapshot since the last take, if any.
    :param status: the newest state since the last take, if any.
    :param errors: the errors since the last take, oldest first.
    :param replies: the replies since the last take, oldest first.
    :param errors_dropped: errors lost because :data:`MAX_ERRORS` were waiting.
    :param closed: the mailbox was closed: the worker should end.
    :param report: the newest full status since the last take, if any.
    """

    snapshot: Snapshot | None
    status: StatusEvent | None
    errors: tuple[LastError, ...]
    replies: tuple[R, ...]
    errors_dropped: int
    closed: bool
    report: GatewayStatus | None = None


class Mailbox(Generic[R]):
    """The loop's posts for one worker (thread-safe; posting never blocks on the worker)."""

    def __init__(self) -> None:
        self._cond = threading.Condition(threading.Lock())
        self._snapshot: Snapshot | None = None
        self._status: StatusEvent | None = None
        self._report: GatewayStatus | None = None
        self._errors: collections.deque[LastError] = collections.deque()
        self._replies: list[R] = []
        self._dropped = 0
        self._closed = False

    def post(self, snapshot: Snapshot | None = None, status: StatusEvent | None = None,
             errors: tuple[LastError, ...] = (), replies: tuple[R, ...] = (),
             report: GatewayStatus | None = None) -> None:
        """Leave news for the worker (the newest snapshot, state and report replace older
        ones)."""
        if (snapshot is None and status is None and not errors and not replies
                and report is None):
            return
        with self._cond:
            if snapshot is not None:
                self._snapshot = snapshot
            if status is not None:
                self._status = status
            if report is not None:
                self._report = report
            for err in errors:
                if len(self._errors) == MAX_ERRORS:
                    self._errors.popleft()
                    self._dropped += 1
                self._errors.append(err)
            self._replies += replies
            self._cond.notify()

    def take(self, timeout_s: float | None = None) -> Delivery[R]:
        """Wait up to ``timeout_s`` (for ever: ``None``) for news, then take all of it."""
        with self._cond:
            if not self._pending():
                self._cond.wait(timeout_s)
            out = Delivery(self._snapshot, self._status, tuple(self._errors),
                           tuple(self._replies), self._dropped, self._closed, self._report)
            self._snapshot = self._status = self._report = None
            self._errors.clear()
            self._replies = []
            self._dropped = 0
            return out

    def close(self) -> None:
        """Wake the worker for the last time (its next take says ``closed``)."""
        with self._cond:
            self._closed = True
            self._cond.notify_all()

    def _pending(self) -> bool:
        return (self._closed or self._snapshot is not None or self._status is not None
                or self._report is not None or bool(self._errors) or bool(self._replies))
