"""What the gateway tells the world: odometry and status at their rates, errors as they come.

:class:`Publisher` encodes ``WG_Odom_Pose``, ``WG_Odom_Velocity``, ``WG_Status`` and
``WG_Error`` frames (:mod:`gateway.wire.can`) and puts the same news in the outbox, as typed
events (:mod:`gateway.core.events`), that the daemon hands to socket subscribers (in their JSON
form, :mod:`gateway.wire.socket.events`).  :class:`gateway.runtime.loop.Gateway` owns one and
sends the frames it returns after each cycle's burst of commands, untracked (reports, not
commands: the next one replaces a lost one).

Errors are reports too.  Every error goes to the outbox at once, but on CAN one ``WG_Error``
goes out per cycle at most: a client that pipelines refused twists, whatever their number,
costs the bus one frame per cycle.  Which one: the newest, except that an answer to a request
(an infeasible twist, a bad command, one refused while not enabled) never displaces a pending
error of the robot's own state (a fault, an e-stop, a bus error, a lost commander or feedback,
a wheel not tracking), so a flood of refusals cannot hide a fault from a CAN listener.  The
others are counted (``errors_not_sent``); the frame's ``count`` field (every error so far)
shows a receiver how many it did not get.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from gateway.core.cadence import next_due
from gateway.core.events import OdometryEvent, StatusEvent
from gateway.core.status import LastError
from gateway.core.types import ConstraintCode, ErrorCode
from gateway.wire.can import NO_TWIST_COUNTER, NO_WHEEL, ErrorReport, StatusFlags, StatusReport

if TYPE_CHECKING:
    from collections.abc import Mapping

    from gateway.core.control import Rejection, Supervisor
    from gateway.core.events import OutboxEvent
    from gateway.core.kinematics import LimitReport
    from gateway.core.kinematics.odometry import Odometry
    from gateway.core.settings import LoopConfig
    from gateway.core.types import Frame
    from gateway.runtime.timing import LoopTimer
    from gateway.wire.can import WgCodec

#: The errors that answer a request: never sent in place of a pending error of another code.
REQUEST_ERRORS = frozenset({ErrorCode.INFEASIBLE_TWIST, ErrorCode.BAD_COMMAND,
                            ErrorCode.NOT_ENABLED})


class Publisher:
    """The gateway's reports, on CAN and in the outbox.

    :param loop: the ``gateway:`` settings (the odometry and status rates).
    :param wg: the codec of the gateway's own CAN frames.
    :param supervisor: the state machine whose state and counters the status reports.
    :param odometry: the odometry whose state is published.
    :param timer: the loop's timing (missed cycles, in the status).
    :param wheel_of: each motor's name -> the model index of its wheel (a steering
        actuator's: its first wheel), for the wheel field of WG_Error and the status's mask.
    """

    def __init__(self, loop: LoopConfig, wg: WgCodec, supervisor: Supervisor,
                 odometry: Odometry, timer: LoopTimer, wheel_of: Mapping[str, int]) -> None:
        self._odom_period_s = 1.0 / loop.odom_rate_hz
        self._status_period_s = 1.0 / loop.status_rate_hz
        self.wg = wg
        self.supervisor = supervisor
        self.odometry = odometry
        self.timer = timer
        self.wheel_of = wheel_of
        self._next_odom_s = 0.0
        self._next_status_s = 0.0
        #: The earliest time a report is due (s): nothing to do before it.
        self.next_due_s = 0.0
        self._status_counter = 0
        self._error_count = 0
        # The error whose WG_Error goes out with the next reports.
        self._error: ErrorReport | None = None
        #: News for socket subscribers, oldest first; the daemon empties it every cycle.
        self.outbox: list[OutboxEvent] = []
        #: The last error reported.
        self.last_error: LastError | None = None

    def error(
        self,
        code: ErrorCode,
        message: str,
        rejection: Rejection | None = None,
        twist_counter: int = NO_TWIST_COUNTER,
        wheel: str | None = None,
    ) -> bool:
        """Report an error: in the outbox at once, on CAN as a ``WG_Error`` with the next
        reports (:meth:`publish`) unless another error takes its place (see the module's
        docstring).

        :param wheel: the wheel the error is about, when it is not the rejection's.
        :return: whether an error's frame will not be sent (this one's, or the one it
            displaced).
        """
        self._error_count += 1
        err = rejection.error if rejection is not None else None
        if err is not None:
            wheel = err.wheel
        pending = self._error
        report = ErrorReport(
            code=code,
            wheel=NO_WHEEL if wheel is None else self.wheel_of[wheel],
            constraint=ConstraintCode.from_name(err.constraint) if err else ConstraintCode.NONE,
            twist_counter=twist_counter,
            residual_m_s=err.residual_m_s if err else 0.0,
            count=self._error_count,
        )
        if (pending is None or code not in REQUEST_ERRORS
                or pending.code in REQUEST_ERRORS):
            self._error = report
        self.next_due_s = -math.inf  # the reports are due now: the pending error's frame
        self.last_error = LastError(code, message)
        self.outbox.append(self.last_error)
        return pending is not None

    def publish(self, now_s: float, limit_report: LimitReport | None,
                bus_trouble: bool) -> list[Frame]:
        """The error frames waiting, and the odometry and status frames due at ``now_s`` (the
        outbox gets their news).

        :param limit_report: the last limits' report (the status's SPEED_LIMITED flag).
        :param bus_trouble: failed bursts or a controller not error-active lately.
        """
        frames: list[Frame] = []
        if self._error is not None:
            frames.append(self.wg.encode_error(self._error))
            self._error = None
        if now_s >= self._next_odom_s:
            self._next_odom_s = next_due(self._next_odom_s, now_s, self._odom_period_s)
            st = self.odometry.state
            frames.append(self.wg.encode_pose(st.pose))
            frames.append(self.wg.encode_velocity(st.twist, st.slip_m_s))
            self.outbox.append(OdometryEvent(st))
        if now_s >= self._next_status_s:
            self._next_status_s = next_due(self._next_status_s, now_s, self._status_period_s)
            frames.append(self.wg.encode_status(self.status_report(limit_report, bus_trouble)))
            self.outbox.append(StatusEvent(self.supervisor.state, self.supervisor.reason))
        self.next_due_s = min(self._next_odom_s, self._next_status_s)
        return frames

    def status_report(self, limit_report: LimitReport | None,
                      bus_trouble: bool) -> StatusReport:
        """The WG_Status content (each call advances its counter)."""
        sup = self.supervisor
        mask = 0
        for name in sup.faulted:
            mask |= 1 << min(self.wheel_of[name], 7)  # wheels 8 and up share bit 7
        flags = StatusFlags(0)
        if sup.cmd_timeout_active:
            flags |= StatusFlags.CMD_TIMEOUT_ACTIVE
        if limit_report is not None and limit_report.speed_scale < 1.0:
            flags |= StatusFlags.SPEED_LIMITED
        if sup.counts.projected:
            flags |= StatusFlags.PROJECTED
        if bus_trouble:
            flags |= StatusFlags.BUS_ERRORS_RECENT
        self._status_counter = (self._status_counter + 1) & 0xFF
        return StatusReport(
            state=sup.state,
            faulted_motors=mask,
            counter=self._status_counter,
            flags=flags,
            missed_cycles=self.timer.missed,
            infeasible_count=sup.counts.infeasible,
        )
