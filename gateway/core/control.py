"""The gateway's decisions, kept pure: which twist to follow, when to stop, when to disarm.

:class:`Supervisor` takes events (twists from any source, stop, e-stop, enable, disable, the
motors' states) with explicit times and answers, each cycle, with a :class:`Decision`: the
twist to command, whether to ramp to it through the acceleration limits or jump (e-stop), and
whether the drives should be armed.  The loop (:mod:`gateway.runtime.loop`) does the I/O around it.

States (:class:`~gateway.core.types.GatewayState`)::

    DISABLED --enable--> ENABLING --all motors ENABLED--> RUNNING
    ENABLING --another program commands the motors--> FAULT (released; runtime.commanders)
    RUNNING  --motor FAULT/OFFLINE, a wheel off its command, a command not encodable--> FAULT
    FAULT    --all answer again, recovery "auto" (3 tries)--> ENABLING
    FAULT    --enable (recovery "manual")--> ENABLING
    any      --e-stop--> ESTOP --enable--> ENABLING
    any      --disable--> DISABLED            ENABLING --timeout--> FAULT

Every change of state goes through one method, checked against :mod:`gateway.core.transitions`.

Safety rules:

* no valid twist for ``cmd_timeout_s`` (when > 0): the target becomes zero, reached within the
  deceleration limits;
* an infeasible twist: ``reject`` answers with the error and ramps to zero; ``project``
  follows the nearest feasible twist and counts a warning;
* a motor that faults or stops answering, or a wheel that stays off its command longer than
  ``tracking_time_s`` (:mod:`gateway.core.tracking`): zero for every wheel (and disarm with
  ``fault_action: disarm``, or when a speed loop closed on the host -- DJI -- would have to
  hold zero on the feedback in doubt); the error names the motor;
* e-stop: zero at once, disarm, and stay there until an explicit enable.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from gateway.core.counts import SupervisorCounts
from gateway.core.errors import InfeasibleTwistError
from gateway.core.settings import FaultAction, FeedbackRecovery, InfeasiblePolicy
from gateway.core.supervision import (
    Accepted,
    Decision,
    Fault,
    MotorBoard,
    Rejection,
    Source,
    StatusBoard,
    motor_fault_text,
)
from gateway.core.tracking import SteerMonitor, TrackingMonitor
from gateway.core.transitions import Event, next_state
from gateway.core.types import DriveState, ErrorCode, GatewayState, Twist

if TYPE_CHECKING:
    from collections.abc import Sequence

    from gateway.core.kinematics import RobotModel
    from gateway.core.settings import LoopConfig

__all__ = ["AUTO_RETRIES", "AUTO_RETRY_DELAY_S", "AUTO_RETRY_RESET_S", "ZERO", "Accepted",
           "Decision", "Fault", "MotorBoard", "Rejection", "Source", "StatusBoard", "Supervisor"]

ZERO = Twist()
#: Automatic re-enable attempts after a fault, once every motor answers again.
AUTO_RETRIES = 3
#: RUNNING this long without a fault gives back the automatic attempts (s): a fault that comes
#: back soon after every recovery (a wheel pushing against an obstacle) is retried at most
#: AUTO_RETRIES times, then waits for an explicit enable.
AUTO_RETRY_RESET_S = 5.0
#: Delay before the first automatic re-enable; the n-th waits n times as long (s).
AUTO_RETRY_DELAY_S = 0.5
#: Faults that put the feedback itself in doubt.
_FEEDBACK_FAULTS = frozenset({ErrorCode.FEEDBACK_TIMEOUT, ErrorCode.TRACKING_ERROR})


_HOLD = Decision(ZERO, ramp=True, armed=False, cmd_timeout=False)  # DISABLED, STOPPING
_ESTOP = Decision(ZERO, ramp=False, armed=False, cmd_timeout=False)
_ENABLING = Decision(ZERO, ramp=True, armed=True, cmd_timeout=False)
_FAULT_ARMED = Decision(ZERO, ramp=False, armed=True, cmd_timeout=False)
_FAULT_RELEASED = Decision(ZERO, ramp=False, armed=False, cmd_timeout=False)


class Supervisor:
    """The gateway's state machine.

    :param model: the robot, to check twists.
    :param loop: the daemon's settings.
    :param host_speed_loop: some wheel's speed loop is closed on the host (DJI): a fault
        about feedback or tracking then releases the motors, whatever ``fault_action`` says.
    """

    def __init__(self, model: RobotModel, loop: LoopConfig,
                 host_speed_loop: bool = False) -> None:
        self.model = model
        self.cfg = loop
        self.host_speed_loop = host_speed_loop
        #: The gateway's state; changed only by :meth:`_go` (:mod:`gateway.core.transitions`).
        self.state = GatewayState.DISABLED
        self.target = ZERO
        self._last_twist_s: float | None = None
        self._enable_started_s = 0.0
        #: The reason for the current FAULT or ESTOP state, for status reports.
        self.reason = ""
        #: Names of the motors that caused the current fault.
        self.faulted: tuple[str, ...] = ()
        #: The error class of the current fault (twists refused in FAULT carry it).
        self.fault_code = ErrorCode.MOTOR_FAULT
        #: Counters of what happened, by kind.
        self.counts = SupervisorCounts()
        #: Whether the bus can carry frames (``False`` from bus-off until the controller
        #: reports that it is back): automatic recovery waits for it.
        self.bus_ok = True
        #: An e-stop whose zero and disarm the loop has not sent yet (its ``stop_now``).
        self.estop_owed = False
        #: An enable requested, not yet taken by the loop (:meth:`take_enable_request`):
        #: nothing is armed meanwhile (:meth:`decide`).
        self.enable_pending = False
        self._timed_out = self.yielded = False  # (yielded to another commander: yield_motors)
        self._fault_s = 0.0
        self._now_hint = 0.0
        self._auto_attempts = 0
        self._running_since_s = 0.0
        self._running = Decision(ZERO, ramp=True, armed=True, cmd_timeout=False)
        #: The tracking-error check (active while RUNNING).
        self.tracking = TrackingMonitor(loop.tracking)
        #: The steering actuators' angle check (active while RUNNING).
        self.steer_tracking = SteerMonitor(loop.tracking)

    def _go(self, event: Event) -> bool:
        """The one place that changes :attr:`state`, as :mod:`gateway.core.transitions` says:
        whether it changed (``False``: the table ignores ``event`` here; an event it does not
        allow in this state raises :class:`~gateway.core.errors.IllegalTransitionError`)."""
        target = next_state(self.state, event)
        if target is None:
            return False
        self.state = target
        return True

    # ----------------------------------------------------------------- commands

    def twist(self, twist: Twist, now_s: float, steer: Sequence[float | None] | None = None
              ) -> Accepted | Rejection:
        """A twist from a client.

        :param steer: current steering angles, for the feasibility check (and the solve that
            :attr:`Accepted.ik` carries).
        """
        if self.state is not GatewayState.RUNNING:
            self.counts.rejected += 1
            return Rejection(*self._not_running())
        try:
            ik = self.model.ik(twist, steer)
        except InfeasibleTwistError as err:
            self.counts.infeasible += 1
            self._last_twist_s = now_s
            if self.cfg.infeasible_policy is InfeasiblePolicy.PROJECT:
                self.counts.projected += 1
                self.target, self._timed_out = err.nearest, False  # followed: no timeout holds it
                return Accepted(err.nearest, projected=True, error=err)
            self.target = ZERO
            return Rejection(ErrorCode.INFEASIBLE_TWIST, str(err), err)
        self.target, self._last_twist_s, self._timed_out = twist, now_s, False
        return Accepted(twist, ik=ik)

    def stop(self, now_s: float) -> None:
        """Zero twist, drives stay armed."""
        self.target, self._last_twist_s = ZERO, now_s

    def estop(self, reason: str = "e-stop requested") -> None:
        """Zero at once and disarm until an explicit enable."""
        if self.state is not GatewayState.ESTOP:
            self.counts.estops += 1
        self._go(Event.ESTOP)
        self.reason = reason
        self.target, self.enable_pending = ZERO, False  # (an enable not yet taken: off)
        self.estop_owed = True

    def enable(self, now_s: float) -> None:
        """Start (or restart) the enable sequence; also the way out of ESTOP and FAULT."""
        self._auto_attempts = 0
        self._start_enable(now_s, Event.ENABLE)

    def _start_enable(self, now_s: float, event: Event) -> None:
        if not self._go(event):
            return
        self._enable_started_s = now_s
        self.enable_pending, self.yielded = True, False
        self.target, self.reason, self.faulted = ZERO, "", ()

    def disable(self) -> None:
        """Ramp to zero and disarm (an e-stop stays latched: only enable releases it)."""
        self._go(Event.DISABLE)
        self.target, self.enable_pending = ZERO, False  # (an enable not yet taken: off)

    def shutdown(self) -> None:
        """The process is stopping: zero and disarm for good."""
        self._go(Event.SHUTDOWN)
        self.target, self.enable_pending = ZERO, False  # (an enable not yet taken: off)

    def enable_failed(self, why: str) -> str:
        """The drives refused the enable sequence: FAULT with ``why`` as the reason."""
        return self._refused(Event.ENABLE_REFUSED, f"enable refused: {why}")

    def yield_motors(self, why: str) -> str:
        """Another program commands these motors: the enable not yet taken is withheld.  FAULT
        (``bus_error``) with ``why``, the motors released whatever ``fault_action`` says (the
        other keeps them; none of our commands goes out) until an enable is taken."""
        self.enable_pending, self.yielded = False, True
        return self._refused(Event.ENABLE_REFUSED, f"enable withheld: {why}", ErrorCode.BUS_ERROR)

    def command_failed(self, why: str) -> str:
        """A drive could not encode the cycle's command (a speed its controller's field cannot
        hold): FAULT with ``why``; none of the cycle's commands went out."""
        return self._refused(Event.COMMAND_FAILED, f"command not sent: {why}")

    def poll_failed(self, why: str) -> str:
        """A drive's housekeeping step raised (e.g. an axis found calibrating when its
        controller-side protection was set up): FAULT with ``why``; an enable under way is
        refused, as when a drive refuses the enable itself."""
        if self.state is GatewayState.ENABLING:
            return self.enable_failed(why)
        return self._refused(Event.COMMAND_FAILED, f"housekeeping failed: {why}")

    def _refused(self, event: Event, reason: str, code: ErrorCode = ErrorCode.MOTOR_FAULT) -> str:
        self.counts.faults += 1
        self._go(event)
        self.target, self._fault_s = ZERO, self._now_hint
        self.fault_code, self.reason = code, reason
        return reason

    @property
    def cmd_timeout_active(self) -> bool:
        """Whether the command timeout holds the target at zero."""
        return self._timed_out

    def hold_enable(self, now_s: float) -> None:
        """The loop holds the enable pending (listening first): ``enable_timeout_s`` restarts."""
        self._enable_started_s = now_s

    def take_enable_request(self) -> bool:
        """Whether the loop should send the drives' enable frames now (once per enable)."""
        pending, self.enable_pending = self.enable_pending, False
        return pending

    # ----------------------------------------------------------------- per cycle

    def motors(
        self,
        board: MotorBoard,
        now_s: float,
        command_rad_s: Sequence[float] | None = None,
        steer_rad: Sequence[float] | None = None,
    ) -> Fault | None:
        """Read the motors' states; return the fault when one starts.

        :param board: the motors (drive motors first, then steering actuators); their states
            are read while enabling, running or recovering, their feedback while running.
        :param command_rad_s: each drive motor's wheel speed as commanded the cycle before
            (the order of ``board``), for the tracking-error check; ``None`` skips it.
        :param steer_rad: each steering actuator's angle as commanded the cycle before (the
            order of the board's motors after the drive motors), for the steering check.
        """
        self._now_hint = now_s
        state = self.state
        if state is GatewayState.RUNNING:
            return self._running_check(board, now_s, command_rad_s, steer_rad)
        self.tracking.reset()
        self.steer_tracking.reset()
        if state is GatewayState.ENABLING:
            states = board.states(now_s)  # (ENABLED before our enable: another program's)
            if not self.enable_pending and states.count(DriveState.ENABLED) == len(states) > 0:
                self._go(Event.ENABLED)
                self._running_since_s = self._last_twist_s = now_s
                return None
            if not self.enable_pending and (failed := board.enable_failed()):
                return self._fault(board, now_s, failed, "failed its enable sequence")
            if now_s - self._enable_started_s > self.cfg.enable_timeout_s:
                late = [i for i, s in enumerate(states) if s is not DriveState.ENABLED]
                return self._fault(board, now_s, late, "did not enable within "
                                                       f"{self.cfg.enable_timeout_s:g} s")
            return None
        if (
            state is GatewayState.FAULT
            and self.cfg.feedback_recovery is FeedbackRecovery.AUTO
            and (states := board.states(now_s))
            and DriveState.OFFLINE not in states
            and self.bus_ok
            and self._auto_attempts < AUTO_RETRIES
            and now_s - self._fault_s >= AUTO_RETRY_DELAY_S * (self._auto_attempts + 1)
            and not (self.host_speed_loop and self.fault_code is ErrorCode.TRACKING_ERROR)
        ):
            # Every motor answers again: re-run the enable sequence, which clears the errors
            # that the outage latched (an expired watchdog).  A fault that persists, or comes
            # back within AUTO_RETRY_RESET_S of each recovery, is retried AUTO_RETRIES times and
            # then waits for an explicit enable.  So does at once a wheel that did not follow a
            # speed loop closed on the host: that loop ran on the very feedback that failed it
            # (a late DJI stream makes it run away again after every re-enable).
            self._auto_attempts += 1
            self._start_enable(now_s, Event.RETRY)
        return None

    def _running_check(
        self,
        board: MotorBoard,
        now_s: float,
        command_rad_s: Sequence[float] | None,
        steer_rad: Sequence[float] | None,
    ) -> Fault | None:
        if self._auto_attempts and now_s - self._running_since_s >= AUTO_RETRY_RESET_S:
            self._auto_attempts = 0
        if board.troubled(now_s) and (bad := [
                i for i, s in enumerate(board.states(now_s))
                if s is DriveState.FAULT or s is DriveState.OFFLINE]):
            return self._fault(board, now_s, bad, "")
        if command_rad_s is None:
            return None
        n = len(command_rad_s)
        feedback = board.motor_feedback()
        off = self.tracking.check(command_rad_s, feedback if len(feedback) == n
                                  else feedback[:n], now_s)
        if off is not None:
            return self._fault(board, now_s, [off.index], off.describe(),
                               ErrorCode.TRACKING_ERROR)
        if steer_rad is not None:
            turn = self.steer_tracking.check(steer_rad, feedback[n:], now_s)
            if turn is not None:
                return self._fault(board, now_s, [n + turn.index], turn.describe(),
                                   ErrorCode.TRACKING_ERROR)
        return None

    def _fault(self, board: MotorBoard, now_s: float, which: Sequence[int], why: str,
               code: ErrorCode = ErrorCode.MOTOR_FAULT) -> Fault:
        """FAULT for the motors ``which`` of ``board``: ``why``, then what each one says."""
        statuses = board.status(now_s)
        motors = [statuses[i] for i in which]
        self.counts.faults += 1
        self._go(Event.FAULT)
        self.target, self._fault_s = ZERO, self._now_hint
        self.faulted = tuple(s.name for s in motors)
        if not why and any(s.state is DriveState.OFFLINE for s in motors):
            code = ErrorCode.FEEDBACK_TIMEOUT
        self.reason = "; ".join(motor_fault_text(s, why) for s in motors)
        self.fault_code = code
        return Fault(code, self.reason)

    def bus_fault(self, message: str, names: Sequence[str] = ()) -> Fault | None:
        """The bus cannot carry the commands (bus-off, a command that does not go out): a
        fault with ``message`` while the motors are enabled or enabling, else nothing.

        :param names: the motors the message is about, when it names any.
        """
        if not self._go(Event.BUS_FAULT):
            return None
        self.counts.faults += 1
        self.target, self._fault_s, self.faulted = ZERO, self._now_hint, tuple(names)
        self.fault_code, self.reason = ErrorCode.BUS_ERROR, message
        return Fault(ErrorCode.BUS_ERROR, message)

    def decide(self, now_s: float) -> Decision:
        """The command for this cycle."""
        state = self.state
        if state is GatewayState.ESTOP:
            return _ESTOP
        if state is GatewayState.DISABLED or state is GatewayState.STOPPING:
            return _HOLD
        if state is GatewayState.FAULT:
            # Zero at once: with a motor gone, no wheel should keep driving on its own.  A speed
            # loop closed on the host cannot hold zero on feedback that is missing, late or not
            # followed (late DJI feedback makes it run away): release those motors.
            release = self.cfg.fault_action is FaultAction.DISARM or self.yielded or (
                self.host_speed_loop and self.fault_code in _FEEDBACK_FAULTS)
            return _FAULT_RELEASED if release else _FAULT_ARMED
        if state is GatewayState.ENABLING:
            return _HOLD if self.enable_pending else _ENABLING
        timeout = self.cfg.cmd_timeout_s
        if (
            timeout > 0.0
            and self.target != ZERO
            and self._last_twist_s is not None
            and now_s - self._last_twist_s > timeout
        ):
            self.target = ZERO
            if not self._timed_out:
                self.counts.cmd_timeouts += 1
            self._timed_out = True
        last = self._running
        if last.twist is not self.target or last.cmd_timeout is not self._timed_out:
            # A new decision only when the target or the timeout changed (it is immutable).
            last = self._running = Decision(self.target, ramp=True, armed=True,
                                            cmd_timeout=self._timed_out)
        return last

    def _not_running(self) -> tuple[ErrorCode, str]:
        if self.state is GatewayState.ESTOP:
            return ErrorCode.ESTOP, f"e-stop is latched ({self.reason}); send enable first"
        if self.state is GatewayState.FAULT:
            return self.fault_code, f"gateway is in FAULT: {self.reason}"
        if self.state is GatewayState.ENABLING:
            return ErrorCode.NOT_ENABLED, "drives are still enabling"
        return ErrorCode.NOT_ENABLED, f"gateway is {self.state.name}; send enable first"
