"""Stateful ODrive CANSimple driver: commands, received frames, faults and odometry.

Reference: the `ODrive CAN protocol
<https://docs.odriverobotics.com/v/latest/manual/can-protocol.html>`_ (docs.odriverobotics.com,
can-protocol).  Frame layouts live in :mod:`drivers.odrive.messages`, the protocol keys in
:mod:`drivers.odrive.options`, each axis' record and its enable sequence in
:mod:`drivers.odrive.axis`, the axis watchdog in :mod:`drivers.odrive.watchdog` and
:mod:`drivers.odrive.protection`, and the mapping of reported errors onto faults in
:mod:`drivers.odrive.faults`.

Per motor, the driver

* arms with Clear_Errors, Set_Controller_Mode and Set_Axis_State CLOSED_LOOP_CONTROL and reports
  ENABLING until a heartbeat shows CLOSED_LOOP_CONTROL; retries, and disarms with Set_Input_Vel 0
  then Set_Axis_State IDLE (:mod:`drivers.odrive.axis`);
* streams Set_Input_Vel every cycle, which also feeds the axis watchdog;
* on firmware 0.6 with the watchdog's endpoint IDs, sets the axis watchdog over CAN before
  arming (Get_Version, RxSdo writes, TxSdo read-back; :mod:`drivers.odrive.watchdog`) and arms
  only once it reads back as written (``gateway.controller_watchdog: warn`` arms anyway, with
  a warning); on 0.5 the motor block states the watchdog set with odrivetool;
* is alive while both the encoder estimates and the heartbeats are younger than
  ``liveness_s`` (:attr:`OdriveDriver.LIVENESS_STREAMS`: the estimates give the odometry, the
  heartbeats the state);
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
from types import MappingProxyType
from typing import TYPE_CHECKING, ClassVar

from drivers.odrive.axis import Axis
from drivers.odrive.codec import OdriveCodec, unpack_estimates
from drivers.odrive.enums import AxisState, CmdId, Firmware, InputMode
from drivers.odrive.faults import error_query_adds_detail, error_reply_detail, heartbeat_faults
from drivers.odrive.messages import (
    CMD_BITS,
    CMD_MASK,
    MAX_EXTENDED_NODE_ID,
    STREAM_HINTS,
    ErrorStatus,
    Heartbeat,
    MotorErrorStatus,
)
from drivers.odrive.options import OdriveOptions
from drivers.odrive.protection import TIMEOUT_ACTION, axis_protection, watchdog_setup
from drivers.odrive.watchdog import TX_SDO, parse_sdo, parse_version
from gateway.core.errors import ConfigError, DecodeError
from gateway.core.protection import ProtectionState
from gateway.core.types import DriveFault, DriveState, WheelFeedback
from gateway.drive.claims import FrameClaim
from gateway.drive.driver import MotorDriver
from gateway.drive.filters import EXT_MASK, STD_MASK

if TYPE_CHECKING:
    from collections.abc import Mapping, Sequence

    from gateway.core.protection import Protection
    from gateway.core.types import Frame, MotorConfig
    from gateway.drive.traffic import Traffic

log = logging.getLogger(__name__)

TAU = 2.0 * math.pi

#: Command ID -> the message name in labels (``Get_Encoder_Estimates``; others: a number).
_NAMES: Mapping[int, str] = MappingProxyType({int(c): c.name.title() for c in CmdId})
#: Command IDs as plain ints for the per-frame tests.
_ESTIMATES = int(CmdId.GET_ENCODER_ESTIMATES)
_GET_ERROR = int(CmdId.GET_ERROR)
#: The 0.6 watchdog setup's replies: Get_Version and TxSdo.
_SETUP_REPLIES = frozenset({int(CmdId.GET_VERSION), TX_SDO})


class OdriveDriver(MotorDriver[OdriveOptions]):
    """All ODrive axes on one bus (one firmware family and one ID mode per driver).

    :param motors: the motors, in the order :meth:`command` receives setpoints.
    :raises ConfigError: for a bad protocol key, a node ID out of range for the ID mode or
        repeated, motors that disagree on ``liveness_s``, ``firmware`` or ``extended_id``, a
        steering actuator not in passthrough, or watchdog endpoint IDs on firmware 0.5.
    """

    Options = OdriveOptions
    BUS_WIDE: ClassVar[tuple[str, ...]] = ("liveness_s", "firmware", "extended_id")
    #: Node IDs with 11-bit identifiers (0x3F is the 0.6 broadcast address).
    NODE_ID_RANGE: ClassVar[tuple[int, int]] = (0, 0x3E)
    #: Node IDs with 29-bit identifiers (``extended_id: true``).
    EXTENDED_NODE_ID_RANGE: ClassVar[tuple[int, int]] = (0, MAX_EXTENDED_NODE_ID)
    LIVENESS_STREAMS: ClassVar[tuple[str, ...]] = ("encoder estimates", "heartbeat")
    STREAM_HINTS: ClassVar[Mapping[str, str]] = STREAM_HINTS
    #: Steering actuators: position control with Set_Input_Pos.
    STEERING: ClassVar[bool] = True
    PROTOCOL: ClassVar[str] = "ODrive"
    TIMEOUT_ACTION: ClassVar[str] = TIMEOUT_ACTION
    #: 0.6 axes with endpoint IDs get their watchdog written and read back before arming.
    CONFIGURES_PROTECTION: ClassVar[bool] = True

    def __init__(self, motors: Sequence[MotorConfig]) -> None:
        super().__init__(motors)
        first = self.opts[0] if self.opts else OdriveOptions()
        self.codec = OdriveCodec(first.firmware_family, first.extended_id)
        self._extended_id = self.codec.extended_id
        self._v06 = self.codec.firmware is Firmware.V0_6
        axes = []
        for i, (m, o) in enumerate(zip(self.motors, self.opts, strict=True)):
            mode = InputMode(o.input_mode)
            if m.steering and mode is not InputMode.PASSTHROUGH:
                raise ConfigError(
                    f"motor {m.wheel!r}.input_mode: expected {int(InputMode.PASSTHROUGH)} "
                    f"(passthrough) for a steering actuator, which gets the gateway's "
                    f"rate-limited angle and its speed as feed-forward, got {int(mode)}"
                )
            axes.append(Axis(
                i, m, m.node_id, m.steering, self.motor_scale[i], o.encoder_request == "rtr",
                mode, watchdog_setup(m, o, self.codec),
            ))
        #: One record per axis, in :attr:`motors` order, and by node ID.
        self._axes: tuple[Axis, ...] = tuple(axes)
        self._by_node = {ax.node_id: ax for ax in axes}
        self._any_steer = any(ax.steer for ax in axes)
        #: (Set_Input_Vel identifier, gear_ratio * sign) per motor, for :meth:`_command`.
        self._vel = tuple((self.codec.arbitration_id(ax.node_id, CmdId.SET_INPUT_VEL), ax.scale)
                          for ax in axes)
        #: Frames to send at the next poll (the watchdog setups' answers to replies).
        self._queued: list[Frame] = []

    @classmethod
    def node_id_range(cls, options: Mapping[str, object] | None = None) -> tuple[int, int]:
        """:attr:`EXTENDED_NODE_ID_RANGE` with ``extended_id: true``, else :attr:`NODE_ID_RANGE`."""
        extended = bool(options and options.get("extended_id"))
        return cls.EXTENDED_NODE_ID_RANGE if extended else cls.NODE_ID_RANGE

    # ----------------------------------------------------------------- protection

    def protection(self, index: int) -> Protection:
        """0.6 with endpoint IDs: CONFIGURED; otherwise STATED by ``controller_timeout_s``
        (set with odrivetool or the web GUI) or UNSTATED (:mod:`drivers.odrive.protection`)."""
        ax = self._axes[index]
        return axis_protection(ax.node_id, self.codec.firmware, ax.watchdog,
                               self.opts[index].controller_timeout_s)

    def protection_state(self, index: int) -> ProtectionState:
        """NOT_APPLICABLE without a 0.6 setup; else PENDING, CONFIRMED or FAILED."""
        wd = self._axes[index].watchdog
        return ProtectionState.NOT_APPLICABLE if wd is None else wd.state

    def protection_failure(self, index: int) -> str:
        """Why motor ``index``'s watchdog setup failed (what came back, or the silence)."""
        wd = self._axes[index].watchdog
        return wd.why if wd is not None and wd.why else super().protection_failure(index)

    # ----------------------------------------------------------------- state

    def _ready_state(self, index: int) -> DriveState:
        """ENABLED (the heartbeat shows CLOSED_LOOP_CONTROL), ENABLING or DISABLED."""
        ax = self._axes[index]
        if self.is_armed(index):
            return DriveState.ENABLED
        return DriveState.ENABLING if ax.enabling else DriveState.DISABLED

    def axis_state(self, index: int) -> AxisState | int:
        """Motor ``index``'s axis state in its last heartbeat (``UNDEFINED`` before one)."""
        return self._axes[index].axis_state

    # ----------------------------------------------------------------- hooks

    def _enable(self, now_s: float) -> list[Frame]:
        """Clear errors, select the control mode and request CLOSED_LOOP_CONTROL on every axis
        (after the watchdog setup on 0.6 with endpoint IDs).

        :raises IllegalTransitionError: if an axis reports a calibration or homing procedure
            (a new state request would abort it); no frame is sent then.
        """
        alive = self.live.alive
        arm = [ax.arm(self.codec, alive(ax.index, now_s)) for ax in self._axes]  # may raise
        frames: list[Frame] = []
        for ax, frames_of in zip(self._axes, arm, strict=True):
            refused = ax.refusal
            frames.extend(ax.start(frames_of, now_s))
            if refused:  # the last enable's refusal goes (a heartbeat re-asserts real faults)
                self._publish_fault(ax, DriveFault.NONE)
        return frames

    def disable(self, now_s: float) -> list[Frame]:
        """Set_Input_Vel 0 and Set_Axis_State IDLE on every axis (allowed from any state)."""
        return [f for ax in self._axes for f in ax.disarm(self.codec)]

    def _command(self, setpoints: Sequence[float], now_s: float) -> list[Frame]:
        """One Set_Input_Vel per axis: turns/s = wheel rad/s * gear_ratio * sign / (2 pi); a
        steering actuator gets Set_Input_Pos instead (see the module docstring)."""
        if self._any_steer:
            return self._command_mixed(setpoints, now_s)
        return self.codec.set_input_vels(self._vel, setpoints)  # checked by command()

    def _command_mixed(self, setpoints: Sequence[float], now_s: float) -> list[Frame]:
        """:meth:`_command` for a bus with steering actuators."""
        out: list[Frame] = []
        codec = self.codec
        for ax, value in zip(self._axes, setpoints, strict=True):
            if not ax.steer:
                out.append(codec.make_set_input_vel(ax.node_id, value * ax.scale / TAU))
                continue
            last, ax.last_angle = ax.last_angle, (now_s, value)
            rate = 0.0
            if last is not None and now_s > last[0]:
                rate = (value - last[1]) / (now_s - last[0])
            # Motor side as MotorConfig.steer_to_motor_rad; the speed within max_rpm.
            m = ax.motor
            limit = m.max_rpm / 60.0
            ff = min(max(rate * ax.scale / TAU, -limit), limit)
            out.append(codec.make_set_input_pos(ax.node_id, m.steer_to_motor_rad(value) / TAU, ff))
        return out

    def _poll(self, now_s: float) -> list[Frame]:
        """The watchdog setups' steps, RTR encoder requests (``encoder_request: rtr``), error
        queries and enable retries."""
        frames, self._queued = self._queued, []
        codec = self.codec
        for ax in self._axes:
            if ax.arm_waits:
                frames.extend(self._watchdog_step(ax, now_s))
            if ax.rtr:
                frames.append(codec.make_request(ax.node_id, CmdId.GET_ENCODER_ESTIMATES))
            if ax.error_request_due:
                ax.error_request_due = False
                frames.append(codec.make_request(ax.node_id, CmdId.GET_ERROR))
            if ax.enabling and ax.retry_due(now_s):
                i = ax.index
                frames.extend(
                    ax.retry(codec, now_s, self.live.alive(i, now_s), bool(self.faults(i)))
                )
                if ax.refusal:  # it gave up: a fault that says why, until the next enable
                    self._publish_fault(ax, self.faults(i))
        return frames

    def _watchdog_step(self, ax: Axis, now_s: float) -> list[Frame]:
        """Drive one axis' watchdog setup; once it ends, arm the axis if :meth:`may_arm`
        (the base reports a failure after this poll)."""
        wd = ax.watchdog
        assert wd is not None
        frames = wd.poll(now_s)
        i = ax.index
        state = wd.state
        if state is ProtectionState.PENDING:
            return frames
        if state is ProtectionState.CONFIRMED:
            log.info(
                'ODrive node %d ("%s"): watchdog %g s confirmed; arming',
                ax.node_id, ax.motor.wheel, wd.timeout_s,
            )
        return [*frames, *ax.settled(self.codec, now_s, self.live.alive(i, now_s), self.may_arm(i))]

    # ----------------------------------------------------------------- frames

    def claims(self) -> tuple[FrameClaim, ...]:
        """Every CANSimple message of our nodes (``node_id << 5 | cmd``, any command): the
        replies and cyclic messages :meth:`on_frame` decodes, and another master's commands
        (the gateway's watch for a second commander hears the cyclic ones first)."""
        ext = self._extended_id
        mask = (EXT_MASK if ext else STD_MASK) & ~CMD_MASK
        return tuple(FrameClaim(ax.node_id << CMD_BITS, mask, ext, ax.index) for ax in self._axes)

    def traffic(self, rate_hz: float) -> Traffic:
        """The axes' heartbeats and estimates (:mod:`drivers.odrive.traffic`)."""
        from drivers.odrive.traffic import axis_traffic  # noqa: PLC0415 - check and run only
        return axis_traffic(self.opts, self._extended_id, rate_hz)

    def message_name(self, arbitration_id: int, is_extended_id: bool) -> str | None:
        """The CANSimple command's name (``Get_Encoder_Estimates``; ``cmd 0x04`` for one
        without a name), for a frame of our nodes."""
        if is_extended_id != self._extended_id or arbitration_id >> CMD_BITS not in self._by_node:
            return None
        cmd = arbitration_id & CMD_MASK
        return _NAMES.get(cmd) or f"cmd 0x{cmd:02X}"

    def _on_frame(self, frame: Frame) -> bool:
        """Take a heartbeat, encoder estimate, error reply or watchdog-setup reply of one of
        our axes.

        Frames of the other ID type or of other nodes are not ours.  Of ours, malformed frames
        raise :class:`DecodeError` (the base counts them); remote frames other than the
        requests this driver sends itself are counted in :attr:`rejected`; command frames
        (another master talking to our axes) are ignored here.
        """
        # Every frame of our nodes comes here: encoder estimates, most of the traffic, go from
        # the payload to the wheel feedback without an EncoderEstimates object.
        if frame.is_extended_id != self._extended_id:
            return False
        arb = frame.arbitration_id
        ax = self._by_node.get(arb >> CMD_BITS)
        if ax is None:
            return False
        cmd = arb & CMD_MASK
        if cmd == _ESTIMATES and frame.dlc == 8 and not frame.is_remote_frame:
            pos, vel = unpack_estimates(ax.node_id, frame)
            t, scale = frame.timestamp_s, ax.scale
            if ax.steer:  # the absolute angle, in the axis' own position frame
                angle = ax.motor.motor_to_steer_rad(pos * TAU)
                self.store_feedback(ax.index, WheelFeedback(angle, vel * TAU / scale, t))
                return True
            pos0 = ax.pos0_turns
            if pos0 is None:
                pos0 = ax.pos0_turns = pos
            # float32 - float32 is exact in float64; the wheel angle counts from the first
            # sample.  Motor to wheel side as MotorConfig.motor_to_wheel_rad_s: x * sign / gear.
            self.store_feedback(
                ax.index, WheelFeedback((pos - pos0) * TAU / scale, vel * TAU / scale, t)
            )
            return True
        if frame.is_remote_frame:
            if not (cmd == _GET_ERROR or (ax.rtr and cmd == _ESTIMATES)):
                self.reject("remote frame where data expected")  # not an echo of our request
            return True
        if self._v06 and cmd in _SETUP_REPLIES:
            self._on_setup_reply(ax, cmd, frame)
            return True
        msg = self.codec.decode_reply(ax.node_id, cmd, frame)
        if isinstance(msg, Heartbeat):
            self._on_heartbeat(ax, msg, frame.timestamp_s)
        elif isinstance(msg, (ErrorStatus, MotorErrorStatus)):
            self._on_error_status(ax, msg)
        return True

    def _on_setup_reply(self, ax: Axis, cmd: int, frame: Frame) -> None:
        """A Get_Version or TxSdo data frame of one axis (0.6): to its watchdog setup while one
        runs (a late reply after a disable changes nothing)."""
        wd = ax.watchdog
        if wd is None or frame.dlc == 0:
            return  # no setup, or a Get_Version request (another host's)
        if cmd == CmdId.GET_VERSION:
            version = parse_version(frame.data)
            if version is not None:
                if ax.arm_waits:
                    self._queued.extend(wd.on_version(*version, frame.timestamp_s))
                return
            expected = "8 bytes in Get_Version"
        else:
            reply = parse_sdo(frame.data)
            if reply is not None:
                if ax.arm_waits:
                    wd.on_tx_sdo(reply[1], reply[2])
                return
            expected = "at least 4 bytes in TxSdo"
        raise DecodeError(f"Expected {expected} of ODrive node {ax.node_id}, but got {frame.dlc}.")

    def _on_heartbeat(self, ax: Axis, hb: Heartbeat, t: float) -> None:
        i = ax.index
        self.live.heard(i, 1, t)
        ax.procedure = hb.procedure_result
        armed = ax.armed_by(hb.axis_state, t)  # (CLOSED_LOOP_CONTROL also ends a refusal)
        if not (hb.axis_error or hb.motor_error or hb.encoder_error or hb.controller_error):
            # A healthy axis, nearly every heartbeat: the state the general path below ends in
            # for no error, without its flag mapping and string work.
            ax.error_detail = ax.axis_detail = ""
            ax.error_request_due = False
            ax.reported = DriveFault.NONE  # (the refusal of the last enable, if any, stays)
            self.set_fault(i, DriveFault.CONTROLLER if ax.refusal else DriveFault.NONE, ax.refusal)
            self.set_armed(i, armed)
            return
        fw = self.codec.firmware
        faults, detail = heartbeat_faults(fw, hb)
        if ax.took_error(faults, detail):  # new in its own flags (logged; a refusal is not)
            ax.error_request_due = error_query_adds_detail(fw, hb)
        if faults and ax.enabling and t - ax.enable_sent_s > Axis.ENABLE_GRACE_S:
            ax.enabling = False
        if not faults:
            ax.error_detail = ""
            ax.error_request_due = False
        ax.axis_detail = detail
        self._publish_fault(ax, faults)
        self.set_armed(i, armed)

    def _on_error_status(self, ax: Axis, msg: ErrorStatus | MotorErrorStatus) -> None:
        ax.error_detail = error_reply_detail(self.codec.firmware, msg)
        self._publish_fault(ax, self.faults(ax.index))

    def _publish_fault(self, ax: Axis, faults: DriveFault) -> None:
        if ax.refusal:  # (Axis.refused: the axis stayed idle through every enable attempt)
            faults |= DriveFault.CONTROLLER
        detail = "; ".join(p for p in (ax.axis_detail, ax.error_detail, ax.refusal) if p)
        self.set_fault(ax.index, faults, detail if faults else "")
