"""One control cycle of the gateway: receive, decide, solve, send one burst, integrate.

:class:`Gateway` owns the bus, the drivers, the odometry and the supervisor.  Its
:meth:`Gateway.cycle` is deterministic given the time it is called with, so tests run it on
simulated time; :mod:`gateway.runtime.daemon` calls it from the real-time loop.

Each cycle:

1. drain the bus: CAN twist frames go to the supervisor, feedback frames to the drivers
   (timestamped on receipt);
2. the supervisor turns the motors' states and the newest valid twist into a target;
3. inverse kinematics and limits (one scale factor, reported) give every wheel's speed;
4. every wheel's frame (and every steering actuator's) is built, then all go out as one
   burst, so no two wheels act on commands from different cycles;
5. odometry integrates the encoder positions exactly (SE(2)), with the steering angles the
   actuators measure (the commanded ones for wheels steered outside the gateway); odometry and
   status go out on CAN and to socket subscribers at their rates.
"""

from __future__ import annotations

import collections
import logging
import time
from typing import TYPE_CHECKING

from gateway.bus.edge import BusEdge, bus_options
from gateway.bus.health import BusErrorState
from gateway.core.control import Accepted, Rejection, Source, Supervisor
from gateway.core.errors import DecodeError, GatewayError, KinematicsError
from gateway.core.kinematics import Odometry, apply_limits
from gateway.core.types import ConstraintCode, ErrorCode, Frame, GatewayState, Twist
from gateway.drive.driveset import DriveSet
from gateway.drive.filters import gateway_filters
from gateway.runtime.timing import LoopTimer
from gateway.wire.can import (
    NO_TWIST_COUNTER,
    NO_WHEEL,
    CounterKind,
    CounterTracker,
    ErrorReport,
    StatusFlags,
    StatusReport,
    TwistFlags,
    WgCodec,
)

if TYPE_CHECKING:
    import can

    from gateway.core.kinematics import IkResult, LimitReport
    from gateway.core.settings import GatewayConfig
    from gateway.drive.labels import FrameLabeler

log = logging.getLogger(__name__)



class Gateway(BusEdge):
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
        self.wg = WgCodec(config.loop.can_ids)
        self.counter = CounterTracker()
        self._last_can_twist_s: float | None = None
        self.timer = timer if timer is not None else LoopTimer(config.loop.rate_hz)
        self.record = record
        self.stamp_with_cycle_time = stamp_with_cycle_time
        self.period_s = 1.0 / config.loop.rate_hz
        self._bus_failures = 0
        self._since_reopen = 0
        #: Event counters for status reports.
        self.counts = {
            "cycles": 0, "frames_sent": 0, "frames_received": 0, "send_failures": 0,
            "bus_reopens": 0, "can_twists": 0, "can_duplicates": 0, "can_lost": 0,
            "bad_can_twists": 0, "errors_reported": 0, "odometry_errors": 0,
        }
        #: The identifiers the gateway consumes (``None``: a driver does not say).
        self.receive_filters = gateway_filters(config, self.drives)
        self._setup_edge(bus_options(
            config.bus.interface,
            None if self.receive_filters is None
            else [f.as_python_can() for f in self.receive_filters],
        ))
        self._own_bus = bus is None
        self.bus = bus if bus is not None else self._open()
        self._labeler: FrameLabeler | None = None
        self.prev: IkResult = self.model.ik(Twist())
        self._driven = tuple(i for i, m in enumerate(config.motors) if m is not None)
        # The wheel each motor's name stands for (a steering actuator: its first wheel), for
        # the wheel field of WG_Error and the faulted-motor mask of WG_Status.
        self._wheel_of = {w.name: i for i, w in enumerate(self.model.wheels)}
        for actuator, wheels in zip(config.steering, self.drives.steered_by, strict=True):
            self._wheel_of[actuator.wheel] = wheels[0]
        # Every wheel driven (most robots): the commands are the IK's speeds as they are.
        self._all_driven = len(self._driven) == len(config.motors)
        self._steering = bool(config.steering)
        # The last inverse-kinematics solve of the cycle (see _solve).
        self._ik_key: tuple[Twist, tuple[float | None, ...]] | None = None
        self._ik_result: IkResult = self.prev
        self._ik_static = not any(w.steered for w in self.model.wheels)
        self.limit_report: LimitReport | None = None
        self._prev_limited = False  # prev came out of the limits (not an e-stop's jump)
        self._armed = False
        self._last_cycle_s: float | None = None
        #: ``time.perf_counter()`` when the last cycle's burst of wheel frames was sent (before
        #: odometry and publishing): where the daemon's twist-to-frames latency ends.
        self.burst_sent_s = 0.0
        #: The longest time between two cycles' bursts (s): a loop stalled for seconds shows
        #: here as seconds, whatever the deadline statistics make of the skipped deadlines.
        self.burst_gap_max_s = 0.0
        self._next_odom_s = 0.0
        self._next_status_s = 0.0
        self._odom_stamp = -1.0
        self._status_counter = 0
        self._error_count = 0
        #: Frames seen per (arbitration ID, extended, transmitted), for monitors.
        self.id_counts: collections.Counter[tuple[int, bool, bool]] = collections.Counter()
        #: Nominal bits of every frame sent and received (bus load = rate / bitrate).
        self.bits = 0
        #: (client, source) pairs that want to hear about errors: filled by the daemon.
        self.outbox: list[tuple[str, dict[str, object]]] = []
        self.last_error: dict[str, object] | None = None

    # ----------------------------------------------------------------- inputs

    def handle_can_twist(self, frame: Frame, now_s: float, out: list[Frame]) -> None:
        """A WG_Twist_Cmd from the bus (counter checked; errors answered with WG_Error)."""
        try:
            cmd = self.wg.decode_twist(frame)
        except DecodeError as err:
            self.counts["bad_can_twists"] += 1
            self.report_error(ErrorCode.BAD_COMMAND, str(err), out)
            return
        if cmd is None:
            return
        # A sender silent for longer than the command timeout is gone: its next frame starts
        # a new sequence, even if it repeats the counter it stopped at (a restarted sender).
        last, self._last_can_twist_s = self._last_can_twist_s, now_s
        timeout = self.config.loop.cmd_timeout_s
        if last is not None and timeout > 0.0 and now_s - last > timeout:
            self.counter.reset()
        kind, lost = self.counter.feed(cmd.counter)
        self.counts["can_lost"] += lost
        duplicate = kind is CounterKind.DUPLICATE
        self.counts["can_duplicates" if duplicate else "can_twists"] += 1
        if cmd.flags & TwistFlags.ESTOP:
            # Taken even from a repeated frame: an e-stop only ever stops.
            self.supervisor.estop("e-stop requested on CAN")
            return
        if duplicate:
            return
        if cmd.flags & TwistFlags.ENABLE:
            if (self.supervisor.state is GatewayState.ESTOP
                    and self.config.loop.estop_release == "socket"):
                self.report_error(
                    ErrorCode.ESTOP, "an e-stop is released only by an enable on the control "
                    "socket (gateway.estop_release: socket); the CAN ENABLE flag was ignored",
                    out, twist_counter=cmd.counter)
                return
            self.supervisor.enable(now_s)
            return
        if cmd.flags & TwistFlags.STOP:
            self.supervisor.stop(now_s)
            return
        result = self.twist(cmd.twist, now_s, Source.CAN)
        if isinstance(result, Rejection):
            self.report_error(result.code, result.message, out, result, cmd.counter)

    def twist(self, twist: Twist, now_s: float, source: Source) -> Accepted | Rejection:
        """A twist from any source; infeasible or refused twists are counted and logged."""
        result = self.supervisor.twist(twist, now_s, self.prev.steer_rad)
        if isinstance(result, Accepted) and result.projected and result.error is not None:
            log.warning("%s twist projected: %s", source.value, result.error)
        elif isinstance(result, Rejection):
            log.info("%s twist refused: %s", source.value, result.message)
        return result

    def report_error(
        self,
        code: ErrorCode,
        message: str,
        out: list[Frame],
        rejection: Rejection | None = None,
        twist_counter: int = NO_TWIST_COUNTER,
        wheel: str | None = None,
    ) -> None:
        """Put an error on CAN (WG_Error) and in the outbox for socket clients.

        :param wheel: the wheel the error is about, when it is not the rejection's.
        """
        self._error_count += 1
        self.counts["errors_reported"] += 1
        err = rejection.error if rejection is not None else None
        if err is not None:
            wheel = err.wheel
        out.append(self.wg.encode_error(ErrorReport(
            code=code,
            wheel=NO_WHEEL if wheel is None else self._wheel_of[wheel],
            constraint=ConstraintCode.from_name(err.constraint) if err else ConstraintCode.NONE,
            twist_counter=twist_counter,
            residual_m_s=err.residual_m_s if err else 0.0,
            count=self._error_count,
        )))
        self.last_error = {"code": code.name.lower(), "message": message}
        self.outbox.append(("error", dict(self.last_error)))

    # ----------------------------------------------------------------- the cycle

    def cycle(self, now_s: float) -> None:
        """One control cycle at time ``now_s`` (monotonic seconds)."""
        self.counts["cycles"] += 1
        out: list[Frame] = []
        frames = self.receive(now_s)
        if frames:
            drives = self.drives
            ids = self.wg.ids
            twist_id = ids.twist if self.config.loop.can_input else -1
            twist_ext = ids.extended
            for frame in frames:
                if frame.arbitration_id == twist_id and frame.is_extended_id == twist_ext:
                    self.handle_can_twist(frame, now_s, out)
                else:
                    drives.on_frame(frame)
        sup = self.supervisor
        if self.starved is not None or self.bus_state_change is not None:
            self._bus_trouble(out)
        elif (self.bus_errors.state is BusErrorState.BUS_OFF
              and sup.state in (GatewayState.ENABLING, GatewayState.RUNNING)):
            self._bus_trouble(out, BusErrorState.BUS_OFF)
        speeds = self.prev.wheel_rad_s
        if not self._all_driven:
            speeds = tuple(speeds[i] for i in self._driven)
        steer = self.drives.steer_setpoints(self.prev.steer_rad) if self._steering else None
        fault = sup.motors(self.drives.status(now_s), now_s, speeds, steer)
        if fault is not None:
            log.error("fault: %s", fault.message)
            self.report_error(fault.code, fault.message, out,
                              wheel=sup.faulted[0] if sup.faulted else None)
        if sup.take_enable_request():
            try:
                out.extend(self.drives.enable(now_s))
            except GatewayError as err:
                # A drive refuses to be enabled now (e.g. an axis calibrating): a fault that
                # names it, never an exception out of the cycle.
                message = sup.enable_failed(str(err))
                log.error("fault: %s", message)
                self.report_error(ErrorCode.MOTOR_FAULT, message, out)
        decision = sup.decide(now_s)
        dt = now_s - self._last_cycle_s if self._last_cycle_s is not None else self.period_s
        self._last_cycle_s = now_s
        result = self._solve(decision.twist)
        if not decision.ramp:
            self._prev_limited = False
        elif not (result is self.prev and self._prev_limited):
            # (Skipped when the solve is the very command the limits passed last cycle -- any
            # change would have been a new object: no change means no acceleration and no
            # steering, the same report.)
            result, self.limit_report = apply_limits(
                self.model, result, self.config.limits, self.prev, dt
            )
            self._prev_limited = True
        if decision.armed:
            self._armed = True
            out.extend(self.drives.command(result.wheel_rad_s, now_s, result.steer_rad))
        elif self._armed:
            self._armed = False
            out.extend(self.drives.disable(now_s))
        out.extend(self.drives.poll(now_s))
        self.prev = result
        self.send(out, now_s)
        sent = time.perf_counter()
        if self.burst_sent_s and sent - self.burst_sent_s > self.burst_gap_max_s:
            self.burst_gap_max_s = sent - self.burst_sent_s
        self.burst_sent_s = sent
        self._integrate()
        self._publish(now_s)

    def _solve(self, twist: Twist) -> IkResult:
        """Inverse kinematics of the target (zero if infeasible), remembered while the target
        and the steering angles it starts from are the same objects: the supervisor keeps
        its target object until it changes, and the solve is a pure function of both."""
        steer = self.prev.steer_rad
        key = self._ik_key
        if key is not None and key[0] is twist and (self._ik_static or key[1] is steer):
            return self._ik_result
        result = self.model.try_ik(twist, steer) or self.model.ik(Twist())
        # Steering that starts where this solve ends gives this solve again: keyed by the
        # result's own angles, the memo holds once the wheels have turned (they become the
        # next cycle's starting angles when the limits pass the result unchanged).
        self._ik_key = (twist, result.steer_rad if result.steer_rad == steer else steer)
        self._ik_result = result
        return result

    def _integrate(self) -> None:
        feedback = self.drives.feedback_by_wheel()
        newest = self._odom_stamp
        for fb in feedback:
            if fb is not None and fb.timestamp_s > newest:
                newest = fb.timestamp_s
        if newest <= self._odom_stamp:
            return
        self._odom_stamp = newest
        positions = [None if fb is None else fb.position_rad for fb in feedback]
        for i in self._driven:
            if positions[i] is None:
                return  # integrate once every driven wheel has reported
        try:
            self.odometry.update(positions, newest, self.drives.measured_steer(self.prev.steer_rad))
        except KinematicsError as err:
            self.counts["odometry_errors"] += 1
            log.warning("odometry update skipped: %s", err)

    def _publish(self, now_s: float) -> None:
        loop = self.config.loop
        frames: list[Frame] = []
        if now_s >= self._next_odom_s:
            self._next_odom_s = now_s + 1.0 / loop.odom_rate_hz
            st = self.odometry.state
            frames.append(self.wg.encode_pose(st.pose))
            frames.append(self.wg.encode_velocity(st.twist, st.slip_m_s))
            self.outbox.append(("odometry", self.odometry_dict()))
        if now_s >= self._next_status_s:
            self._next_status_s = now_s + 1.0 / loop.status_rate_hz
            frames.append(self.wg.encode_status(self.status_report()))
            self.outbox.append(("status", {"state": self.supervisor.state,
                                           "reason": self.supervisor.reason}))
        self.send(frames, now_s, tracked=False)

    def _bus_trouble(self, out: list[Frame], change: BusErrorState | None = None) -> None:
        """Act on what the bus reported: bus-off, or a command that does not go out, is a
        fault that names it; leaving bus-off lets the recovery go on."""
        if change is None:
            change, self.bus_state_change = self.bus_state_change, None
        starved, self.starved = self.starved, None
        sup = self.supervisor
        bus = self.config.bus
        messages: list[tuple[str, tuple[str, ...]]] = []
        if change is BusErrorState.BUS_OFF:
            sup.bus_ok = False
            messages.append((
                f"CAN bus-off on {bus.interface}:{bus.channel} ({self.bus_errors.last}): the "
                f"CAN controller stopped sending after too many transmit errors; check the "
                f"wiring, termination and bitrate of every node (the kernel restarts it with "
                f"'ip link set {bus.channel} type can restart-ms 100')", ()))
        elif change is not None:
            sup.bus_ok = True
        if starved is not None:
            can_id, extended, n = starved
            if self._labeler is None:
                from gateway.drive.labels import FrameLabeler  # noqa: PLC0415 - rare path

                self._labeler = FrameLabeler(self.config)
            label = self._labeler.label_id(can_id, extended)
            messages.append((
                f"the frame {label.text} (ID 0x{can_id:X}) has not gone out for {n} cycles: the "
                f"CAN transmit queue stays full (the bus is slower than the commands: check the "
                f"bitrate, the interface's txqueuelen and the bus load)",
                tuple(w for w in label.wheels if w in self._wheel_of)))
        for message, wheels in messages:
            fault = sup.bus_fault(message, wheels)
            if fault is not None:
                log.error("fault: %s", message)
                self.report_error(fault.code, message, out,
                                  wheel=wheels[0] if wheels else None)

    # ----------------------------------------------------------------- reports

    def status_report(self) -> StatusReport:
        """The WG_Status content."""
        sup = self.supervisor
        mask = 0
        for name in sup.faulted:
            mask |= 1 << min(self._wheel_of[name], 7)  # wheels 8 and up share bit 7
        flags = StatusFlags(0)
        if sup.cmd_timeout_active:
            flags |= StatusFlags.CMD_TIMEOUT_ACTIVE
        if self.limit_report is not None and self.limit_report.speed_scale < 1.0:
            flags |= StatusFlags.SPEED_LIMITED
        if sup.counts["projected"]:
            flags |= StatusFlags.PROJECTED
        if self._bus_failures or self.bus_errors.state is not BusErrorState.ACTIVE:
            flags |= StatusFlags.BUS_ERRORS_RECENT
        self._status_counter = (self._status_counter + 1) & 0xFF
        return StatusReport(
            state=sup.state,
            faulted_motors=mask,
            counter=self._status_counter,
            flags=flags,
            missed_cycles=self.timer.missed,
            infeasible_count=sup.counts["infeasible"],
        )

    def odometry_dict(self) -> dict[str, object]:
        """The odometry as a JSON-able mapping."""
        st = self.odometry.state
        return {
            "x": st.pose.x_m, "y": st.pose.y_m, "theta": st.pose.theta_rad,
            "vx": st.twist.vx_m_s, "vy": st.twist.vy_m_s, "wz": st.twist.wz_rad_s,
            "slip": st.slip_m_s, "distance": st.distance_m, "t": st.timestamp_s,
        }

    @property
    def state(self) -> GatewayState:
        """The supervisor's state."""
        return self.supervisor.state
