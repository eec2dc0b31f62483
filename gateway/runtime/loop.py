"""One control cycle of the gateway: receive, decide, solve, send one burst, integrate.

:class:`Gateway` owns the drivers, the odometry and the supervisor, and parts of its own: the
bus (:class:`~gateway.bus.edge.BusEdge`: send, receive, tally, reopen), the CAN command input
(:class:`~gateway.runtime.can_twist.CanTwists`), the reports
(:class:`~gateway.runtime.publish.Publisher`) and the watch for a second commander
(:mod:`gateway.runtime.commanders`).  :meth:`Gateway.cycle` is deterministic given the time
it is called with, so tests run it on simulated time; :mod:`gateway.runtime.daemon` calls it
from the real-time loop.  Each cycle:

1. drain the bus: CAN twists to the supervisor, feedback to the drivers (timestamped on
   receipt), our own frames sent by another to the watch;
2. the supervisor turns the motors' states and the newest valid twist into a target (an
   enable is taken once the watch has listened for another commander and heard none);
3. inverse kinematics and limits (one scale factor, reported) give every wheel's speed (one
   solve per new target: the supervisor's feasibility check of an accepted twist is it);
4. every wheel's frame (and every steering actuator's) is built, then all go out as one
   burst, so no two wheels act on commands from different cycles;
5. odometry integrates the encoder positions exactly (SE(2)) once every driven wheel has a
   new one (:class:`~gateway.core.odom_feed.OdomFeed`'s whole rounds), with the measured
   steering angles; odometry and status go out at their rates, and errors at most one
   ``WG_Error`` a cycle (:mod:`gateway.runtime.publish`), after the burst.
"""

from __future__ import annotations

import logging
import time
from typing import TYPE_CHECKING

from gateway.bus.edge import LOG_EVERY_S, BusEdge, bus_options
from gateway.bus.health import LogThrottle, bus_off_restart, since_last, unsent_why
from gateway.core.control import ZERO, Accepted, Rejection, Source, Supervisor
from gateway.core.errors import EncodeError, GatewayError, KinematicsError
from gateway.core.kinematics import apply_limits
from gateway.core.kinematics.odometry import Odometry
from gateway.core.odom_feed import OdomFeed
from gateway.core.status import BusErrorState
from gateway.core.types import ErrorCode, Frame, GatewayState, Twist
from gateway.drive.driveset import DriveSet
from gateway.drive.ownership import gateway_filters
from gateway.runtime.can_twist import CanTwists
from gateway.runtime.commanders import Commanders, own_frames
from gateway.runtime.counts import LoopCounts
from gateway.runtime.publish import Publisher
from gateway.runtime.rejections import RejectionLog
from gateway.runtime.timing import LoopTimer
from gateway.wire.can import NO_TWIST_COUNTER, StatusReport, WgCodec

if TYPE_CHECKING:
    import can

    from gateway.core.kinematics import IkResult, LimitReport
    from gateway.core.settings import GatewayConfig
    from gateway.core.status import LastError
    from gateway.drive.labels import FrameLabeler

log = logging.getLogger(__name__)

#: Every wheel's steering angle (``None``: not steered), as in ``IkResult.steer_rad``.
Angles = tuple[float | None, ...]


class Gateway:
    """The gateway's state and its cycle.

    :param config: the validated configuration.
    :param bus: an open python-can bus; opened from the config when omitted.
    :param record: a python-can writer that gets every frame sent and received.
    :param timer: the loop's timing statistics (the daemon's scheduler keeps them).
    :param stamp_with_cycle_time: stamp received frames with the time ``cycle`` is called with
        (simulated time in tests) instead of their own receive time.
    """

    def __init__(
        self,
        config: GatewayConfig,
        bus: can.BusABC | None = None,
        record: can.Listener | None = None,
        timer: LoopTimer | None = None,
        stamp_with_cycle_time: bool = False,
    ) -> None:
        self.config = config
        self.model = config.model
        self.drives = DriveSet(config)
        self.supervisor = Supervisor(self.model, config.loop, self.drives.host_speed_loop)
        self.supervisor.tracking.dead_bands = self.drives.uncontrolled_bands()
        self.odometry = Odometry(self.model)
        self._driven = tuple(i for i, m in enumerate(config.motors) if m is not None)
        self.odom_feed = OdomFeed(self._driven, config.limits.max_wheel_rad_s,
                                  self.drives.liveness_s, whole_rounds=True)
        self.wg = WgCodec(config.loop.can_ids)
        self.timer = timer if timer is not None else LoopTimer(config.loop.rate_hz)
        self.period_s = 1.0 / config.loop.rate_hz
        #: Event counters for status reports (the bus's: ``edge.counts``).
        self.counts = LoopCounts()
        own = own_frames(config, self.drives)  # (heard only when another sends them)
        #: The identifiers the gateway consumes (its drivers' claims and its twist input).
        self.receive_filters = gateway_filters(config, self.drives, own)
        #: The bus: sending, receiving, tallying, reopening.
        self.edge = BusEdge(
            config, bus, self.period_s,
            bus_options(config.bus.interface, [f.as_python_can() for f in self.receive_filters]),
            record, stamp_with_cycle_time,
        )
        self._labeler: FrameLabeler | None = None
        self.prev: IkResult = self.model.ik(Twist())
        # The wheel each motor's name stands for (a steering actuator: its first wheel), for
        # the wheel field of WG_Error and the faulted-motor mask of WG_Status.
        self._wheel_of = {w.name: i for i, w in enumerate(self.model.wheels)}
        for actuator, wheels in zip(config.steering, self.drives.steered_by, strict=True):
            self._wheel_of[actuator.wheel] = wheels[0]
        # Every wheel driven (most robots): the commands are the IK's speeds as they are.
        self._all_driven = len(self._driven) == len(config.motors)
        self._steering = bool(config.steering)
        # The last inverse-kinematics solve (see _solve), and the steering angles it holds for.
        self._ik_key: tuple[Twist, Angles, Angles] | None = None
        self._ik_result: IkResult = self.prev
        self._ik_static = not any(w.steered for w in self.model.wheels)
        self.limit_report: LimitReport | None = None
        #: Whether the drives are armed by this gateway (its last decision armed them).
        self.armed = False
        self._prev_limited = False  # (prev came out of the limits: no e-stop)
        self._last_cycle_s: float | None = None
        #: ``time.perf_counter()`` when the last cycle's burst of wheel frames went (before
        #: odometry and publishing): the end of the daemon's twist-to-frames latency.
        self.burst_sent_s = 0.0
        #: The longest time between two cycles' bursts (s): a loop stalled for seconds shows
        #: here as seconds, whatever the deadline statistics make of the skipped deadlines.
        self.burst_gap_max_s = 0.0
        #: Odometry, status and errors, on CAN and in the outbox.
        self.publisher = Publisher(config.loop, self.wg, self.supervisor, self.odometry,
                                   self.timer, self._wheel_of)
        #: News for socket subscribers (:mod:`gateway.core.events`): emptied by the daemon
        #: every cycle.
        self.outbox = self.publisher.outbox
        #: WG_Twist_Cmd frames from the bus.
        self.can_twists = CanTwists(self.wg, config.loop, self.supervisor, self.counts,
                                    self.twist, self.report_error)
        #: Our own frames from another sender (:mod:`gateway.runtime.commanders`).
        self.commanders = Commanders(config, own, self.supervisor, self.report_error)
        self._route = self.commanders.route(self.drives.takers)
        #: The log lines of the frames the drivers rejected.
        self.rejections = RejectionLog(self.drives.groups)
        # The log throttles of projected and refused twists (by source and kind), of jumps.
        self._logs: dict[str, LogThrottle] = {}

    # ----------------------------------------------------------------- inputs

    def twist(self, twist: Twist, now_s: float, source: Source) -> Accepted | Rejection:
        """A twist from any source; infeasible or refused twists are counted and logged (one
        line per :data:`~gateway.bus.edge.LOG_EVERY_S` and kind, with the count).

        The supervisor's feasibility check solves the inverse kinematics from the current
        steering angles, the very solve the next cycle needs: kept for it (:meth:`_solve`).
        """
        steer = self.prev.steer_rad
        result = self.supervisor.twist(twist, now_s, steer)
        if isinstance(result, Accepted) and result.ik is not None:
            self._remember(result.twist, steer, result.ik)
        if isinstance(result, Accepted) and result.projected and result.error is not None:
            self._log(logging.WARNING, f"{source.value} twist projected", str(result.error), now_s)
        elif isinstance(result, Rejection):
            self._log(logging.INFO, f"{source.value} twist refused", result.message, now_s)
        return result

    def _log(self, level: int, key: str, text: str, now_s: float, what: str = "twists") -> None:
        """Log ``key: text``, throttled per key (a projected or refused twist, by source; a
        position jump): a client that pipelines them costs the loop a line per 5 s, not one
        per request."""
        throttle = self._logs.get(key)
        if throttle is None:
            throttle = self._logs[key] = LogThrottle(LOG_EVERY_S)
        count = throttle.note(now_s)
        if count is not None:
            log.log(level, "%s: %s%s", key, text, since_last(count, f"such {what}"))

    def report_error(self, code: ErrorCode, message: str, rejection: Rejection | None = None,
                     twist_counter: int = NO_TWIST_COUNTER, wheel: str | None = None) -> None:
        """Report an error: in the outbox for socket clients at once, and on CAN as a
        ``WG_Error`` with the cycle's reports -- after its burst of commands, untracked; the
        next cycle's for an error reported between cycles (a request's) -- at most one a cycle
        (:meth:`~gateway.runtime.publish.Publisher.error` says which), the others counted
        (``errors_not_sent``).  Never sends: a request refused between cycles costs the bus
        nothing until the cycle, whatever the number of requests.

        :param wheel: the wheel the error is about, when it is not the rejection's.
        """
        self.counts.errors_reported += 1
        if self.publisher.error(code, message, rejection, twist_counter, wheel):
            self.counts.errors_not_sent += 1

    # ----------------------------------------------------------------- the cycle

    def cycle(self, now_s: float) -> None:
        """One control cycle at time ``now_s`` (monotonic seconds)."""
        self.counts.cycles += 1
        out: list[Frame] = []
        edge = self.edge
        frames = edge.receive(now_s)
        if frames:
            ids = self.wg.ids
            twist_id = ids.twist if self.config.loop.can_input else -1
            twist_ext = ids.extended
            take, other = self._route.get, self.drives.on_frame
            for frame in frames:
                ident, ext = frame.arbitration_id, frame.is_extended_id
                if ident == twist_id and ext == twist_ext:
                    self.can_twists.handle(frame, now_s)
                elif (taker := take((ident, ext))) is not None:
                    taker(frame)
                else:
                    other(frame)
        sup = self.supervisor
        if sup.estop_owed:
            self.stop_now(now_s)
        if edge.starved is not None or edge.bus_state_change is not None:
            self._bus_trouble()
        elif (edge.bus_errors.state is BusErrorState.BUS_OFF
              and sup.state in (GatewayState.ENABLING, GatewayState.RUNNING)):
            self._bus_trouble(BusErrorState.BUS_OFF)
        prev = self.prev
        speeds = prev.wheel_rad_s
        if not self._all_driven:
            speeds = tuple(speeds[i] for i in self._driven)
        steer = self.drives.steer_setpoints(prev.steer_rad) if self._steering else None
        fault = sup.motors(self.drives, now_s, speeds, steer)
        if fault is not None:
            log.error("fault: %s", fault.message)
            self.report_error(fault.code, fault.message,
                              wheel=sup.faulted[0] if sup.faulted else None)
        if sup.enable_pending and self.commanders.may_enable(now_s) and sup.take_enable_request():
            try:
                out.extend(self.drives.enable(now_s))
            except GatewayError as err:
                # A drive refuses to be enabled now (e.g. an axis calibrating): a fault that
                # names it, never an exception out of the cycle.
                message = sup.enable_failed(str(err))
                log.error("fault: %s", message)
                self.report_error(ErrorCode.MOTOR_FAULT, message)
        decision = sup.decide(now_s)
        # The limits' interval: at most two periods.  Through a stalled cycle the controllers
        # held the last command, so the wheels are where it left them: the next may not step
        # them by the acceleration of the whole stall at once.
        last, self._last_cycle_s = self._last_cycle_s, now_s
        dt = self.period_s if last is None else min(now_s - last, 2.0 * self.period_s)
        result = self._solve(decision.twist)
        if not decision.ramp:
            self._prev_limited = False
        elif not (result is prev and self._prev_limited):
            # (Skipped for the very command the limits passed last cycle: the same report.)
            result, self.limit_report = apply_limits(
                self.model, result, self.config.limits, prev, dt
            )
            self._prev_limited = True
        if decision.armed:
            self.armed = True
            try:
                out.extend(self.drives.command(result.wheel_rad_s, now_s, result.steer_rad))
            except EncodeError as err:  # e.g. a max_rpm beyond the controller's speed field
                message = sup.command_failed(str(err))
                log.error("fault: %s", message)
                self.report_error(ErrorCode.MOTOR_FAULT, message)
        elif self.armed:
            self.armed = False
            out.extend(self.drives.disable(now_s))
            # Disarmed, the wheels coast down on their own: the next enable ramps from zero,
            # not on down from the speed before the disable (as after an e-stop, stop_now).
            result, self._prev_limited = self._solve(ZERO), False
        try:  # (housekeeping: not while the motors are another's, commanders.quiet)
            if self.armed or not self.commanders.quiet(now_s):
                out.extend(self.drives.poll(now_s))
        except GatewayError as err:  # a step a drive refuses now: a fault, never an exit
            message = sup.poll_failed(str(err))
            log.error("fault: %s", message)
            self.report_error(ErrorCode.MOTOR_FAULT, message)
        self.prev = result
        edge.send(out, now_s)
        sent = time.perf_counter()
        if self.burst_sent_s and sent - self.burst_sent_s > self.burst_gap_max_s:
            self.burst_gap_max_s = sent - self.burst_sent_s
        self.burst_sent_s = sent
        self._integrate()
        if now_s >= self.publisher.next_due_s:  # an error waiting, or odometry or status due
            self.rejections.check(now_s)
            edge.send(self.publisher.publish(now_s, self.limit_report, edge.errors_recent),
                      now_s, tracked=False)

    def stop_now(self, now_s: float) -> None:
        """Act on an e-stop not acted on yet (``Supervisor.estop_owed``): the zero and disarm
        go out now, and the limits start again from zero.  Called where the e-stop is taken
        (a socket or bridge request) and by the cycle after its frames (CAN): an enable
        handled after it, before the cycle's decision, would otherwise make an ENABLING that
        never disarmed, whose ramp resumed the speed of before the e-stop."""
        sup = self.supervisor
        if not sup.estop_owed:
            return
        sup.estop_owed = False
        self.prev, self._prev_limited = self._solve(ZERO), False
        if self.armed:
            self.armed = False
            self.edge.send(self.drives.disable(now_s), now_s)

    def _solve(self, twist: Twist) -> IkResult:
        """Inverse kinematics of the target (zero if infeasible), remembered while the target
        and the steering angles it starts from are the same objects: the supervisor keeps
        its target object until it changes, and the solve is a pure function of both (the
        supervisor's own solve of an accepted twist is remembered by :meth:`twist`)."""
        steer = self.prev.steer_rad
        key = self._ik_key
        if key is not None and key[0] is twist and (
                self._ik_static or key[1] is steer or key[2] is steer):
            return self._ik_result
        return self._remember(twist, steer,
                              self.model.try_ik(twist, steer) or self.model.ik(Twist()))

    def _remember(self, twist: Twist, steer: Angles, result: IkResult) -> IkResult:
        """Keep ``result``, the solve of ``twist`` from ``steer``, for :meth:`_solve`."""
        # Steering that starts where this solve ends gives this solve again: keyed by the
        # result's own angles too, the memo holds once the wheels have turned (they become
        # the next cycle's starting angles when the limits pass the result unchanged).
        self._ik_key = (twist, steer, result.steer_rad if result.steer_rad == steer else steer)
        self._ik_result = result
        return result

    def _integrate(self) -> None:
        feed = self.odom_feed
        jumps = feed.jumps
        got = feed.sample(self.drives.feedback_by_wheel())
        if feed.jumps != jumps:
            self.counts.position_jumps += feed.jumps - jumps
            self._log(logging.WARNING, "odometry", feed.last_jump_text(self.model.names),
                      feed.stamp_s, "position jumps")
        if got is None:
            return
        try:
            self.odometry.take(got[1], got[0], self.drives.measured_steer(self.prev.steer_rad))
        except KinematicsError as err:
            self.counts.odometry_errors += 1
            log.warning("odometry update skipped: %s", err)

    def _bus_trouble(self, change: BusErrorState | None = None) -> None:
        """Act on what the bus reported: bus-off, or a command that does not go out, is a
        fault that names it; leaving bus-off lets the recovery go on."""
        edge = self.edge
        if change is None:
            change, edge.bus_state_change = edge.bus_state_change, None
        starved, edge.starved = edge.starved, None
        sup, bus = self.supervisor, self.config.bus
        messages: list[tuple[str, tuple[str, ...]]] = []
        if change is BusErrorState.BUS_OFF:
            sup.bus_ok = False
            messages.append((
                f"CAN bus-off on {bus.interface}:{bus.channel} ({edge.bus_errors.last}): the "
                f"CAN controller stopped sending after too many transmit errors; check the "
                f"wiring, termination and bitrate of every node"
                f"{bus_off_restart(bus.interface, bus.channel)}", ()))
        elif change is not None:
            sup.bus_ok = True
        if starved is not None:
            can_id, extended, n = starved
            if self._labeler is None:
                from gateway.drive.labels import FrameLabeler  # noqa: PLC0415 - rare path

                self._labeler = FrameLabeler(self.config)
            label = self._labeler.label_id(can_id, extended)
            why = unsent_why(bus.interface, bus.channel, edge.send_gone)
            messages.append((
                f"the frame {label.text} (ID 0x{can_id:X}) has not gone out for {n} cycles: "
                f"{why}", tuple(w for w in label.wheels if w in self._wheel_of)))
        for message, wheels in messages:
            fault = sup.bus_fault(message, wheels)
            if fault is not None:
                log.error("fault: %s", message)
                self.report_error(fault.code, message, wheel=wheels[0] if wheels else None)

    # ----------------------------------------------------------------- reports

    def status_report(self) -> StatusReport:
        """The WG_Status content (each call advances its counter)."""
        return self.publisher.status_report(self.limit_report, self.edge.errors_recent)

    @property
    def last_error(self) -> LastError | None:
        """The last error reported."""
        return self.publisher.last_error

    @property
    def state(self) -> GatewayState:
        """The supervisor's state."""
        return self.supervisor.state

    def close(self) -> None:
        """Close the bus if this gateway opened it (safe to call twice)."""
        self.edge.close()
