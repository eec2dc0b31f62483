"""The setpoints a driver takes: their bounds per motor, and the errors for setpoints out of
bounds or of the wrong count, and for a node ID out of range."""

from __future__ import annotations

import sys
from typing import TYPE_CHECKING

from gateway.core.errors import ConfigError, EncodeError

if TYPE_CHECKING:
    from collections.abc import Callable, Mapping, Sequence

    from gateway.core.types import MotorConfig

#: The bound of a steering angle: any finite value (the gateway limits the angles).
ANY_FINITE = sys.float_info.max
#: Relative slack on the speed for ``max_rpm``, for rounding in the limits' arithmetic.
SPEED_SLACK = 1e-9


def bounds(motors: Sequence[MotorConfig]) -> tuple[float, ...]:
    """Per motor, the largest setpoint magnitude: the wheel speed for ``max_rpm`` (rad/s) for
    a drive motor, any finite angle for a steering actuator."""
    return tuple(
        ANY_FINITE if m.steering else m.max_wheel_rad_s * (1.0 + SPEED_SLACK) for m in motors
    )


def setpoint_error(
    motors: Sequence[MotorConfig], setpoints: Sequence[float], protocol: str
) -> EncodeError:
    """The error for the first setpoint out of its motor's :func:`bounds` (NaN included)."""
    for m, value, bound in zip(motors, setpoints, bounds(motors), strict=True):
        if -bound <= value <= bound:
            continue
        node = f'{protocol} node {m.node_id} ("{m.wheel}")'
        if m.steering:
            return EncodeError(
                f"Expected a finite steering angle for {node} in rad, but got {value}."
            )
        limit = m.max_wheel_rad_s
        return EncodeError(
            f"Expected a wheel speed for {node} between {-limit:.6g} and {limit:.6g} rad/s "
            f"(max_rpm {m.max_rpm:g}), but got {value}."
        )
    raise AssertionError("no setpoint out of bounds")  # pragma: no cover


def check_motors(
    motors: Sequence[MotorConfig],
    steering: bool,
    check_node: Callable[[int, str, Mapping[str, object]], None],
) -> None:
    """Check the motors one driver serves: steering actuators only for a ``steering`` driver,
    every node ID valid (``check_node``) and used once.

    :raises ConfigError: naming the motor.
    """
    owners: dict[int, str] = {}
    for m in motors:
        if m.steering and not steering:
            raise ConfigError(
                f"motor {m.wheel!r}: the {m.driver} driver does not command steering actuators"
            )
        where = f"motor {m.wheel!r}.node_id"
        check_node(m.node_id, where, m.options)
        if m.node_id in owners:
            raise ConfigError(
                f"{where}: node {m.node_id} is already used by wheel {owners[m.node_id]!r}"
            )
        owners[m.node_id] = m.wheel


def count_error(motors: Sequence[MotorConfig], got: int, protocol: str) -> EncodeError:
    """The error for ``got`` setpoints given to a driver of ``motors``."""
    return EncodeError(
        f"Expected {len(motors)} setpoints for the {protocol} motors "
        f"({', '.join(m.wheel for m in motors)}), but got {got}."
    )


def check_node_id(node_id: int, where: str, valid: tuple[int, int]) -> None:
    """Check a node ID against the inclusive range ``valid``.

    :raises ConfigError: if it is out of range.
    """
    lo, hi = valid
    if not lo <= node_id <= hi:
        raise ConfigError(f"{where}: expected int {lo}..{hi}, got {node_id!r}")
