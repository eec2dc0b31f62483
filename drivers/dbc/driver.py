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
such as ODrive's ``Axis3_...``).  See :data:`drivers.dbc.options.OPTIONS` for every key,
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

**When wheelgate dies** only the controller's own command timeout stops the motor, and a DBC
file does not say which parameter sets it, so wheelgate cannot set or read it: the motor block
states what was set with the vendor's tool, ``controller_timeout_s: 0.2``
(:attr:`~gateway.core.protection.Guard.STATED`); without it ``wheelgate check`` and the start-up log
warn (:attr:`~gateway.core.protection.Guard.UNSTATED`).  The simulator stops its motor that long
after the last command frame, and holds the last command for ever when none is stated.
"""

from __future__ import annotations

import logging
import math
from typing import TYPE_CHECKING, ClassVar

from drivers.dbc.binding import DatabaseCache, bind_motor
from drivers.dbc.codec import DbcCodec, describe_fault
from drivers.dbc.options import OPTIONS, UnitConversion, motor_where, parse_options
from drivers.dbc.sim import DbcSimulator
from gateway.core.errors import DecodeError, EncodeError
from gateway.core.types import WheelFeedback
from gateway.drive.driver import MotorDriver
from gateway.drive.filters import CanFilter

if TYPE_CHECKING:
    from collections.abc import Mapping, Sequence

    from drivers.dbc.binding import MotorBinding
    from drivers.dbc.codec import DbcReading
    from drivers.dbc.options import DbcOptions
    from gateway.core.options import OptionSpec
    from gateway.core.types import Frame, MotorConfig

log = logging.getLogger(__name__)


class DbcDriver(MotorDriver):
    """Drives every ``driver: dbc`` motor on one bus through the messages of its DBC file.

    The DBC file, messages and signals are checked when the driver is built.  Drive motors
    and steering actuators may be mixed in any order.

    :param motors: the motor blocks, in the order :meth:`command` gets setpoints.
    :raises ConfigError: for a bad key, a missing or invalid DBC file, a name the DBC does
        not have (the message lists the names it has), frame IDs that collide, a drive motor
        without a velocity command, or a steering actuator without a position command or
        whose position signals cannot carry its travel.
    """

    OPTIONS: ClassVar[Mapping[str, OptionSpec]] = OPTIONS
    NODE_ID_RANGE: ClassVar[tuple[int, int]] = (0, 0x7FF)
    STEERING: ClassVar[bool] = True
    PROTOCOL: ClassVar[str] = "DBC"
    TIMEOUT_ACTION: ClassVar[str] = (
        "whatever the controller's firmware does when its command timeout expires"
    )
    TIMEOUT_FIX: ClassVar[str] = (
        "set a command timeout on the controller with its vendor's tool (a DBC file does not "
        "say how) and state it as controller_timeout_s in the motor block"
    )

    def __init__(self, motors: Sequence[MotorConfig]) -> None:
        super().__init__(motors)
        cache = DatabaseCache()
        self._opts: tuple[DbcOptions, ...] = tuple(
            parse_options(m.options, motor_where(m), m.role) for m in self.motors
        )
        self.liveness_s = self._opts[0].liveness_s if self._opts else self.liveness_s
        self._units = tuple(
            UnitConversion.build(m, o) for m, o in zip(self.motors, self._opts, strict=True)
        )
        self.bindings: tuple[MotorBinding, ...] = tuple(
            bind_motor(m, o, cache, motor_where(m))
            for m, o in zip(self.motors, self._opts, strict=True)
        )
        #: The pure codec for all motors of this driver.
        self.codec = DbcCodec(self.bindings)
        n = len(self.motors)
        self._velocity: list[float | None] = [None] * n
        self._position: list[float | None] = [None] * n
        self._pos_first: list[int | float | None] = [None] * n
        self._pos_last: list[int | float] = [0] * n
        self._pos_total: list[int] = [0] * n
        #: Per steering actuator, the last position command sent (signal units).
        self._target: list[float | None] = [None] * n
        #: Per steering actuator, the absolute motor position last measured (rad).
        self._motor_rad: list[float | None] = [None] * n

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

    # ----------------------------------------------------------------- hooks

    def enable(self, now_s: float) -> list[Frame]:
        """Position-mode selection (steering actuators that configure it), a zero velocity
        command (drive motors) or a hold-where-it-stands position command (steering
        actuators), then the arming frames (if an enable signal is set)."""
        hold = self._hold()
        frames = list(self.codec.encode_mode(self._steer_nodes(), hold))
        for i in range(len(self.motors)):
            self.set_armed(i, True)
        return frames + [f for f in self._with_enable(True, hold) if f not in frames]

    def disable(self, now_s: float) -> list[Frame]:
        """A zero velocity command (drive motors) or a position command where it stands
        (steering actuators), then the disarming frames (if an enable signal is set)."""
        for i in range(len(self.motors)):
            self.set_armed(i, False)
        return self._with_enable(False, self._hold())

    def command(self, wheel_rad_s: Sequence[float], now_s: float) -> list[Frame]:
        """Command frames: a velocity per drive motor (zero while disarmed), a position per
        steering actuator (where it stands while disarmed).

        :param wheel_rad_s: per motor, the wheel speed (rad/s) or the steering angle (rad).
        :raises EncodeError: for the wrong number of setpoints, a setpoint that is not finite,
            or a command outside the signal's range.
        """
        if len(wheel_rad_s) != len(self.motors):
            raise EncodeError(
                f"Expected {len(self.motors)} wheel speeds, but got {len(wheel_rad_s)}."
            )
        commands: dict[int, float] = {}
        for i, (m, value) in enumerate(zip(self.motors, wheel_rad_s, strict=True)):
            if m.steering:
                commands[m.node_id] = self._steer_command(i, m, value)
                continue
            if not math.isfinite(value):
                raise EncodeError(
                    f'Expected a finite speed for node {m.node_id} ("{m.wheel}"), '
                    f"but got {value!r}."
                )
            commands[m.node_id] = self._units[i].wheel_to_command(value) if self._armed[i] else 0.0
        return list(self.codec.encode_command(commands, self._armed_map()))

    def receive_filters(self) -> tuple[CanFilter, ...]:
        """The feedback messages of the motors' DBC bindings (exact frame IDs and types)."""
        return tuple(CanFilter.exact(i, ext) for i, ext in sorted(self.codec.received_ids))

    def on_frame(self, frame: Frame) -> bool:
        """Take feedback; malformed frames of configured messages are counted, never raised."""
        try:
            readings = self.codec.decode(frame)
        except DecodeError as err:
            self.reject("malformed", err)
            return True
        if readings is None:
            return False
        for reading in readings:
            index = self.index_of(reading.node_id)
            if index is not None:
                self._take(index, reading, frame.timestamp_s)
        return True

    @classmethod
    def make_simulator(cls, motor: MotorConfig) -> DbcSimulator:
        """A generic simulator of ``motor`` that speaks its DBC messages and stops the motor
        ``controller_timeout_s`` after the last command, if the block states one (else never)."""
        return DbcSimulator(motor)

    # ----------------------------------------------------------------- internals

    def _nodes(self) -> list[int]:
        return [m.node_id for m in self.motors]

    def _steer_nodes(self) -> list[int]:
        return [m.node_id for m in self.motors if m.steering]

    def _armed_map(self) -> dict[int, bool]:
        return {m.node_id: self._armed[i] for i, m in enumerate(self.motors)}

    def _steer_command(self, i: int, m: MotorConfig, angle: float) -> float:
        """The position command value (signal units) for steering angle ``angle`` (rad)."""
        if not math.isfinite(angle):
            raise EncodeError(
                f'Expected a finite steering angle in rad for node {m.node_id} ("{m.wheel}"), '
                f"but got {angle!r}."
            )
        if not self._armed[i]:
            return self._hold_value(i)
        value = self._units[i].motor_to_target(m.steer_to_motor_rad(angle))
        self._target[i] = value
        return value

    def _hold_value(self, i: int) -> float:
        """Where steering actuator ``i`` stands (signal units): measured, else the last
        command, else its neutral position."""
        measured = self._motor_rad[i]
        if measured is not None:
            return self._units[i].motor_to_target(measured)
        last = self._target[i]
        if last is not None:
            return last
        return self._units[i].motor_to_target(self.motors[i].zero_rad)

    def _hold(self) -> dict[int, float]:
        return {m.node_id: self._hold_value(i) for i, m in enumerate(self.motors) if m.steering}

    def _with_enable(self, enable: bool, hold: Mapping[int, float]) -> list[Frame]:
        """Zero (or hold) commands, then arming frames (those not already sent: the enable
        signal may share the command message)."""
        commands = {
            m.node_id: hold[m.node_id] if m.steering else 0.0 for m in self.motors
        }
        frames = list(self.codec.encode_command(commands, self._armed_map()))
        frames += [
            f for f in self.codec.encode_enable(self._nodes(), enable, hold) if f not in frames
        ]
        return frames

    def _take(self, i: int, reading: DbcReading, timestamp_s: float) -> None:
        binding = self.bindings[i]
        if reading.fault is not None and binding.fault is not None:
            flags, detail = describe_fault(binding.fault.signal, reading.fault)
            if flags and not self._faults[i]:
                log.warning("node %d (%s) reports %s", binding.node_id, binding.label, detail)
                self.set_armed(i, False)
            self.set_fault(i, flags, detail)
        if reading.velocity is not None:
            self._velocity[i] = self._units[i].velocity_to_wheel(reading.velocity)
        if reading.position_raw is not None:
            self._position[i] = self._angle(i, reading.position_raw)
        vel, pos = self._velocity[i], self._position[i]
        if (
            vel is not None
            and pos is not None
            and (reading.velocity is not None or reading.position_raw is not None)
        ):
            self.store_feedback(i, WheelFeedback(pos, vel, timestamp_s))

    def _angle(self, i: int, raw: int | float) -> float:
        """The wheel angle (drive motor, from the first sample) or the steering angle
        (steering actuator, absolute) for a raw position value (rad)."""
        steps = self._unwrap(i, raw)
        ref = self.bindings[i].position
        if not self.motors[i].steering:
            return self._units[i].position_to_wheel(steps * ref.scale)
        base = ref.to_physical(self._base_raw(i))
        motor_rad = self._units[i].position_to_motor(base + steps * ref.scale)
        self._motor_rad[i] = motor_rad
        return self.motors[i].motor_to_steer_rad(motor_rad)

    def _base_raw(self, i: int) -> int | float:
        """The absolute raw value of steering actuator ``i``'s first sample.

        A counter that wraps modulo ``2**position_wrap_bits`` gives the position only up to
        whole wraps: of the values it may stand for, take the one nearest the neutral position
        ``zero_rad`` (exact while the travel is shorter than half a wrap either way, which
        :func:`~drivers.dbc.binding.check_travel` ensures).
        """
        first = self._pos_first[i]
        if first is None:
            raise DecodeError(f"No position sample yet for node {self.motors[i].node_id}.")
        bits = self._opts[i].position_wrap_bits
        if not bits or not isinstance(first, int):
            return first
        ref, units = self.bindings[i].position, self._units[i]
        zero_phys = units.motor_to_position(self.motors[i].zero_rad)
        zero_raw = (zero_phys - float(ref.signal.offset)) / ref.scale
        modulus = 1 << bits
        return first + round((zero_raw - first) / modulus) * modulus

    def _unwrap(self, i: int, raw: int | float) -> int | float:
        """Raw steps since the first sample, undoing counter wrap-around exactly."""
        first = self._pos_first[i]
        if first is None:
            self._pos_first[i] = first = raw
            self._pos_last[i] = raw
            self._pos_total[i] = 0
        bits = self._opts[i].position_wrap_bits
        if bits and isinstance(raw, int):
            modulus = 1 << bits
            step = (raw - int(self._pos_last[i])) % modulus
            if step >= modulus // 2:
                step -= modulus
            self._pos_total[i] += step
            self._pos_last[i] = raw
            return self._pos_total[i]
        return raw - first
