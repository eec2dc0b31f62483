"""Unit conversions of a ``driver: dbc`` motor: wheel (or motor) quantities <-> signal values.

:class:`UnitConversion` derives, from the protocol keys (:class:`~drivers.dbc.options.DbcOptions`)
and the motor block (gear ratio, inversion), the factors between wheel rad/s and the values of
the command and feedback signals, in both directions (the driver's and the simulator's).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from drivers.dbc.options import POSITION_UNITS, VELOCITY_UNITS

if TYPE_CHECKING:
    from drivers.dbc.options import DbcOptions
    from gateway.core.types import MotorConfig


@dataclass(frozen=True, slots=True)
class UnitConversion:
    """Factors between wheel quantities and signal values for one motor.

    A command signal value is ``wheel_rad_s * gear * sign * command_per_rad_s`` (motor side)
    or ``wheel_rad_s * sign * command_per_rad_s`` (wheel side); feedback goes the other way
    with its own side.  The simulator uses the inverse functions from the motor shaft
    (:class:`gateway.sim.device.MotorModel` rad and rad/s, already inverted).

    :param command_per_rad_s: command signal value per rad/s on the command side.
    :param velocity_per_rad_s: velocity signal value per rad/s on the feedback side.
    :param position_per_rad: position signal value per rad on the feedback side.
    :param target_per_rad: position command signal value per rad on the command side.
    :param command_gear: gear ratio if the command is motor side, else 1.
    :param feedback_gear: gear ratio if the feedback is motor side, else 1.
    :param sign: -1.0 for an inverted motor, else 1.0.
    :param gear_ratio: motor turns per wheel turn.
    """

    command_per_rad_s: float
    velocity_per_rad_s: float
    position_per_rad: float
    target_per_rad: float
    command_gear: float
    feedback_gear: float
    sign: float
    gear_ratio: float

    @classmethod
    def build(cls, motor: MotorConfig, opts: DbcOptions) -> UnitConversion:
        """The conversion for ``motor`` with the protocol keys ``opts``."""
        def speed(unit: str, scale: float) -> float:  # eRPM: per pole pair
            return VELOCITY_UNITS[unit] * scale * (opts.pole_pairs if unit == "erpm" else 1)

        def angle(unit: str, scale: float) -> float:  # counts: per encoder count
            return POSITION_UNITS[unit] * scale * (opts.counts_per_rev if unit == "counts" else 1)

        return cls(
            command_per_rad_s=speed(opts.command_unit, opts.command_scale),
            velocity_per_rad_s=speed(opts.velocity_unit, opts.velocity_scale),
            position_per_rad=angle(opts.position_unit, opts.position_scale),
            target_per_rad=angle(opts.position_command_unit, opts.position_command_scale),
            command_gear=motor.gear_ratio if opts.command_side == "motor" else 1.0,
            feedback_gear=motor.gear_ratio if opts.feedback_side == "motor" else 1.0,
            sign=motor.sign,
            gear_ratio=motor.gear_ratio,
        )

    def wheel_to_command(self, wheel_rad_s: float) -> float:
        """Command signal value for a wheel speed (rad/s)."""
        return wheel_rad_s * self.command_gear * self.sign * self.command_per_rad_s

    def velocity_to_wheel(self, value: float) -> float:
        """Wheel speed (rad/s) for a velocity signal value."""
        return value / self.velocity_per_rad_s * self.sign / self.feedback_gear

    def position_to_wheel(self, delta: float) -> float:
        """Wheel angle (rad) for a change of the position signal value."""
        return delta / self.position_per_rad * self.sign / self.feedback_gear

    # Steering actuators: absolute positions in the controller's frame, motor rad (the sign is
    # already in MotorConfig.steer_to_motor_rad).

    def motor_to_target(self, motor_rad: float) -> float:
        """Position command signal value for a motor position (rad, controller frame)."""
        return motor_rad * self.command_gear / self.gear_ratio * self.target_per_rad

    def position_to_motor(self, value: float) -> float:
        """Motor position (rad, controller frame) for a position signal value (absolute)."""
        return value / self.position_per_rad * self.gear_ratio / self.feedback_gear

    # Device side, for the simulator: the motor model turns at the (inverted) shaft speed.

    def target_to_motor(self, value: float) -> float:
        """Motor position (rad) that a position command signal value asks for."""
        return value / self.target_per_rad * self.gear_ratio / self.command_gear

    def command_to_motor(self, value: float) -> float:
        """Motor shaft speed (rad/s) that a command signal value asks for."""
        side = value / self.command_per_rad_s
        return side * (self.gear_ratio / self.command_gear)

    def motor_to_velocity(self, motor_rad_s: float) -> float:
        """Velocity signal value a device reports for a motor shaft speed (rad/s)."""
        return motor_rad_s * self.feedback_gear / self.gear_ratio * self.velocity_per_rad_s

    def motor_to_position(self, motor_rad: float) -> float:
        """Position signal value a device reports for a motor shaft angle (rad)."""
        return motor_rad * self.feedback_gear / self.gear_ratio * self.position_per_rad
