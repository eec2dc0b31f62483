"""Stateful ODrive CANSimple driver: enable sequence, liveness, faults and odometry.

Reference: the `ODrive CAN protocol
<https://docs.odriverobotics.com/v/latest/manual/can-protocol.html>`_ and
the ODrive CAN protocol documentation (docs.odriverobotics.com, can-protocol).  Frame layouts live
in :mod:`drivers.odrive.messages`,
the protocol keys in :mod:`drivers.odrive.options`, and the mapping of reported errors onto
faults in :mod:`drivers.odrive.faults`.

Per motor, the driver

* arms with Clear_Errors, Set_Controller_Mode (velocity control, the configured input mode) and
  Set_Axis_State CLOSED_LOOP_CONTROL, and reports ENABLING until a heartbeat shows
  CLOSED_LOOP_CONTROL (the official ``can_simple.py`` example does the same).  An enable that
  does not take is repeated every :attr:`OdriveDriver.ENABLE_RETRY_S` while the axis is alive,
  idle and error-free, :attr:`OdriveDriver.ENABLE_ATTEMPTS` times at most; a reported error is
  never cleared automatically;
* disarms with Set_Input_Vel 0 then Set_Axis_State IDLE;
* streams Set_Input_Vel every cycle, which also feeds the axis watchdog;
* on firmware 0.6 with the watchdog's endpoint IDs, sets the axis watchdog over CAN before
  arming (Get_Version, RxSdo writes, TxSdo read-back; :mod:`drivers.odrive.watchdog`) and arms
  only once it reads back as written (``gateway.controller_watchdog: warn`` arms anyway, with
  a warning); on 0.5 the motor block states the watchdog set with odrivetool;
* is alive while both heartbeats and encoder estimates are younger than ``liveness_s``
  (heartbeats give the state, estimates the odometry);
* reports FAULT with the decoded flag names when the heartbeat carries an axis error (0.5: also
  the motor/encoder/controller flags) and then asks once for Get_Error (0.6: active errors and
  disarm reason) or Get_Motor_Error (0.5) to complete the detail text.

Steering actuators (motors with the ``STEER`` role) arm in POSITION_CONTROL with the
PASSTHROUGH input mode and get one Set_Input_Pos per cycle: the steering angle through
``zero_rad``, ``gear_ratio`` and ``invert`` in turns, with the commanded angle's rate since the
previous cycle as speed feed-forward (the gateway already limits the steering rate, so the axis
needs no trajectory of its own).  Their feedback is the absolute position estimate, so the axis'
position frame must be fixed across power cycles (an absolute encoder, or an index search whose
result ``zero_rad`` records).

Odometry precision: the position is the firmware's float32 estimate in turns.  Its resolution
is one float32 ULP, 2**(e - 23) turns for a value in [2**e, 2**(e + 1)): 1.2e-7 turn near 1
turn, 0.0078 turn at 1e5 turns, 0.125 turn beyond 2**20 turns.  The driver subtracts the first
sample in float64 (exact), so the only loss is the firmware's own rounding; for long missions
re-zero the axis position (0.6 Set_Absolute_Position, 0.5 Set_Linear_Count) while stopped.
"""

from __future__ import annotations

import logging
import math
from typing import TYPE_CHECKING, ClassVar, cast

from drivers.odrive.codec import OdriveCodec
from drivers.odrive.enums import AxisState, CmdId, ControlMode, Firmware, InputMode
from drivers.odrive.faults import error_query_adds_detail, error_reply_detail, heartbeat_faults
from drivers.odrive.messages import (
    CMD_BITS,
    CMD_MASK,
    MAX_EXTENDED_NODE_ID,
    EncoderEstimates,
    ErrorStatus,
    Heartbeat,
    MotorErrorStatus,
)
from drivers.odrive.options import OPTIONS, bus_settings
from drivers.odrive.sim import OdriveSimulator
from drivers.odrive.watchdog import (
    DEFAULT_TIMEOUT_S,
    RX_SDO,
    TX_SDO,
    Step,
    WatchdogSetup,
    endpoints_from_options,
    parse_sdo,
    parse_version,
)
from gateway.core.errors import ConfigError, DecodeError, EncodeError, IllegalTransitionError
from gateway.core.protection import Guard, Protection, ProtectionState, WatchdogPolicy
from gateway.core.types import DriveFault, DriveState, WheelFeedback
from gateway.drive.driver import MotorDriver, OptionSpec
from gateway.drive.filters import EXT_MASK, STD_MASK, CanFilter

if TYPE_CHECKING:
    from collections.abc import Mapping, Sequence

    from gateway.core.types import Frame, MotorConfig
    from gateway.sim.device import DeviceSimulator

log = logging.getLogger(__name__)

TAU = 2.0 * math.pi


class OdriveDriver(MotorDriver):
    """All ODrive axes on one bus (one firmware family and one ID mode per driver).

    :param motors: the motors, in the order :meth:`command` receives speeds.
    :raises ConfigError: for a bad protocol key, a node ID out of range for the ID mode, a
        repeated node ID, or motors that disagree on ``firmware`` or ``extended_id``.
    """

    OPTIONS: ClassVar[Mapping[str, OptionSpec]] = OPTIONS
    #: Node IDs with 11-bit identifiers (0x3F is the 0.6 broadcast address).
    NODE_ID_RANGE: ClassVar[tuple[int, int]] = (0, 0x3E)
    #: Node IDs with 29-bit identifiers (``extended_id: true``).
    EXTENDED_NODE_ID_RANGE: ClassVar[tuple[int, int]] = (0, MAX_EXTENDED_NODE_ID)
    #: Seconds between enable attempts that have not reached CLOSED_LOOP_CONTROL.
    ENABLE_RETRY_S: ClassVar[float] = 0.5
    #: Enable attempts (while the axis answers) before giving up.
    ENABLE_ATTEMPTS: ClassVar[int] = 3
    #: Heartbeats this soon after an enable may still carry the errors it just cleared.
    ENABLE_GRACE_S: ClassVar[float] = 0.3
    #: Steering actuators: position control with Set_Input_Pos.
    STEERING: ClassVar[bool] = True
    PROTOCOL: ClassVar[str] = "ODrive"
    TIMEOUT_ACTION: ClassVar[str] = (
        "latches WATCHDOG_TIMER_EXPIRED and goes IDLE: the motor coasts"
    )

    def __init__(self, motors: Sequence[MotorConfig]) -> None:
        super().__init__(motors)
        opts = [self.validate_options(m.options, f"motor {m.wheel!r}") for m in self.motors]
        self.codec = OdriveCodec(*bus_settings(self.motors, opts))
        self._extended_id = self.codec.extended_id
        if opts:
            self.liveness_s = cast("float", opts[0]["liveness_s"])
        n = len(self.motors)
        self._input_mode = [InputMode(cast("int", o["input_mode"])) for o in opts]
        for m, mode in zip(self.motors, self._input_mode, strict=True):
            if m.steering and mode is not InputMode.PASSTHROUGH:
                raise ConfigError(
                    f"motor {m.wheel!r}.input_mode: expected {int(InputMode.PASSTHROUGH)} "
                    f"(passthrough) for a steering actuator, which gets the gateway's "
                    f"rate-limited angle and its speed as feed-forward, got {int(mode)}"
                )
        #: Whether each motor is a steering actuator (position control).
        self._steer = tuple(m.steering for m in self.motors)
        self._any_steer = any(self._steer)
        #: The previous cycle's steering command of each motor: (time, angle), for the
        #: speed feed-forward.
        self._last_angle: list[tuple[float, float] | None] = [None] * n
        self._rtr = [o["encoder_request"] == "rtr" for o in opts]
        self._axis_state: list[AxisState | int] = [AxisState.UNDEFINED] * n
        self._heartbeat_s: list[float | None] = [None] * n
        self._encoder_s: list[float | None] = [None] * n
        self._pos0_turns: list[float | None] = [None] * n
        self._enabling = [False] * n
        self._enable_sent_s = [0.0] * n
        self._attempts = [0] * n
        self._axis_detail = [""] * n
        self._error_detail = [""] * n
        self._error_request_due = [False] * n
        #: Per motor, the 0.6 watchdog setup (``None``: 0.5, or no endpoint IDs given), and
        #: whether its arming waits for it.
        self._stated_s = [float(cast("float", o["controller_timeout_s"])) for o in opts]
        self._wd = [self._watchdog_setup(m, o) for m, o in zip(self.motors, opts, strict=True)]
        self._arm_waits = [False] * n
        #: Frames to send at the next poll (the setup's answers to replies).
        self._queued: list[Frame] = []
        #: (node ID, gear ratio, sign, speed bound in rad/s) per motor, for :meth:`command`.
        self._cmd = tuple(
            (m.node_id, m.gear_ratio, m.sign, m.max_wheel_rad_s * (1.0 + 1e-12))
            for m in self.motors
        )

    def _watchdog_setup(self, m: MotorConfig, o: Mapping[str, object]) -> WatchdogSetup | None:
        where = f"motor {m.wheel!r}"
        endpoints = endpoints_from_options(o, where, str(o["config_dir"]))
        if endpoints is None:
            return None
        if self.codec.firmware is not Firmware.V0_6:
            raise ConfigError(
                f"{where}: flat_endpoints/watchdog_endpoints: expected firmware 0.6 (0.5 has "
                f"no parameter access over CAN: set the watchdog with odrivetool and state "
                f"controller_timeout_s), got firmware {self.codec.firmware.value}"
            )
        timeout = cast("float", o["controller_timeout_s"]) or DEFAULT_TIMEOUT_S
        arb = self.codec.arbitration_id
        return WatchdogSetup(
            endpoints, timeout, arb(m.node_id, RX_SDO), arb(m.node_id, CmdId.GET_VERSION),
            self._extended_id,
        )

    def protection(self, index: int) -> Protection:
        """0.6 with endpoint IDs: CONFIGURED; otherwise STATED by ``controller_timeout_s``
        (set with odrivetool or the web GUI) or UNSTATED (see :mod:`drivers.odrive.watchdog`)."""
        wd, m, stated = self._wd[index], self.motors[index], self._stated_s[index]
        if wd is not None:
            ep = wd.endpoints
            return Protection(
                Guard.CONFIGURED, wd.timeout_s, self.TIMEOUT_ACTION,
                f"axis watchdog written over CAN (RxSdo endpoints {ep.timeout_id}, "
                f"{ep.enable_id} of firmware {ep.fw_version}) and read back before arming",
            )
        v06 = self.codec.firmware is Firmware.V0_6
        if stated > 0 and not v06:
            return Protection(
                Guard.STATED, stated, self.TIMEOUT_ACTION,
                "axis watchdog set with odrivetool (0.5 cannot set it over CAN); stated by "
                "controller_timeout_s, not verifiable over CAN",
            )
        axis = f"odrv.axis0 of node {m.node_id}"
        if v06:
            return Protection(
                Guard.UNSTATED, stated or None, "unknown",
                "not set over CAN: the motor block names no endpoint IDs (flat_endpoints or "
                "watchdog_endpoints)" + (
                    f"; controller_timeout_s {stated:g} s is not confirmed" if stated else ""
                ),
                "give flat_endpoints: the flat_endpoints.json of the axis' firmware release "
                "(https://docs.odriverobotics.com/releases/firmware)",
                configurable=True,
            )
        return Protection(
            Guard.UNSTATED, None, "unknown",
            "not stated: an ODrive's watchdog is off from the factory",
            f"in odrivetool: {axis}.config.watchdog_timeout = 0.25, "
            f"{axis}.config.enable_watchdog = True, save_configuration(); then state "
            "controller_timeout_s: 0.25",
        )

    def protection_state(self, index: int) -> ProtectionState:
        """NOT_APPLICABLE without a 0.6 setup; else PENDING, CONFIRMED or FAILED."""
        wd = self._wd[index]
        if wd is None:
            return ProtectionState.NOT_APPLICABLE
        if wd.step is Step.CONFIRMED:
            return ProtectionState.CONFIRMED
        return ProtectionState.FAILED if wd.step is Step.FAILED else ProtectionState.PENDING

    @classmethod
    def node_id_range(cls, options: Mapping[str, object] | None = None) -> tuple[int, int]:
        """:attr:`EXTENDED_NODE_ID_RANGE` with ``extended_id: true``, else :attr:`NODE_ID_RANGE`."""
        extended = bool(options and options.get("extended_id"))
        return cls.EXTENDED_NODE_ID_RANGE if extended else cls.NODE_ID_RANGE

    @classmethod
    def make_simulator(cls, motor: MotorConfig) -> DeviceSimulator:
        """An :class:`~drivers.odrive.sim.OdriveSimulator` for ``motor``, as the motor block
        says it was configured: at factory settings (watchdog off) with the 0.6 endpoint IDs
        it names, or with the watchdog it states (``controller_timeout_s``) saved."""
        o = cls.validate_options(motor.options, f"motor {motor.wheel!r}")
        endpoints = endpoints_from_options(o, f"motor {motor.wheel!r}", str(o["config_dir"]))
        if endpoints is not None:
            return OdriveSimulator(motor, endpoints=endpoints)
        return OdriveSimulator(
            motor, watchdog_timeout_s=cast("float", o["controller_timeout_s"])
        )

    # ----------------------------------------------------------------- state

    def _alive(self, i: int, now_s: float) -> bool:
        hb, enc = self._heartbeat_s[i], self._encoder_s[i]
        return (
            hb is not None
            and enc is not None
            and now_s - hb <= self.liveness_s
            and now_s - enc <= self.liveness_s
        )

    def state(self, index: int, now_s: float) -> DriveState:
        """OFFLINE, FAULT, ENABLED (heartbeat shows CLOSED_LOOP_CONTROL), ENABLING or DISABLED."""
        # _alive, inlined: this runs for every motor on every cycle.
        hb, enc, live = self._heartbeat_s[index], self._encoder_s[index], self.liveness_s
        if hb is None or enc is None or now_s - hb > live or now_s - enc > live:
            return DriveState.OFFLINE
        if self._faults[index]:
            return DriveState.FAULT
        if self._axis_state[index] == AxisState.CLOSED_LOOP_CONTROL:
            return DriveState.ENABLED
        return DriveState.ENABLING if self._enabling[index] else DriveState.DISABLED

    def axis_state(self, index: int) -> AxisState | int:
        """The axis state of motor ``index`` in its last heartbeat (``UNDEFINED`` before one)."""
        return self._axis_state[index]

    # ----------------------------------------------------------------- hooks

    def enable(self, now_s: float) -> list[Frame]:
        """Clear errors, select velocity control and request CLOSED_LOOP_CONTROL on every axis.

        :raises IllegalTransitionError: if an axis reports a calibration or homing procedure
            (a new state request would abort it); no frame is sent then.
        """
        frames: list[Frame] = []
        arm = [self._arm_frames(i, now_s) for i in range(len(self.motors))]  # may raise
        for i, wd in enumerate(self._wd):
            self.clear_protection_fault(i)
            self._arm_waits[i] = wd is not None
            frames.extend(arm[i] if wd is None else wd.start(now_s))
        for i in range(len(self.motors)):
            self._enabling[i] = True
            self._enable_sent_s[i] = now_s
            self._attempts[i] = 1
            self._error_detail[i] = ""
        return frames

    def _arm_frames(self, i: int, now_s: float) -> tuple[Frame, ...]:
        m = self.motors[i]
        current = self._axis_state[i] if self._alive(i, now_s) else AxisState.UNDEFINED
        mode = ControlMode.POSITION_CONTROL if m.steering else ControlMode.VELOCITY_CONTROL
        self._last_angle[i] = None
        try:
            return self.codec.make_transition(
                m.node_id, current, AxisState.CLOSED_LOOP_CONTROL, self._input_mode[i], mode
            )
        except IllegalTransitionError as err:
            raise IllegalTransitionError(f'Cannot enable wheel "{m.wheel}": {err}') from err

    def disable(self, now_s: float) -> list[Frame]:
        """Set_Input_Vel 0 and Set_Axis_State IDLE on every axis (allowed from any state)."""
        frames: list[Frame] = []
        for i, m in enumerate(self.motors):
            self._enabling[i] = False
            self._arm_waits[i] = False
            frames.extend(
                self.codec.make_transition(m.node_id, self._axis_state[i], AxisState.IDLE)
            )
        return frames

    def command(self, wheel_rad_s: Sequence[float], now_s: float) -> list[Frame]:
        """One Set_Input_Vel per axis: turns/s = wheel rad/s * gear_ratio * sign / (2 pi); a
        steering actuator gets Set_Input_Pos instead (see the module docstring).

        :param wheel_rad_s: wheel speeds in rad/s (steering angles in rad for steering
            actuators), in :attr:`motors` order.
        :raises EncodeError: for a speed that is not finite or beyond the motor's ``max_rpm``,
            a steering angle that is not finite, or a number of setpoints other than the
            number of motors.
        """
        if len(wheel_rad_s) != len(self.motors):
            raise EncodeError(
                f"Expected {len(self.motors)} wheel speeds for the ODrive axes, "
                f"but got {len(wheel_rad_s)}."
            )
        if self._any_steer:
            return self._command_mixed(wheel_rad_s, now_s)
        # Per-motor constants come from __init__; the arithmetic is the same as
        # m.wheel_to_motor_rad_s(w) / TAU against m.max_wheel_rad_s.
        make = self.codec.make_set_input_vel
        out: list[Frame] = []
        for (node_id, gear, sign, bound), w in zip(self._cmd, wheel_rad_s, strict=True):
            if not (math.isfinite(w) and abs(w) <= bound):
                raise self._speed_error(len(out), w)
            out.append(make(node_id, w * gear * sign / TAU))
        return out

    def _command_mixed(self, setpoints: Sequence[float], now_s: float) -> list[Frame]:
        """:meth:`command` for a bus with steering actuators."""
        out: list[Frame] = []
        for i, (m, value) in enumerate(zip(self.motors, setpoints, strict=True)):
            if not m.steering:
                out.extend(self._drive_frame(i, value))
                continue
            if not math.isfinite(value):
                raise EncodeError(
                    f'Expected a finite steering angle for node {m.node_id} ("{m.wheel}") in '
                    f"rad, but got {value}."
                )
            last, self._last_angle[i] = self._last_angle[i], (now_s, value)
            rate = 0.0
            if last is not None and now_s > last[0]:
                rate = (value - last[1]) / (now_s - last[0])
            # Motor side as MotorConfig.steer_to_motor_rad; the speed within max_rpm.
            limit = m.max_rpm / 60.0
            ff = min(max(rate * m.gear_ratio * m.sign / TAU, -limit), limit)
            out.append(
                self.codec.make_set_input_pos(m.node_id, m.steer_to_motor_rad(value) / TAU, ff)
            )
        return out

    def _drive_frame(self, i: int, w: float) -> tuple[Frame]:
        node_id, gear, sign, bound = self._cmd[i]
        if not (math.isfinite(w) and abs(w) <= bound):
            raise self._speed_error(i, w)
        return (self.codec.make_set_input_vel(node_id, w * gear * sign / TAU),)

    def _speed_error(self, i: int, w: float) -> EncodeError:
        m = self.motors[i]
        limit = m.max_wheel_rad_s
        return EncodeError(
            f'Expected velocity for node {m.node_id} ("{m.wheel}") between '
            f"{-limit:.3g} and {limit:.3g} rad/s, but got {w}."
        )

    def poll(self, now_s: float) -> list[Frame]:
        """RTR encoder requests (``encoder_request: rtr``), error queries and enable retries."""
        frames, self._queued = self._queued, []
        for i, m in enumerate(self.motors):
            if self._arm_waits[i]:
                frames.extend(self._watchdog_step(i, now_s))
            if self._rtr[i]:
                frames.append(self.codec.make_request(m.node_id, CmdId.GET_ENCODER_ESTIMATES))
            if self._error_request_due[i]:
                self._error_request_due[i] = False
                frames.append(self.codec.make_request(m.node_id, CmdId.GET_ERROR))
            if (
                self._enabling[i]
                and not self._arm_waits[i]
                and now_s - self._enable_sent_s[i] >= self.ENABLE_RETRY_S
            ):
                frames.extend(self._retry_enable(i, now_s))
        return frames

    def _watchdog_step(self, i: int, now_s: float) -> list[Frame]:
        """Drive motor ``i``'s watchdog setup; arm it once confirmed (or failed, under
        ``controller_watchdog: warn``)."""
        wd = self._wd[i]
        assert wd is not None
        frames = wd.poll(now_s)
        if wd.step is Step.CONFIRMED:
            m = self.motors[i]
            log.info(
                'ODrive node %d ("%s"): watchdog %g s confirmed; arming',
                m.node_id, m.wheel, wd.timeout_s,
            )
        elif wd.step is Step.FAILED:
            self.protection_fault(i, wd.why)
            if self.watchdog_policy is not WatchdogPolicy.WARN:
                self._arm_waits[i] = self._enabling[i] = False
                return frames
        else:
            return frames
        self._arm_waits[i] = False
        self._enable_sent_s[i] = now_s
        self._attempts[i] = 1
        return [*frames, *self._arm_frames(i, now_s)]

    def _retry_enable(self, i: int, now_s: float) -> tuple[Frame, ...]:
        m = self.motors[i]
        if self._faults[i]:
            if now_s - self._enable_sent_s[i] > self.ENABLE_GRACE_S:
                self._enabling[i] = False  # the axis refused: stay in FAULT, never auto-clear
            return ()
        if not self._alive(i, now_s) or self._axis_state[i] != AxisState.IDLE:
            return ()  # not answering yet, or busy: wait without using up an attempt
        if self._attempts[i] >= self.ENABLE_ATTEMPTS:
            log.warning(
                'ODrive node %d ("%s") stayed in IDLE after %d enable attempts; giving up',
                m.node_id,
                m.wheel,
                self._attempts[i],
            )
            self._enabling[i] = False
            return ()
        self._attempts[i] += 1
        self._enable_sent_s[i] = now_s
        log.info('ODrive node %d ("%s"): enable attempt %d', m.node_id, m.wheel, self._attempts[i])
        return self._arm_frames(i, now_s)

    def receive_filters(self) -> tuple[CanFilter, ...]:
        """Every CANSimple message of our nodes (``node_id << 5 | cmd``, any command): the
        replies and cyclic messages, and the command frames ``on_frame`` ignores."""
        ext = self._extended_id
        mask = (EXT_MASK if ext else STD_MASK) & ~CMD_MASK
        return tuple(CanFilter(m.node_id << CMD_BITS, mask, ext) for m in self.motors)

    def on_frame(self, frame: Frame) -> bool:
        """Take a heartbeat, encoder estimate or error reply of one of our axes.

        Frames of the other ID type or of other nodes are not ours.  Of ours, malformed frames
        and remote frames other than the requests this driver sends itself are counted in
        :attr:`rejected`; command frames (another master talking to our axes) are ignored.
        """
        # Every received frame of the bus comes here: the identifier is split once (the
        # codec's decode_reply takes the parts), and encoder estimates, most of the traffic,
        # go from the payload to the wheel feedback without an EncoderEstimates object.
        if frame.is_extended_id != self._extended_id:
            return False
        arb = frame.arbitration_id
        node = arb >> CMD_BITS
        i = self._index.get(node)
        if i is None:
            return False
        cmd = arb & CMD_MASK
        if cmd in (CmdId.GET_VERSION, TX_SDO) and not frame.is_remote_frame:
            if self.codec.firmware is Firmware.V0_6:
                self._on_setup_reply(i, cmd, frame)
                return True
        try:
            if frame.is_remote_frame:
                msg = None
            elif cmd == CmdId.GET_ENCODER_ESTIMATES and frame.dlc == 8:
                pos, vel = self.codec.unpack_estimates(node, frame)
                self._on_estimates(i, pos, vel, frame.timestamp_s)
                return True
            else:
                msg = self.codec.decode_reply(node, cmd, frame)
        except DecodeError as err:
            self.reject("malformed", err)
            return True
        if isinstance(msg, EncoderEstimates):
            self._on_estimates(i, msg.pos_turns, msg.vel_turns_s, frame.timestamp_s)
        elif isinstance(msg, Heartbeat):
            self._on_heartbeat(i, msg, frame.timestamp_s)
        elif isinstance(msg, (ErrorStatus, MotorErrorStatus)):
            self._on_error_status(i, msg)
        elif frame.is_remote_frame and not self._own_request(i, cmd):
            self.reject("remote frame where data expected")
        return True

    def _on_setup_reply(self, i: int, cmd: int, frame: Frame) -> None:
        """A Get_Version or TxSdo data frame of axis ``i`` (0.6): to its watchdog setup."""
        wd = self._wd[i]
        if wd is None or frame.dlc == 0:
            return  # no setup, or a Get_Version request (another host's)
        node = self.motors[i].node_id
        if cmd == CmdId.GET_VERSION:
            version = parse_version(frame.data)
            if version is not None:
                self._queued.extend(wd.on_version(*version, frame.timestamp_s))
                return
            expected = "8 bytes in Get_Version"
        else:
            reply = parse_sdo(frame.data)
            if reply is not None:
                wd.on_tx_sdo(reply[1], reply[2])
                return
            expected = "at least 4 bytes in TxSdo"
        self.reject("malformed", DecodeError(
            f"Expected {expected} of ODrive node {node}, but got {frame.dlc}."
        ))

    def _own_request(self, i: int, cmd: int) -> bool:
        """Whether this driver itself sends RTR frames with ``cmd`` (their echo is no error)."""
        return cmd == CmdId.GET_ERROR or (self._rtr[i] and cmd == CmdId.GET_ENCODER_ESTIMATES)

    # ----------------------------------------------------------------- receive helpers

    def _on_estimates(self, i: int, pos_turns: float, vel_turns_s: float, t: float) -> None:
        _, gear, sign, _ = self._cmd[i]
        if self._steer[i]:
            # A steering actuator: the absolute angle, in the axis' own position frame.
            m = self.motors[i]
            self._encoder_s[i] = t
            self._feedback[i] = WheelFeedback(
                m.motor_to_steer_rad(pos_turns * TAU), vel_turns_s * TAU * sign / gear, t
            )
            return
        pos0 = self._pos0_turns[i]
        if pos0 is None:
            pos0 = self._pos0_turns[i] = pos_turns
        # float32 - float32 is exact in float64; the wheel angle is relative to the first sample.
        # Motor to wheel side as MotorConfig.motor_to_wheel_rad_s: x * sign / gear.
        position = (pos_turns - pos0) * TAU * sign / gear
        velocity = vel_turns_s * TAU * sign / gear
        self._encoder_s[i] = t
        self._feedback[i] = WheelFeedback(position, velocity, t)  # store_feedback, inlined

    def _on_heartbeat(self, i: int, hb: Heartbeat, t: float) -> None:
        fw = self.codec.firmware
        self._heartbeat_s[i] = t
        self._axis_state[i] = hb.axis_state
        if not (hb.axis_error or hb.motor_error or hb.encoder_error or hb.controller_error):
            # A healthy axis, nearly every heartbeat: the state the general path below ends in
            # for no error, without its flag mapping and string work.
            self._error_detail[i] = ""
            self._error_request_due[i] = False
            self._axis_detail[i] = ""
            self.set_fault(i, DriveFault.NONE)
            self._set_axis_state(i, hb.axis_state)
            return
        faults, detail = heartbeat_faults(fw, hb)
        if faults and not self._faults[i]:
            m = self.motors[i]
            log.warning('ODrive node %d ("%s") reports %s', m.node_id, m.wheel, detail)
            self._error_request_due[i] = error_query_adds_detail(fw, hb)
        if faults and self._enabling[i] and t - self._enable_sent_s[i] > self.ENABLE_GRACE_S:
            self._enabling[i] = False
        if not faults:
            self._error_detail[i] = ""
            self._error_request_due[i] = False
        self._axis_detail[i] = detail
        self._publish_fault(i, faults)
        self._set_axis_state(i, hb.axis_state)

    def _set_axis_state(self, i: int, axis_state: AxisState | int) -> None:
        armed = axis_state == AxisState.CLOSED_LOOP_CONTROL
        if armed:
            self._enabling[i] = False
        self.set_armed(i, armed)

    def _on_error_status(self, i: int, msg: ErrorStatus | MotorErrorStatus) -> None:
        self._error_detail[i] = error_reply_detail(self.codec.firmware, msg)
        self._publish_fault(i, self._faults[i])

    def _publish_fault(self, i: int, faults: DriveFault) -> None:
        detail = "; ".join(p for p in (self._axis_detail[i], self._error_detail[i]) if p)
        self.set_fault(i, faults, detail if faults else "")
