"""The targets of the command RPDOs: velocity units for a drive motor, the target position for
a steering actuator.

A drive motor's target velocity (0x60FF) is the wheel speed at the motor in device velocity
units (``velocity_factor``), rounded and checked against the int32 range (the driver's base
has checked it against ``max_rpm``; :class:`~drivers.cia402.axis.Axis`).

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

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from drivers.cia402.options import Cia402Options
    from gateway.core.types import MotorConfig

_INT32_SPAN = 1 << 32


def wrap_delta(previous: int, current: int) -> int:
    """Signed difference of two int32 counter readings, modulo 2^32.

    >>> wrap_delta(0x7FFFFFFF, -0x80000000)
    1
    """
    return (current - previous + (1 << 31)) % _INT32_SPAN - (1 << 31)


def target_counts(m: MotorConfig, opts: Cia402Options, angle: float) -> float:
    """The target position (counts, unwrapped, not rounded) of steering angle ``angle`` (rad)
    (the driver has checked that it is finite)."""
    return opts.rad_to_counts(m.steer_to_motor_rad(angle))
