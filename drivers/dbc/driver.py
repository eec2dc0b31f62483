"""The stateful half of the generic DBC driver: units, arming, unwrapping, fault state.

Any controller whose CAN messages are described in a DBC file can drive a wheel: the motor
block names the file, the message and signal of the velocity command, the message(s) and
signals of the velocity and position feedback, and their units.  For example (the fictional
controller of ``config/example_controller.dbc``)::

    motor:
      driver: dbc
      node_id: 3
      gear_ratio: 10.0
      dbc: example_controller.dbc      # relative to config_dir, else to the cwd
      command_message: WD_Velocity_Command
      command_signal: Target_Velocity
      command_unit: rpm
      feedback_message: WD_Feedback
      velocity_signal: Actual_Velocity
      velocity_unit: rpm
      position_signal: Position_Count
      position_unit: counts
      counts_per_rev: 4096
      position_wrap_bits: 32
      enable_message: WD_Enable
      enable_signal: Enable
      fault_signal: Fault_Code

Frame IDs on the wire are the DBC ID plus ``node_id << node_id_shift`` (``node_id_in_frame:
add``, the default) or the DBC IDs as they are (``none``, for DBCs with one message per node
such as ODrive's ``Axis3_...``).  See :class:`drivers.dbc.options.DbcOptions` for every key,
Vector's "DBC File Format Documentation" for the format and https://cantools.readthedocs.io/
for the codec library.

A steering actuator (a ``steering:`` block, :attr:`DbcDriver.STEERING`) names its position
command instead of a velocity command, e.g. an ODrive axis through the official DBC::

    steering:
      front_left:
        driver: dbc
        node_id: 5
        gear_ratio: 12.8
        max_rpm: 3000
        dbc: odrive-cansimple.dbc
        node_id_in_frame: none
        position_command_message: Axis5_Set_Input_Pos
        position_command_signal: Input_Pos
        position_command_unit: rev
        position_mode_message: Axis5_Set_Controller_Mode
        position_mode_values: {Control_Mode: 3, Input_Mode: 1}   # POSITION, PASSTHROUGH
        feedback_message: Axis5_Get_Encoder_Estimates
        velocity_signal: Vel_Estimate
        velocity_unit: rev/s
        position_signal: Pos_Estimate
        position_unit: rev
        enable_message: Axis5_Set_Axis_State
        enable_signal: Axis_Requested_State
        enable_value: 8                  # CLOSED_LOOP_CONTROL
        disable_value: 1                 # IDLE

Its position is absolute in the controller's frame (``zero_rad`` is defined there): the first
sample is taken as it is, and counter wrap-around is undone from there on.

An enable (and a mode) message is sent once per enable and is not answered: a controller that
is silent when the gateway enables it (powered after the gateway) gets them again once it is
heard (:meth:`DbcDriver._poll`).

**When wheelgate dies** only the controller's own command timeout stops the motor, and a DBC
file does not say which parameter sets it, so wheelgate cannot set or read it: the motor block
states what was set with the vendor's tool, ``controller_timeout_s: 0.2``
(:attr:`~gateway.core.protection.Guard.STATED`); without it ``wheelgate check`` and the start-up log
warn (:attr:`~gateway.core.protection.Guard.UNSTATED`).  The simulator stops its motor that long
after the last command frame, and holds the last command for ever when none is stated.

Each motor's state is one :class:`~drivers.dbc.axis.Axis`.  The frames of the driver are the
messages its motors bind (:meth:`DbcDriver.claims`): the feedback messages it takes, the
command, mode and enable messages it sends, named as in the DBC file
(:meth:`DbcDriver.message_name`).
"""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING, ClassVar, cast

from drivers.dbc.axis import Axis
from drivers.dbc.binding import bind_motor
from drivers.dbc.codec import DbcCodec, describe_fault
from drivers.dbc.database import DatabaseCache
from drivers.dbc.options import DbcOptions, motor_where, parse_options
from gateway.core.errors import EncodeError
from gateway.core.types import WheelFeedback
from gateway.drive.claims import FrameClaim
from gateway.drive.driver import MotorDriver

if TYPE_CHECKING:
    from collections.abc import Mapping, Sequence
    from typing import Any

    from drivers.dbc.binding import MotorBinding
    from drivers.dbc.frames import FeedbackSlot
    from gateway.core.types import Frame, MotorConfig
    from gateway.drive.options import DriverOptions
    from gateway.drive.traffic import Traffic

log = logging.getLogger(__name__)


class DbcDriver(MotorDriver[DbcOptions]):
    """Drives every ``driver: dbc`` motor on one bus through the messages of its DBC file.

    The DBC file, messages and signals are checked when the driver is built.  Drive motors
    and steering actuators may be mixed in any order.

    :param motors: the motor blocks, in the order :meth:`command` gets setpoints.
    :raises ConfigError: for a bad key, a missing or invalid DBC file, a name the DBC does
        not have (the message lists the names it has), frame IDs that collide, a drive motor
        without a velocity command, or a steering actuator without a position command or
        whose position signals cannot carry its travel.
    """

    Options: ClassVar[type[DriverOptions]] = DbcOptions
    NODE_ID_RANGE: ClassVar[tuple[int, int]] = (0, 0x7FF)
    STEERING: ClassVar[bool] = True
    PROTOCOL: ClassVar[str] = "DBC"
    #: Velocity and position may come in two messages: a motor is OFFLINE while either is
    #: older than ``liveness_s`` (one message that stopped must not leave the other's value
    #: standing as fresh feedback).
    LIVENESS_STREAMS: ClassVar[tuple[str, ...]] = ("velocity", "position")
    SPEED_STREAM: ClassVar[int | None] = 0
    TIMEOUT_ACTION: ClassVar[str] = (
        "whatever the controller's firmware does when its command timeout expires"
    )
    TIMEOUT_FIX: ClassVar[str] = (
        "set a command timeout on the controller with its vendor's tool (a DBC file does not "
        "say how) and state it as controller_timeout_s in the motor block"
    )

    def __init__(self, motors: Sequence[MotorConfig]) -> None:
        motors = tuple(motors)
        for m in motors:  # the rules between keys and of the role, named by the block's path
            parse_options(m.options, motor_where(m), m.role)
        super().__init__(motors)
        cache = DatabaseCache()
        self.bindings: tuple[MotorBinding, ...] = tuple(
            bind_motor(m, o, cache, motor_where(m))
            for m, o in zip(self.motors, self.opts, strict=True)
        )
        #: The pure codec for all motors of this driver.
        self.codec = DbcCodec(self.bindings)
        self._axes = tuple(
            Axis(m, o, b) for m, o, b in zip(self.motors, self.opts, self.bindings, strict=True)
        )
        self._rx = self.codec.rx
        #: Per motor, the command signal value of this cycle (reused).
        self._values: list[float] = [0.0] * len(self.motors)
        #: The motors that were silent when they were enabled (see :meth:`_poll`).
        self._unreached: set[int] = set()
        self._claims = self._declare()
        self._names = {
            (g.frame_id, g.extended): str(g.message.name)
            for g in (*self.codec.rx.values(), *self.codec.tx.values())
        }

    @classmethod
    def validate_options(cls, raw: Mapping[str, object], where: str) -> dict[str, object]:
        """Validate the protocol keys, including the rules between keys (no file access).

        The role of the block is not known here, so a block needs a velocity command or a
        position command; the driver checks the one its role needs.

        :raises ConfigError: naming the key.
        """
        out = super().validate_options(raw, where)
        parse_options(out, where)
        return out

    # ----------------------------------------------------------------- frames

    def _declare(self) -> tuple[FrameClaim, ...]:
        """The feedback messages (sorted by ID) and the command messages (in configuration
        order), each of one motor or, shared, of none."""
        rx = sorted(self.codec.rx.values(), key=lambda g: (g.frame_id, g.extended))
        out = []
        for receive, groups in ((True, rx), (False, list(self.codec.tx.values()))):
            for g in groups:
                owners = {m.index for m in g.members}
                motor = owners.pop() if len(owners) == 1 else None
                out.append(FrameClaim.exact(g.frame_id, g.extended, motor, receive))
        return tuple(out)

    def claims(self) -> tuple[FrameClaim, ...]:
        """The messages the motors bind: the feedback, velocity, position and fault messages
        it takes (``receive=True``), the command, mode and enable messages it sends."""
        return self._claims

    def message_name(self, arbitration_id: int, is_extended_id: bool) -> str | None:
        """The DBC file's name of a claimed message (``WD_Feedback``)."""
        return self._names.get((arbitration_id, is_extended_id))

    def traffic(self, rate_hz: float) -> Traffic:
        """The received messages at their DBC cycle times (:mod:`drivers.dbc.traffic`)."""
        from drivers.dbc.traffic import received_traffic  # noqa: PLC0415 - check and run only
        return received_traffic(self.codec.rx.values())

    # ----------------------------------------------------------------- hooks

    def _enable(self, now_s: float) -> list[Frame]:
        """Position-mode selection (steering actuators that configure it), a zero velocity
        command (drive motors) or a hold-where-it-stands position command (steering
        actuators), then the arming frames (if an enable signal is set)."""
        hold = self._hold()
        frames = self.codec.encode_mode(hold)
        for i in range(len(self.motors)):
            self.set_armed(i, True)
        self._unreached = {i for i in range(len(self.motors)) if not self.live.alive(i, now_s)}
        return frames + [f for f in self._with_enable(True, hold) if f not in frames]

    def _poll(self, now_s: float) -> list[Frame]:
        """The mode and enable messages again, once a motor that was silent when it was enabled
        is heard: a controller powered after the gateway missed them, and neither is answered.
        (Not the command messages, which go out every cycle with the motors' own values.)"""
        if not self._unreached:
            return []
        heard = {i for i in self._unreached if self.live.alive(i, now_s)}
        if not heard:
            return []
        self._unreached -= heard
        if not any(self.is_armed(i) for i in heard):
            return []
        hold = self._hold()
        try:
            frames = [*self.codec.encode_mode(hold), *self.codec.encode_enable(True, hold)]
        except EncodeError:  # a steering actuator whose position is not known yet
            self._unreached |= heard
            return []
        commands = self.codec.command_ids
        return [f for f in frames if f.arbitration_id not in commands]

    def disable(self, now_s: float) -> list[Frame]:
        """A zero velocity command (drive motors) or a position command where it stands
        (steering actuators), then the disarming frames (if an enable signal is set)."""
        self._unreached = set()
        for i in range(len(self.motors)):
            self.set_armed(i, False)
        return self._with_enable(False, self._hold())

    def _command(self, setpoints: Sequence[float], now_s: float) -> list[Frame]:
        """A velocity per drive motor (zero while disarmed), a position per steering actuator
        (where it stands while disarmed).

        :raises EncodeError: for a command outside the signal's range.
        """
        values, armed = self._values, self._armed
        for i, ax in enumerate(self._axes):
            if not ax.steering:
                values[i] = ax.units.wheel_to_command(setpoints[i]) if armed[i] else 0.0
            elif armed[i]:
                values[i] = ax.target = ax.units.motor_to_target(
                    ax.motor.steer_to_motor_rad(setpoints[i]))
            else:
                values[i] = ax.hold_value()
        return self.codec.encode_command(values, armed)

    def _on_frame(self, frame: Frame) -> bool:
        """Take the feedback messages of the motors' bindings."""
        group = self._rx.get(frame.arbitration_id)
        if group is None or frame.is_extended_id != group.extended:
            return False  # another ID, or the same number as the other ID type: not ours
        raw = group.read(frame)  # DecodeError: malformed, counted by on_frame
        for slot in group.slots:
            self._take(slot, raw, frame.timestamp_s)
        return True

    # ----------------------------------------------------------------- internals

    def _take(self, slot: FeedbackSlot, raw: Mapping[str, Any], timestamp_s: float) -> None:
        i = slot.index
        ax = self._axes[i]
        if slot.fault is not None:
            code = int(raw[slot.fault])
            if code != ax.fault_code:
                ax.fault_code = code
                self._fault(i, ax, slot.fault_signal, code)
        velocity, position = slot.velocity, slot.position
        if velocity is None and position is None:
            return
        if velocity is not None:
            ax.velocity = ax.units.velocity_to_wheel(raw[velocity] * slot.scale + slot.offset)
            self.live.heard(i, 0, timestamp_s)
        if position is not None:
            ax.position = ax.angle(raw[position])
            self.live.heard(i, 1, timestamp_s)
        # Once both were heard, stamped with the position's time (a velocity message apart
        # refreshes the speed only): when its stream was heard.
        if ax.velocity is not None and ax.position is not None:
            pos_s = cast("float", self.live.times[i][1])
            self.store_feedback(i, WheelFeedback(ax.position, ax.velocity, pos_s), None)

    def _fault(self, i: int, ax: Axis, signal: Any, code: int) -> None:
        """A new fault code of motor ``i`` (in the cantools ``signal``): its flags and text;
        a fault disarms the motor."""
        flags, detail = describe_fault(signal, code)
        if flags and not self.faults(i):
            log.warning("node %d (%s) reports %s", ax.binding.node_id, ax.binding.label, detail)
            self.set_armed(i, False)
        self.set_fault(i, flags, detail)

    def _hold(self) -> list[float | None]:
        """Per motor, where a steering actuator stands (signal units); ``None`` for a drive
        motor."""
        return [ax.hold_value() if ax.steering else None for ax in self._axes]

    def _with_enable(self, enable: bool, hold: list[float | None]) -> list[Frame]:
        """Zero (or hold) commands, then arming frames (those not already sent: the enable
        signal may share the command message)."""
        commands = [0.0 if h is None else h for h in hold]
        frames = self.codec.encode_command(commands, self._armed)
        frames += [f for f in self.codec.encode_enable(enable, hold) if f not in frames]
        return frames
