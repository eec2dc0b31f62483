"""Protocol keys of a ``driver: dbc`` motor block and the unit conversions they imply.

Every key is described once in :data:`OPTIONS` (an :class:`~gateway.drive.driver.OptionSpec` each);
:func:`parse_options` turns a validated mapping into the frozen :class:`DbcOptions` and checks
the rules that involve several keys.  :class:`UnitConversion` derives, from the options and the
motor block (gear ratio, inversion), the factors between wheel rad/s and the signal values.
Nothing here reads the DBC file; :mod:`drivers.dbc.binding` does.

A drive motor names its velocity command (``command_message``, ``command_signal``); a steering
actuator (a ``steering:`` block) names its position command instead
(``position_command_message``, ``position_command_signal``, in a position unit) and, if the
controller needs one, the message that selects position control (``position_mode_message``
with ``position_mode_values``, signal name -> value, sent by ``enable()``).  Which of the two a
block needs depends on its role, which only the driver knows: config loading checks that at
least one is complete, the driver checks the right one (:func:`parse_options` with ``role``).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import TYPE_CHECKING

from gateway.core.errors import ConfigError
from gateway.core.options import OptionSpec, validate_block
from gateway.core.types import MotorRole
from gateway.drive.driver import CONTROLLER_TIMEOUT_OPTION

if TYPE_CHECKING:
    from gateway.core.types import MotorConfig

log = logging.getLogger(__name__)

_TWO_PI = 2.0 * math.pi

#: Velocity units: value of 1 rad/s in the unit ("erpm" is further multiplied by pole pairs).
VELOCITY_UNITS: dict[str, float] = {
    "rad/s": 1.0,
    "rpm": 60.0 / _TWO_PI,
    "rev/s": 1.0 / _TWO_PI,
    "deg/s": 180.0 / math.pi,
    "erpm": 60.0 / _TWO_PI,
}
#: Position units: value of 1 rad in the unit ("counts" is further multiplied by counts/rev).
POSITION_UNITS: dict[str, float] = {
    "rad": 1.0,
    "rev": 1.0 / _TWO_PI,
    "deg": 180.0 / math.pi,
    "counts": 1.0 / _TWO_PI,
}
_SIDES = ("motor", "wheel")
_NO_VALUES: Mapping[str, object] = MappingProxyType({})

#: The protocol keys of a ``driver: dbc`` motor block.  ``""`` means "not used" or
#: "same as another key", as each help text says.
OPTIONS: dict[str, OptionSpec] = {
    "dbc": OptionSpec(str, help="path of the DBC file (absolute, or relative to config_dir)"),
    "config_dir": OptionSpec(
        str, "", help="directory relative DBC paths start from; '' = current directory"
    ),
    "command_message": OptionSpec(
        str, "", help="DBC message that carries the velocity command (drive motors)"
    ),
    "command_signal": OptionSpec(str, "", help="signal of command_message with the velocity"),
    "command_unit": OptionSpec(str, "rpm", tuple(VELOCITY_UNITS), help="unit of command_signal"),
    "command_scale": OptionSpec(float, 1.0, help="signal value = speed in command_unit * this"),
    "command_side": OptionSpec(
        str, "motor", _SIDES, help="the command signal (speed or position) is motor or wheel side"
    ),
    "position_command_message": OptionSpec(
        str, "", help="DBC message that carries the position command (steering actuators)"
    ),
    "position_command_signal": OptionSpec(
        str, "", help="signal of position_command_message with the position"
    ),
    "position_command_unit": OptionSpec(
        str, "rev", tuple(POSITION_UNITS), help="unit of position_command_signal"
    ),
    "position_command_scale": OptionSpec(
        float, 1.0, help="signal value = angle in position_command_unit * this"
    ),
    "position_mode_message": OptionSpec(
        str, "", help="message that selects position control in enable(); '' = none"
    ),
    "position_mode_values": OptionSpec(
        Mapping, _NO_VALUES, help="signal of position_mode_message -> value that selects it"
    ),
    "pole_pairs": OptionSpec(int, 1, minimum=1, help="motor pole pairs, for the erpm unit"),
    "feedback_message": OptionSpec(str, help="DBC message that carries the measured velocity"),
    "velocity_signal": OptionSpec(str, help="signal of feedback_message with the velocity"),
    "velocity_unit": OptionSpec(str, "rpm", tuple(VELOCITY_UNITS), help="unit of velocity_signal"),
    "velocity_scale": OptionSpec(float, 1.0, help="signal value = speed in velocity_unit * this"),
    "feedback_side": OptionSpec(
        str, "", ("", *_SIDES), help="feedback is motor or wheel side; '' = as command_side"
    ),
    "position_message": OptionSpec(str, "", help="message with the position; '' = feedback one"),
    "position_signal": OptionSpec(str, help="signal of position_message with the position"),
    "position_unit": OptionSpec(str, "rev", tuple(POSITION_UNITS), help="unit of position_signal"),
    "position_scale": OptionSpec(float, 1.0, help="signal value = angle in position_unit * this"),
    "counts_per_rev": OptionSpec(int, 1, minimum=1, help="encoder counts per turn ('counts')"),
    "position_wrap_bits": OptionSpec(
        int, 0, minimum=0, maximum=64, help="raw position wraps modulo 2**bits; 0 = never"
    ),
    "node_id_in_frame": OptionSpec(
        str, "add", ("add", "none"), help="frame ID = DBC ID + (node_id << shift), or DBC ID"
    ),
    "node_id_shift": OptionSpec(
        int, 0, minimum=0, maximum=28, help="left shift of node_id before it is added"
    ),
    "enable_message": OptionSpec(str, "", help="DBC message that arms the drive; '' = none"),
    "enable_signal": OptionSpec(str, "", help="signal of enable_message"),
    "enable_value": OptionSpec(float, 1.0, help="enable_signal value that arms"),
    "disable_value": OptionSpec(float, 0.0, help="enable_signal value that disarms"),
    "fault_message": OptionSpec(str, "", help="message with a fault code; '' = feedback one"),
    "fault_signal": OptionSpec(str, "", help="signal with a fault code (0 = healthy); '' = none"),
    "liveness_s": OptionSpec(
        float, 0.25, minimum=0.001, help="feedback older than this marks the motor OFFLINE (s)"
    ),
    # The controller's own stop when wheelgate dies: a DBC names no timeout parameter, so the
    # block states what was set with the vendor's tool (0: not stated, a warning).
    "controller_timeout_s": CONTROLLER_TIMEOUT_OPTION,
}


def motor_where(motor: MotorConfig) -> str:
    """Key path of a motor block for messages, e.g. ``wheels['left'].motor``."""
    return f"wheels[{motor.wheel!r}].motor"


@dataclass(frozen=True, slots=True)
class DbcOptions:
    """The protocol keys of one motor block, validated; see :data:`OPTIONS` for each key."""

    dbc: str
    config_dir: str
    command_message: str
    command_signal: str
    command_unit: str
    command_scale: float
    command_side: str
    position_command_message: str
    position_command_signal: str
    position_command_unit: str
    position_command_scale: float
    position_mode_message: str
    position_mode_values: tuple[tuple[str, float], ...]
    pole_pairs: int
    feedback_message: str
    velocity_signal: str
    velocity_unit: str
    velocity_scale: float
    feedback_side: str
    position_message: str
    position_signal: str
    position_unit: str
    position_scale: float
    counts_per_rev: int
    position_wrap_bits: int
    node_id_in_frame: str
    node_id_shift: int
    enable_message: str
    enable_signal: str
    enable_value: float
    disable_value: float
    fault_message: str
    fault_signal: str
    liveness_s: float
    controller_timeout_s: float


def parse_options(
    values: Mapping[str, object], where: str, role: MotorRole | None = None
) -> DbcOptions:
    """Validate a motor block's protocol keys and check the rules between keys.

    Values that :meth:`~gateway.drive.driver.MotorDriver.validate_options` already normalised pass
    through unchanged, so this may be applied twice (at config load and driver construction).
    Keys ``position_message`` and ``fault_message`` default to ``feedback_message``, and
    ``feedback_side`` to ``command_side``.

    :param values: the protocol keys of the block (defaults filled in for missing ones).
    :param where: file and key path of the block for messages.
    :param role: what the motor does: a drive motor needs a velocity command and takes no
        position command, a steering actuator the other way round; ``None`` (config load,
        where the role is not known) needs one of the two.
    :return: the typed options.
    :raises ConfigError: naming the key, for an unknown, missing or bad value.
    """
    out = validate_block(values, OPTIONS, where, "protocol keys for this driver")
    for key in ("dbc", "feedback_message", "velocity_signal", "position_signal"):
        if not out[key]:
            raise ConfigError(f"{where}.{key}: expected a non-empty name, got ''")
    _check_command_keys(out, where, role)
    for key in ("command_scale", "velocity_scale", "position_scale", "position_command_scale"):
        if out[key] == 0.0:
            raise ConfigError(f"{where}.{key}: expected a non-zero factor, got 0.0")
    if bool(out["enable_message"]) != bool(out["enable_signal"]):
        given, missing = (
            ("enable_message", "enable_signal")
            if out["enable_message"]
            else ("enable_signal", "enable_message")
        )
        raise ConfigError(f"{where}.{missing}: required when {given} is given")
    if out["enable_message"] and out["enable_value"] == out["disable_value"]:
        raise ConfigError(
            f"{where}.disable_value: expected a value other than enable_value "
            f"{out['enable_value']!r}, got {out['disable_value']!r}"
        )
    if out["fault_message"] and not out["fault_signal"]:
        raise ConfigError(f"{where}.fault_signal: required when fault_message is given")
    if out["node_id_in_frame"] == "none" and out["node_id_shift"]:
        raise ConfigError(
            f"{where}.node_id_shift: only used with node_id_in_frame 'add', "
            f"got {out['node_id_shift']!r}"
        )
    out["position_mode_values"] = _mode_values(out, where)
    out["position_message"] = out["position_message"] or out["feedback_message"]
    if out["fault_signal"]:
        out["fault_message"] = out["fault_message"] or out["feedback_message"]
    out["feedback_side"] = out["feedback_side"] or out["command_side"]
    return DbcOptions(**out)  # type: ignore[arg-type]


_VELOCITY_KEYS = ("command_message", "command_signal")
_POSITION_KEYS = ("position_command_message", "position_command_signal")


def _check_command_keys(out: Mapping[str, object], where: str, role: MotorRole | None) -> None:
    """The command keys a block needs for its role (see :func:`parse_options`)."""
    velocity, position = bool(out["command_message"]), bool(out["position_command_message"])
    if role is None:
        for pair in (_VELOCITY_KEYS, _POSITION_KEYS):
            if bool(out[pair[0]]) != bool(out[pair[1]]):
                given, missing = pair if out[pair[0]] else pair[::-1]
                raise ConfigError(f"{where}.{missing}: required when {given} is given")
        if not (velocity or position):
            raise ConfigError(
                f"{where}.command_message: required key is missing (a drive motor names its "
                "velocity command in command_message and command_signal, a steering actuator "
                "its position command in position_command_message and position_command_signal)"
            )
        return
    if role is MotorRole.DRIVE:
        for key in _VELOCITY_KEYS:
            if not out[key]:
                raise ConfigError(
                    f"{where}.{key}: expected a non-empty name for a drive motor's velocity "
                    "command, got ''"
                )
        for key in (*_POSITION_KEYS, "position_mode_message"):
            if out[key]:
                raise ConfigError(
                    f"{where}.{key}: only a steering actuator takes a position command; "
                    f"expected '' for a drive motor, got {out[key]!r}"
                )
        return
    for key in _POSITION_KEYS:
        if not out[key]:
            raise ConfigError(
                f"{where}.{key}: expected a non-empty name for a steering actuator's position "
                "command (it is commanded in position, not in velocity), got ''"
            )
    for key in _VELOCITY_KEYS:
        if out[key]:
            raise ConfigError(
                f"{where}.{key}: a steering actuator is commanded in position "
                f"(position_command_message); expected '', got {out[key]!r}"
            )


def _mode_values(out: Mapping[str, object], where: str) -> tuple[tuple[str, float], ...]:
    """``position_mode_values`` as (signal, value) pairs, checked against the message key."""
    raw = out["position_mode_values"]
    if isinstance(raw, tuple):  # already parsed
        return raw
    key = f"{where}.position_mode_values"
    if not isinstance(raw, Mapping):
        raise ConfigError(f"{key}: expected a mapping of signal name to value, got {raw!r}")
    pairs: list[tuple[str, float]] = []
    for name, value in raw.items():
        if not isinstance(name, str) or not name:
            raise ConfigError(f"{key}: expected signal names, got {name!r}")
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(f"{key}.{name}: expected a number, got {value!r}")
        if not math.isfinite(value):
            raise ConfigError(f"{key}.{name}: expected a finite number, got {value!r}")
        pairs.append((name, float(value)))
    if out["position_mode_message"] and not pairs:
        raise ConfigError(f"{key}: required when position_mode_message is given")
    if pairs and not out["position_mode_message"]:
        raise ConfigError(f"{where}.position_mode_message: required when position_mode_values "
                          "is given")
    return tuple(pairs)


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
        cmd = VELOCITY_UNITS[opts.command_unit] * opts.command_scale
        if opts.command_unit == "erpm":
            cmd *= opts.pole_pairs
        vel = VELOCITY_UNITS[opts.velocity_unit] * opts.velocity_scale
        if opts.velocity_unit == "erpm":
            vel *= opts.pole_pairs
        pos = POSITION_UNITS[opts.position_unit] * opts.position_scale
        if opts.position_unit == "counts":
            pos *= opts.counts_per_rev
        target = POSITION_UNITS[opts.position_command_unit] * opts.position_command_scale
        if opts.position_command_unit == "counts":
            target *= opts.counts_per_rev
        return cls(
            command_per_rad_s=cmd,
            velocity_per_rad_s=vel,
            position_per_rad=pos,
            target_per_rad=target,
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
