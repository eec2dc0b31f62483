"""Protocol keys of a ``driver: dbc`` motor block.

Every key is declared once, as a field of the frozen :class:`DbcOptions` (an
:func:`~gateway.drive.options.option` each: type, default, bounds, choices, help);
``liveness_s`` and ``controller_timeout_s`` are the keys every protocol shares
(:class:`~gateway.drive.options.StatedTimeout`).  :func:`parse_options` validates a block and
checks the rules that involve several keys.  Nothing here reads the DBC file;
:mod:`drivers.dbc.binding` does, and :mod:`drivers.dbc.units` derives the unit conversions.

A drive motor names its velocity command (``command_message``, ``command_signal``); a steering
actuator (a ``steering:`` block) names its position command instead
(``position_command_message``, ``position_command_signal``, in a position unit) and, if the
controller needs one, the message that selects position control (``position_mode_message``
with ``position_mode_values``, signal name -> value, sent by ``enable()``).  Which of the two a
block needs depends on its role, which only the driver knows: config loading checks that at
least one is complete, the driver checks the right one (:func:`parse_options` with ``role``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING

from gateway.core.errors import ConfigError
from gateway.core.types import MotorRole
from gateway.drive.options import StatedTimeout, option

if TYPE_CHECKING:
    from gateway.core.types import MotorConfig

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
_VELOCITY = tuple(VELOCITY_UNITS)
_POSITION = tuple(POSITION_UNITS)


def motor_where(motor: MotorConfig) -> str:
    """Key path of a motor block for messages, e.g. ``wheels['left'].motor``."""
    return f"wheels[{motor.wheel!r}].motor"


@dataclass(frozen=True, kw_only=True)
class DbcOptions(StatedTimeout):
    """The protocol keys of one motor block, validated (``""``: "not used" or "same as
    another key", as each help says).

    Built from a block whose rules between keys :func:`parse_options` has checked, it
    resolves the keys that default to others (``position_message`` and, with a fault signal,
    ``fault_message`` to ``feedback_message``; ``feedback_side`` to ``command_side``) and keeps
    ``position_mode_values`` as ``(signal, value)`` pairs.
    """

    dbc: str = option(str, help="path of the DBC file (absolute, or relative to config_dir)")
    config_dir: str = option(
        str, "", help="directory relative DBC paths start from; '' = current directory"
    )
    command_message: str = option(
        str, "", help="DBC message that carries the velocity command (drive motors)"
    )
    command_signal: str = option(str, "", help="signal of command_message with the velocity")
    command_unit: str = option(str, "rpm", choices=_VELOCITY, help="unit of command_signal")
    command_scale: float = option(
        float, 1.0, help="signal value = speed in command_unit * this"
    )
    command_side: str = option(
        str, "motor", choices=_SIDES,
        help="the command signal (speed or position) is motor or wheel side",
    )
    position_command_message: str = option(
        str, "", help="DBC message that carries the position command (steering actuators)"
    )
    position_command_signal: str = option(
        str, "", help="signal of position_command_message with the position"
    )
    position_command_unit: str = option(
        str, "rev", choices=_POSITION, help="unit of position_command_signal"
    )
    position_command_scale: float = option(
        float, 1.0, help="signal value = angle in position_command_unit * this"
    )
    position_mode_message: str = option(
        str, "", help="message that selects position control in enable(); '' = none"
    )
    #: Given as a mapping (signal -> value), kept as ``(signal, value)`` pairs.
    position_mode_values: tuple[tuple[str, float], ...] = option(
        Mapping, {}, help="signal of position_mode_message -> value that selects it"
    )
    pole_pairs: int = option(int, 1, minimum=1, help="motor pole pairs, for the erpm unit")
    feedback_message: str = option(
        str, help="DBC message that carries the measured velocity"
    )
    velocity_signal: str = option(str, help="signal of feedback_message with the velocity")
    velocity_unit: str = option(str, "rpm", choices=_VELOCITY, help="unit of velocity_signal")
    velocity_scale: float = option(
        float, 1.0, help="signal value = speed in velocity_unit * this"
    )
    feedback_side: str = option(
        str, "", choices=("", *_SIDES), help="feedback is motor or wheel side; '' = as command_side"
    )
    position_message: str = option(
        str, "", help="message with the position; '' = feedback one"
    )
    position_signal: str = option(str, help="signal of position_message with the position")
    position_unit: str = option(str, "rev", choices=_POSITION, help="unit of position_signal")
    position_scale: float = option(
        float, 1.0, help="signal value = angle in position_unit * this"
    )
    counts_per_rev: int = option(int, 1, minimum=1, help="encoder counts per turn ('counts')")
    position_wrap_bits: int = option(
        int, 0, minimum=0, maximum=64, help="raw position wraps modulo 2**bits; 0 = never"
    )
    node_id_in_frame: str = option(
        str, "add", choices=("add", "none"),
        help="frame ID = DBC ID + (node_id << shift), or DBC ID",
    )
    node_id_shift: int = option(
        int, 0, minimum=0, maximum=28, help="left shift of node_id before it is added"
    )
    enable_message: str = option(str, "", help="DBC message that arms the drive; '' = none")
    enable_signal: str = option(str, "", help="signal of enable_message")
    enable_value: float = option(float, 1.0, help="enable_signal value that arms")
    disable_value: float = option(float, 0.0, help="enable_signal value that disarms")
    fault_message: str = option(
        str, "", help="message with a fault code; '' = feedback one"
    )
    fault_signal: str = option(
        str, "", help="signal with a fault code (0 = healthy); '' = none"
    )

    def __post_init__(self) -> None:
        resolved = {
            "position_mode_values": _pairs(self.position_mode_values),
            "position_message": self.position_message or self.feedback_message,
            "fault_message": (self.fault_message or self.feedback_message)
            if self.fault_signal else self.fault_message,
            "feedback_side": self.feedback_side or self.command_side,
        }
        for key, value in resolved.items():
            object.__setattr__(self, key, value)


def _pairs(raw: object) -> tuple[tuple[str, float], ...]:
    """``position_mode_values`` as pairs: from a mapping :func:`parse_options` has checked,
    or pairs as they are."""
    if isinstance(raw, Mapping):
        return tuple((str(name), float(value)) for name, value in raw.items())
    if isinstance(raw, tuple):
        return raw
    raise ConfigError(f"position_mode_values: expected a mapping of signal name to value, "
                      f"got {raw!r}")


def parse_options(
    values: Mapping[str, object], where: str, role: MotorRole | None = None
) -> DbcOptions:
    """Validate a motor block's protocol keys and check the rules between keys.

    Values that :meth:`~gateway.drive.driver.MotorDriver.validate_options` already normalised
    pass through unchanged, so this may be applied twice (at config load and driver
    construction).

    :param values: the protocol keys of the block (defaults filled in for missing ones).
    :param where: file and key path of the block for messages.
    :param role: what the motor does: a drive motor needs a velocity command and takes no
        position command, a steering actuator the other way round; ``None`` (config load,
        where the role is not known) needs one of the two.
    :return: the typed options.
    :raises ConfigError: naming the key, for an unknown, missing or bad value.
    """
    out = DbcOptions.validate(values, where)
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
    _check_mode_values(out, where)
    return DbcOptions.from_block(out, where)


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


def _check_mode_values(out: Mapping[str, object], where: str) -> None:
    """``position_mode_values``: signal names with finite numbers, given with the message."""
    raw = out["position_mode_values"]
    key = f"{where}.position_mode_values"
    if not isinstance(raw, Mapping):
        raise ConfigError(f"{key}: expected a mapping of signal name to value, got {raw!r}")
    for name, value in raw.items():
        if not isinstance(name, str) or not name:
            raise ConfigError(f"{key}: expected signal names, got {name!r}")
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(f"{key}.{name}: expected a number, got {value!r}")
        if not math.isfinite(value):
            raise ConfigError(f"{key}.{name}: expected a finite number, got {value!r}")
    if out["position_mode_message"] and not raw:
        raise ConfigError(f"{key}: required when position_mode_message is given")
    if raw and not out["position_mode_message"]:
        raise ConfigError(f"{where}.position_mode_message: required when position_mode_values "
                          "is given")
