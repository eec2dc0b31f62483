"""The targets of the command RPDOs: velocity units for a drive motor, the target position for
a steering actuator.

A drive motor's target velocity (0x60FF) is the wheel speed at the motor in device velocity
units (``velocity_factor``), rounded and checked against ``max_rpm`` and the int32 range.

**Steering actuators** (:attr:`~drivers.cia402.driver.Cia402Driver.STEERING`) run in cyclic
synchronous position mode (CSP, 0x6060 = 8; drive motors stay in profile velocity, 3), with the
target position 0x607A in place of 0x60FF in their command RPDO (6040 + 607A), in position units
(``counts_per_rev`` per motor turn). CSP rather than profile position (PP, 1) because this
driver streams one setpoint per node every cycle, each followed by one SYNC, and that is the
contract of CSP (CiA 402-2, "cyclic synchronous position mode": the drive takes a new 0x607A at
every SYNC and interpolates over the cycle; synchronous RPDOs, transmission type 1, apply at the
SYNC). PP takes a new setpoint only through the controlword handshake: bit 4 "new setpoint"
rising edge (with bit 5 "change set immediately"), wait for statusword bit 12 "setpoint
acknowledge", clear bit 4, wait for bit 12 to clear. That is a statusword round trip through a
TPDO per setpoint, so at best one setpoint every other cycle (fewer with feedback latency), an
edge-sensitive state per node that a lost RPDO or TPDO stalls, and a profile the drive re-plans
at every setpoint. CSP has no handshake: a lost RPDO just repeats the previous target. What CSP
asks of the master, the driver does: the RPDOs must be synchronous (``sync: false`` is refused
for a steering actuator); the target must be a trajectory the drive can follow, so each cycle's
target moves from the previous one by at most ``max_rpm`` times the time since it (at most
:attr:`~drivers.cia402.driver.Cia402Driver.SLEW_MAX_DT_S`), starting from the measured position;
and the drive follows 0x607A from the moment it reaches OPERATION ENABLED, so the enable walk
sends the measured position as the target (:mod:`drivers.cia402.sequence`). A steering
actuator's stop is SHUTDOWN at once. Its feedback is absolute in the drive's frame: the first
0x6064 after the driver starts (or after a boot-up) is taken as is, and later ones unwrapped
modulo 2^32, so the angle stays right across the int32 wrap.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from drivers.cia402.codec import INT32_RANGE, position_to_raw, velocity_to_raw
from gateway.core.errors import EncodeError

if TYPE_CHECKING:
    from collections.abc import Sequence

    from drivers.cia402.options import NodeOptions
    from gateway.core.types import MotorConfig

_INT32_SPAN = 1 << 32


def wrap_delta(previous: int, current: int) -> int:
    """Signed difference of two int32 counter readings, modulo 2^32.

    >>> wrap_delta(0x7FFFFFFF, -0x80000000)
    1
    """
    return (current - previous + (1 << 31)) % _INT32_SPAN - (1 << 31)


def target_counts(m: MotorConfig, opts: NodeOptions, angle: float) -> float:
    """The target position (counts, unwrapped) of steering angle ``angle`` (rad).

    :raises EncodeError: if the angle is not finite.
    """
    if not math.isfinite(angle):
        raise EncodeError(
            f'Expected a finite steering angle in rad for node {m.node_id} ("{m.wheel}"), '
            f"but got {angle!r}."
        )
    return opts.rad_to_counts(m.steer_to_motor_rad(angle))


def raw_targets(
    motors: Sequence[MotorConfig], kinds: Sequence[tuple[NodeOptions, bool]],
    limits: Sequence[float], setpoints: Sequence[float],
) -> list[int]:
    """Every motor's RPDO target: velocity units, or a steering actuator's target position
    for the angle itself (int32, wrapped).

    :param kinds: per motor, its options and whether it is a steering actuator.
    :param limits: per motor, ``max_wheel_rad_s``.
    :param setpoints: per motor, the wheel speed (rad/s) or the steering angle (rad).
    :raises EncodeError: for a wrong count, a speed that is not finite or beyond ``max_rpm``,
        an angle that is not finite.
    """
    if len(setpoints) != len(motors):
        raise EncodeError(f"Expected {len(motors)} wheel speeds, but got {len(setpoints)}.")
    raws: list[int] = []
    lo, hi = INT32_RANGE
    for m, (opts, steer), limit, w in zip(motors, kinds, limits, setpoints, strict=True):
        if steer:
            raws.append(position_to_raw(target_counts(m, opts, w),
                                        f"target position for node {m.node_id}"))
            continue
        if not math.isfinite(w) or abs(w) > limit * (1.0 + 1e-9):
            raise EncodeError(
                f'Expected velocity for node {m.node_id} ("{m.wheel}") between '
                f"{-limit:.4g} and {limit:.4g} rad/s, but got {w!r}."
            )
        units = opts.rad_s_to_units(m.wheel_to_motor_rad_s(w))
        raw = round(units) if math.isfinite(units) else None
        if raw is None or not lo <= raw <= hi:
            # velocity_to_raw raises; its message is only built on this path.
            raw = velocity_to_raw(units, f"target velocity for node {m.node_id}")
        raws.append(raw)
    return raws
