"""Pure codec of ODrive "CANSimple" (firmware 0.5.x and 0.6.x): no I/O, no clock.

Reference: the `ODrive CAN protocol
<https://docs.odriverobotics.com/v/latest/manual/can-protocol.html>`_, the 0.5.x
`can_simple.cpp <https://github.com/odriverobotics/ODrive/blob/master/Firmware/communication/
can/can_simple.cpp>`_ and the official DBC ``odrive-cansimple.dbc`` (0.5.6); summarised with
worked frames in the ODrive CAN protocol documentation (docs.odriverobotics.com, can-protocol).

Arbitration ID = ``node_id << 5 | cmd_id``, with 11-bit IDs (node 0..0x3F) or, when the axis is
configured ``is_extended``, 29-bit IDs (node 0..0xFFFFFF).  The firmware ignores frames whose IDE
flag does not match its configuration, so this codec treats them as "not mine".  Every payload
is little endian; floats are IEEE-754 float32.

Each message is described once, as a :class:`~drivers.odrive.messages.Layout` in
:mod:`drivers.odrive.messages`; the encoders and decoders here derive from those tables.
"""

from __future__ import annotations

import math
from types import MappingProxyType
from typing import TYPE_CHECKING

from drivers.odrive.enums import AxisState, CmdId, ControlMode, Firmware, InputMode, ProcedureResult
from drivers.odrive.messages import (
    CLEAR_ERRORS_05,
    CLEAR_ERRORS_06,
    CMD_BITS,
    CMD_MASK,
    CONTROLLER_ERROR_05,
    DEFAULT_EXTENDED_ID,
    DEFAULT_FIRMWARE,
    ENCODER_ESTIMATES,
    ESTOP,
    GET_ERROR_06,
    GET_MOTOR_ERROR_05,
    HEARTBEAT,
    MAX_EXTENDED_NODE_ID,
    MAX_STANDARD_NODE_ID,
    SET_AXIS_STATE,
    SET_CONTROLLER_MODE,
    SET_INPUT_POS,
    SET_INPUT_VEL,
    TRAJ_DONE_05,
    TRANSITIONS,
    EncoderEstimates,
    ErrorStatus,
    Feedback,
    Heartbeat,
    Layout,
    MotorErrorStatus,
    Step,
    check_float32,
    check_u32,
    ff_counts,
)
from gateway.core.errors import ConfigError, DecodeError, EncodeError, IllegalTransitionError
from gateway.core.types import Frame, frame_of

if TYPE_CHECKING:
    from collections.abc import Iterable, Mapping, Sequence

#: Bound methods of the two messages on the hot path (a command per wheel per cycle, an
#: estimate per wheel per feedback period): one attribute lookup fewer each.
_SET_INPUT_VEL_PACK = SET_INPUT_VEL.packer.pack
_TAU = 2.0 * math.pi
_ESTIMATES_UNPACK = ENCODER_ESTIMATES.packer.unpack


#: Value -> member of the enums a heartbeat carries: a dict lookup per heartbeat instead of
#: an enum call (and a caught ``ValueError`` for values this firmware's enum lacks).
_AXIS_STATES: Mapping[int, AxisState] = MappingProxyType({int(s): s for s in AxisState})
_PROCEDURE_RESULTS: Mapping[int, ProcedureResult] = MappingProxyType(
    {int(r): r for r in ProcedureResult}
)


class OdriveCodec:
    """Frames of one ODrive CAN bus configuration.

    :param firmware: firmware family of the axes (heartbeat layout, Clear_Errors DLC, 0x03).
    :param extended_id: 29-bit identifiers (``axis.config.can.is_extended``).
    """

    def __init__(
        self, firmware: Firmware = DEFAULT_FIRMWARE, extended_id: bool = DEFAULT_EXTENDED_ID
    ) -> None:
        self.firmware = firmware
        self.extended_id = extended_id
        self.max_node_id = MAX_EXTENDED_NODE_ID if extended_id else MAX_STANDARD_NODE_ID
        self.clear_errors_layout = CLEAR_ERRORS_06 if firmware is Firmware.V0_6 else CLEAR_ERRORS_05
        self.error_layout = GET_ERROR_06 if firmware is Firmware.V0_6 else GET_MOTOR_ERROR_05
        self._feedback: dict[int, Layout] = {
            HEARTBEAT.cmd: HEARTBEAT,
            ENCODER_ESTIMATES.cmd: ENCODER_ESTIMATES,
            self.error_layout.cmd: self.error_layout,
        }

    @classmethod
    def from_options(cls, options: Mapping[str, object]) -> OdriveCodec:
        """The codec for a motor block's ``firmware`` and ``extended_id`` keys.

        :raises ConfigError: for an unknown firmware family.
        """
        value = options.get("firmware", DEFAULT_FIRMWARE.value)
        try:
            firmware = Firmware(value)
        except ValueError as err:
            known = ", ".join(repr(f.value) for f in Firmware)
            raise ConfigError(f"firmware: expected one of {known}, got {value!r}") from err
        return cls(firmware, bool(options.get("extended_id", DEFAULT_EXTENDED_ID)))

    # ------------------------------------------------------------------ identifiers

    def arbitration_id(self, node_id: int, cmd: int) -> int:
        """``node_id << 5 | cmd``.

        :raises EncodeError: if ``node_id`` does not fit this ID mode.
        """
        if not 0 <= node_id <= self.max_node_id:
            kind = "29-bit" if self.extended_id else "11-bit"
            raise EncodeError(
                f"Expected ODrive node ID between 0 and {self.max_node_id:#x} with {kind} "
                f"identifiers, but got {node_id!r}."
            )
        return node_id << CMD_BITS | cmd

    def split_id(self, frame: Frame) -> tuple[int, int] | None:
        """``(node_id, cmd_id)`` of a frame, or ``None`` if its IDE flag is not this mode's."""
        if frame.is_extended_id != self.extended_id:
            return None
        return frame.arbitration_id >> CMD_BITS, frame.arbitration_id & CMD_MASK

    def _frame(self, node_id: int, layout: Layout, *values: float) -> Frame:
        return Frame(
            self.arbitration_id(node_id, layout.cmd), layout.pack(*values), self.extended_id
        )

    # ------------------------------------------------------------------ host -> axis

    def make_set_input_vel(
        self, node_id: int, vel_turns_s: float, torque_ff_nm: float = 0.0
    ) -> Frame:
        """Set_Input_Vel.

        :param vel_turns_s: velocity set point in turns/s (finite float32).
        :param torque_ff_nm: torque feed-forward in N*m (finite float32).
        :raises EncodeError: for a non-finite or out-of-float32-range value, or a bad node ID.
        """
        check_float32("Input_Vel", node_id, vel_turns_s, "turns/s")
        check_float32("Input_Torque_FF", node_id, torque_ff_nm, "Nm")
        return self._frame(node_id, SET_INPUT_VEL, vel_turns_s, torque_ff_nm)

    def set_input_vels(
        self, axes: Sequence[tuple[int, float]], setpoints: Iterable[float]
    ) -> list[Frame]:
        """Set_Input_Vel without torque feed-forward for many axes at once, the frames of every
        cycle: ``(arbitration ID, scale)`` per axis (the ID from :meth:`arbitration_id`), the
        velocity in turns/s is ``setpoint * scale / (2 pi)`` (rad/s to turns/s).

        The caller guarantees finite velocities and valid identifiers (the driver's checked
        setpoints and configured nodes); a velocity beyond float32 is an :class:`EncodeError`.
        """
        pack, ext = _SET_INPUT_VEL_PACK, self.extended_id
        try:
            return [frame_of((arb, pack(w * k / _TAU, 0.0), ext, False, 8, 0.0))
                    for (arb, k), w in zip(axes, setpoints)]  # noqa: B905 - count checked
        except OverflowError as err:  # a max_rpm beyond float32 turns/s
            raise EncodeError(f"Expected Input_Vel within float32 in turns/s: {err}.") from err

    def make_set_input_pos(
        self,
        node_id: int,
        pos_turns: float,
        vel_ff_turns_s: float = 0.0,
        torque_ff_nm: float = 0.0,
    ) -> Frame:
        """Set_Input_Pos: a position set point with speed and torque feed-forward.

        :param pos_turns: position set point in turns (finite float32).
        :param vel_ff_turns_s: speed feed-forward in turns/s, sent in steps of 0.001 and
            clipped to +-32.767 (int16); a feed-forward only shapes the approach.
        :param torque_ff_nm: torque feed-forward in N*m, as ``vel_ff_turns_s``.
        :raises EncodeError: for a non-finite position or feed-forward, or a bad node ID.
        """
        check_float32("Input_Pos", node_id, pos_turns, "turns")
        check_float32("Vel_FF", node_id, vel_ff_turns_s, "turns/s")
        check_float32("Torque_FF", node_id, torque_ff_nm, "Nm")
        return self._frame(
            node_id, SET_INPUT_POS, pos_turns, ff_counts(vel_ff_turns_s), ff_counts(torque_ff_nm)
        )

    def make_set_axis_state(self, node_id: int, state: int) -> Frame:
        """Set_Axis_State, DLC 8.

        :raises EncodeError: if ``state`` is not a u32 or the node ID is bad.
        """
        check_u32("Axis_Requested_State", node_id, state)
        return self._frame(node_id, SET_AXIS_STATE, state)

    def make_set_controller_mode(self, node_id: int, control_mode: int, input_mode: int) -> Frame:
        """Set_Controller_Mode.

        :raises EncodeError: if a mode is not a u32 or the node ID is bad.
        """
        check_u32("Control_Mode", node_id, control_mode)
        check_u32("Input_Mode", node_id, input_mode)
        return self._frame(node_id, SET_CONTROLLER_MODE, control_mode, input_mode)

    def make_clear_errors(self, node_id: int, identify: bool = False) -> Frame:
        """Clear_Errors: DLC 0 in 0.5, one ``Identify`` byte in 0.6 (ignored in 0.5)."""
        if self.firmware is Firmware.V0_6:
            return self._frame(node_id, CLEAR_ERRORS_06, int(identify))
        return self._frame(node_id, CLEAR_ERRORS_05)

    def make_estop(self, node_id: int) -> Frame:
        """Estop (DLC 0): the axis disarms with ESTOP_REQUESTED."""
        return self._frame(node_id, ESTOP)

    def make_request(self, node_id: int, cmd: CmdId) -> Frame:
        """An RTR request (DLC 0) for ``cmd``; the axis answers with a data frame on the same ID."""
        return Frame(self.arbitration_id(node_id, cmd), b"", self.extended_id, is_remote_frame=True)

    def make_transition(
        self,
        node_id: int,
        current: AxisState | int,
        requested: AxisState,
        input_mode: InputMode = InputMode.PASSTHROUGH,
        control_mode: ControlMode = ControlMode.VELOCITY_CONTROL,
    ) -> tuple[Frame, ...]:
        """The frames that take an axis from ``current`` to ``requested`` (:data:`TRANSITIONS`).

        :param current: the axis state last reported (``UNDEFINED`` when unknown).
        :param requested: ``IDLE`` or ``CLOSED_LOOP_CONTROL``.
        :param input_mode: input mode selected when arming.
        :param control_mode: control mode selected when arming (position for a steering
            actuator).
        :raises IllegalTransitionError: for a pair the table does not allow.
        """
        step = TRANSITIONS.get((current, requested)) if isinstance(current, AxisState) else None
        if step is None and requested is AxisState.IDLE:
            step = Step.DISARM  # an unknown (newer) state can always be left for IDLE
        if step is None:
            cur = current.name if isinstance(current, AxisState) else str(current)
            raise IllegalTransitionError(
                f"Expected ODrive node {node_id} in IDLE, CLOSED_LOOP_CONTROL or UNDEFINED to "
                f"request {requested.name}, but it is in {cur}."
            )
        if step is Step.DISARM:
            return (
                self.make_set_input_vel(node_id, 0.0),
                self.make_set_axis_state(node_id, AxisState.IDLE),
            )
        return (
            self.make_clear_errors(node_id),
            self.make_set_controller_mode(node_id, control_mode, input_mode),
            self.make_set_axis_state(node_id, AxisState.CLOSED_LOOP_CONTROL),
        )

    # ------------------------------------------------------------------ axis -> host

    def make_heartbeat(self, hb: Heartbeat) -> Frame:
        """The heartbeat frame an axis of this firmware sends (used by the simulator)."""
        if self.firmware is Firmware.V0_6:
            tail = (int(hb.procedure_result), int(hb.trajectory_done), 0)
        else:
            flags7 = (TRAJ_DONE_05 if hb.trajectory_done else 0) | int(hb.controller_error)
            tail = (int(hb.motor_error), int(hb.encoder_error), flags7)
        check_u32("Axis_Error", hb.node_id, hb.axis_error)
        return self._frame(hb.node_id, HEARTBEAT, hb.axis_error, int(hb.axis_state), *tail)

    def make_encoder_estimates(self, node_id: int, pos_turns: float, vel_turns_s: float) -> Frame:
        """Get_Encoder_Estimates reply (both values rounded to float32 like the firmware's)."""
        check_float32("Pos_Estimate", node_id, pos_turns, "turns")
        check_float32("Vel_Estimate", node_id, vel_turns_s, "turns/s")
        return self._frame(node_id, ENCODER_ESTIMATES, pos_turns, vel_turns_s)

    def make_error_status(self, status: ErrorStatus | MotorErrorStatus) -> Frame:
        """Get_Error (0.6) or Get_Motor_Error (0.5) reply."""
        if isinstance(status, ErrorStatus):
            return self._frame(
                status.node_id, GET_ERROR_06, status.active_errors, status.disarm_reason
            )
        return self._frame(status.node_id, GET_MOTOR_ERROR_05, status.motor_error)

    def decode(self, frame: Frame) -> Feedback | None:
        """Decode a reply: heartbeat, encoder estimates, Get_Error / Get_Motor_Error.

        :return: ``None`` for a frame of the other ID type, any other command ID, and requests
            (RTR frames, and 0.5's DLC 0 data frames), which are not replies.
        :raises DecodeError: for a wrong DLC or a non-finite encoder estimate.
        """
        if frame.is_extended_id != self.extended_id or frame.is_remote_frame:
            return None  # the other ID type (split_id's test), or a request
        arb = frame.arbitration_id
        return self.decode_reply(arb >> CMD_BITS, arb & CMD_MASK, frame)

    def decode_reply(self, node: int, cmd: int, frame: Frame) -> Feedback | None:
        """:meth:`decode` of a data frame whose identifier is already split (and of this ID
        mode): the driver splits every received identifier once, to find the axis.

        :raises DecodeError: as :meth:`decode`.
        """
        layout = self._feedback.get(cmd)
        if layout is None or (frame.dlc == 0 and self.firmware is Firmware.V0_5):
            return None
        if layout is ENCODER_ESTIMATES:
            return EncoderEstimates(node, *unpack_estimates(node, frame))
        values = layout.unpack(node, frame)
        if layout is HEARTBEAT:
            return self._heartbeat(node, values)
        if layout is GET_ERROR_06:
            return ErrorStatus(node, int(values[0]), int(values[1]))
        return MotorErrorStatus(node, int(values[0]))

    def _heartbeat(self, node: int, values: tuple[int, ...]) -> Heartbeat:
        # Every field of the heartbeat's struct is an integer ("<IBBBB"): no int() needed.
        error, state, b5, b6, b7 = values
        axis_state = _AXIS_STATES.get(state, state)
        if self.firmware is Firmware.V0_6:
            result = _PROCEDURE_RESULTS.get(b5, b5)
            return Heartbeat(node, error, axis_state, bool(b6 & 1), result)
        return Heartbeat(
            node,
            error,
            axis_state,
            bool(b7 & TRAJ_DONE_05),
            ProcedureResult.SUCCESS,
            bool(b5 & 1),
            bool(b6 & 1),
            bool(b7 & CONTROLLER_ERROR_05),
        )


def unpack_estimates(node: int, frame: Frame) -> tuple[float, float]:
    """``(position turns, velocity turns/s)`` of a Get_Encoder_Estimates data frame of ``node``.

    The driver's per-frame path: most of the feedback traffic, so it gives the two floats
    without building an :class:`~drivers.odrive.messages.EncoderEstimates`.

    :raises DecodeError: for a wrong DLC or a non-finite estimate.
    """
    data = frame.data
    if frame.dlc != 8 or len(data) != 8:
        ENCODER_ESTIMATES.unpack(node, frame)  # raises, naming the message
    pos, vel = _ESTIMATES_UNPACK(data)
    if not (math.isfinite(pos) and math.isfinite(vel)):
        raise DecodeError(
            f"Expected finite encoder estimates from ODrive node {node}, "
            f"but got position {pos} turns, velocity {vel} turns/s."
        )
    return pos, vel
