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
"""

from __future__ import annotations

import logging
import math
from typing import TYPE_CHECKING, ClassVar

from drivers.dbc.binding import DatabaseCache, bind_motor
from drivers.dbc.codec import DbcCodec, describe_fault
from drivers.dbc.options import OPTIONS, UnitConversion, motor_where, parse_options
from drivers.dbc.sim import DbcSimulator
from gateway.driver import MotorDriver
from gateway.errors import DecodeError, EncodeError
from gateway.types import WheelFeedback

if TYPE_CHECKING:
    from collections.abc import Mapping, Sequence

    from drivers.dbc.binding import MotorBinding
    from drivers.dbc.codec import DbcReading
    from drivers.dbc.options import DbcOptions
    from gateway.options import OptionSpec
    from gateway.types import Frame, MotorConfig

log = logging.getLogger(__name__)


class DbcDriver(MotorDriver):
    """Drives every ``driver: dbc`` motor on one bus through the messages of its DBC file.

    The DBC file, messages and signals are checked when the driver is built.

    :param motors: the motor blocks, in the order :meth:`command` gets speeds.
    :raises ConfigError: for a bad key, a missing or invalid DBC file, a name the DBC does
        not have (the message lists the names it has), or frame IDs that collide.
    """

    OPTIONS: ClassVar[Mapping[str, OptionSpec]] = OPTIONS
    NODE_ID_RANGE: ClassVar[tuple[int, int]] = (0, 0x7FF)

    def __init__(self, motors: Sequence[MotorConfig]) -> None:
        super().__init__(motors)
        cache = DatabaseCache()
        self._opts: tuple[DbcOptions, ...] = tuple(
            parse_options(m.options, motor_where(m)) for m in self.motors
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

    @classmethod
    def validate_options(cls, raw: Mapping[str, object], where: str) -> dict[str, object]:
        """Validate the protocol keys, including the rules between keys (no file access).

        :raises ConfigError: naming the key.
        """
        out = super().validate_options(raw, where)
        parse_options(out, where)
        return out

    # ----------------------------------------------------------------- hooks

    def enable(self, now_s: float) -> list[Frame]:
        """A zero velocity command, then the arming frames (if an enable signal is set)."""
        for i in range(len(self.motors)):
            self.set_armed(i, True)
        return self._with_enable(True)

    def disable(self, now_s: float) -> list[Frame]:
        """A zero velocity command, then the disarming frames (if an enable signal is set)."""
        for i in range(len(self.motors)):
            self.set_armed(i, False)
        return self._with_enable(False)

    def command(self, wheel_rad_s: Sequence[float], now_s: float) -> list[Frame]:
        """Velocity command frames; disarmed motors are commanded zero.

        :raises EncodeError: for the wrong number of speeds, a speed that is not finite, or
            a command outside the signal's range.
        """
        if len(wheel_rad_s) != len(self.motors):
            raise EncodeError(
                f"Expected {len(self.motors)} wheel speeds, but got {len(wheel_rad_s)}."
            )
        commands: dict[int, float] = {}
        for i, (m, speed) in enumerate(zip(self.motors, wheel_rad_s, strict=True)):
            if not math.isfinite(speed):
                raise EncodeError(
                    f'Expected a finite speed for node {m.node_id} ("{m.wheel}"), '
                    f"but got {speed!r}."
                )
            commands[m.node_id] = self._units[i].wheel_to_command(speed) if self._armed[i] else 0.0
        return list(self.codec.encode_command(commands, self._armed_map()))

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
        """A generic simulator of ``motor`` that speaks its DBC messages."""
        return DbcSimulator(motor)

    # ----------------------------------------------------------------- internals

    def _nodes(self) -> list[int]:
        return [m.node_id for m in self.motors]

    def _armed_map(self) -> dict[int, bool]:
        return {m.node_id: self._armed[i] for i, m in enumerate(self.motors)}

    def _with_enable(self, enable: bool) -> list[Frame]:
        """Zero commands, then arming frames (those not already sent: the enable signal may
        share the command message)."""
        frames = self._zero()
        frames += [f for f in self.codec.encode_enable(self._nodes(), enable) if f not in frames]
        return frames

    def _zero(self) -> list[Frame]:
        return list(self.codec.encode_command(dict.fromkeys(self._nodes(), 0.0), self._armed_map()))

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
            self._position[i] = self._unwrap(i, reading.position_raw)
        vel, pos = self._velocity[i], self._position[i]
        if (
            vel is not None
            and pos is not None
            and (reading.velocity is not None or reading.position_raw is not None)
        ):
            self.store_feedback(i, WheelFeedback(pos, vel, timestamp_s))

    def _unwrap(self, i: int, raw: int | float) -> float:
        """Wheel angle (rad) since the first sample, undoing counter wrap-around exactly."""
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
            delta: float = self._pos_total[i]
        else:
            delta = raw - first
        return self._units[i].position_to_wheel(delta * self.bindings[i].position.scale)
