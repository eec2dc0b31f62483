"""One ``driver: dbc`` motor's state in the driver: its keys, units, signals, the last values
heard and the position counter's unwrapping.

A drive motor's position is counted from its first sample; a steering actuator's is absolute
in the controller's frame (``zero_rad`` is defined there): the first sample is taken as it
is, and counter wrap-around is undone from there on.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from drivers.dbc.units import UnitConversion
from gateway.core.errors import DecodeError

if TYPE_CHECKING:
    from drivers.dbc.binding import MotorBinding
    from drivers.dbc.options import DbcOptions
    from gateway.core.types import MotorConfig


@dataclass(slots=True)
class Axis:
    """One motor of a :class:`~drivers.dbc.driver.DbcDriver`.

    :param motor: its motor block.
    :param opts: its protocol keys.
    :param binding: its DBC messages and signals.
    """

    motor: MotorConfig
    opts: DbcOptions
    binding: MotorBinding
    units: UnitConversion = field(init=False)
    #: Whether it is commanded in position (a steering actuator).
    steering: bool = field(init=False)
    #: The raw position counter wraps modulo ``2**position_wrap_bits`` (0: never).
    wrap_bits: int = field(init=False)
    #: The last velocity (wheel rad/s) and angle (rad) heard, ``None`` before the first.
    velocity: float | None = None
    position: float | None = None
    #: The last raw fault code heard (0: healthy).
    fault_code: int = 0
    #: The first raw position sample, the last one, and the raw steps counted since the first.
    pos_first: int | float | None = None
    pos_last: int | float = 0
    pos_total: int = 0
    #: A steering actuator's last position command sent (signal units).
    target: float | None = None
    #: A steering actuator's absolute motor position last measured (rad).
    motor_rad: float | None = None

    def __post_init__(self) -> None:
        self.units = UnitConversion.build(self.motor, self.opts)
        self.steering = self.motor.steering
        self.wrap_bits = self.opts.position_wrap_bits

    def angle(self, raw: int | float) -> float:
        """The wheel angle (drive motor, from the first sample) or the steering angle
        (steering actuator, absolute) for a raw position value (rad)."""
        steps = self._unwrap(raw)
        ref = self.binding.position
        if not self.steering:
            return self.units.position_to_wheel(steps * ref.scale)
        base = ref.to_physical(self._base_raw())
        motor_rad = self.units.position_to_motor(base + steps * ref.scale)
        self.motor_rad = motor_rad
        return self.motor.motor_to_steer_rad(motor_rad)

    def hold_value(self) -> float:
        """Where a steering actuator stands (signal units): measured, else the last command,
        else its neutral position."""
        if self.motor_rad is not None:
            return self.units.motor_to_target(self.motor_rad)
        if self.target is not None:
            return self.target
        return self.units.motor_to_target(self.motor.zero_rad)

    def _base_raw(self) -> int | float:
        """The absolute raw value of a steering actuator's first sample.

        A counter that wraps modulo ``2**position_wrap_bits`` gives the position only up to
        whole wraps: of the values it may stand for, take the one nearest the neutral position
        ``zero_rad`` (exact while the travel is shorter than half a wrap either way, which
        :func:`~drivers.dbc.binding.check_travel` ensures).
        """
        first = self.pos_first
        if first is None:
            raise DecodeError(f"No position sample yet for node {self.motor.node_id}.")
        bits = self.wrap_bits
        if not bits or not isinstance(first, int):
            return first
        ref = self.binding.position
        zero_phys = self.units.motor_to_position(self.motor.zero_rad)
        zero_raw = (zero_phys - float(ref.signal.offset)) / ref.scale
        modulus = 1 << bits
        return first + round((zero_raw - first) / modulus) * modulus

    def _unwrap(self, raw: int | float) -> int | float:
        """Raw steps since the first sample, undoing counter wrap-around exactly."""
        first = self.pos_first
        if first is None:
            self.pos_first = first = raw
            self.pos_last = raw
            self.pos_total = 0
        bits = self.wrap_bits
        if bits and isinstance(raw, int):
            modulus = 1 << bits
            step = (raw - int(self.pos_last)) % modulus
            if step >= modulus // 2:
                step -= modulus
            self.pos_total += step
            self.pos_last = raw
            return self.pos_total
        return raw - first
