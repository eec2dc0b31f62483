"""Host-side position loop of a DJI steering actuator (pure; no clock, no state).

C620 / C610 ESCs have no position (or speed) mode: they take a torque-current set point only
(the RoboMaster C620/C610 user guides' CAN protocol sections).  A steering actuator therefore gets
a cascade on the
host, as DJI's own gimbal firmware does for its current-driven motors (`RoboRTS-Firmware
<https://github.com/RoboMaster/RoboRTS-Firmware>`_ commit ``06ea500a``,
``application/gimbal_task.c``: ``cascade[n].outer`` angle loop feeding ``cascade[n].inter``
speed loop, whose output is the current sent on ``0x1FF``; the angle is the encoder reading
against a stored centre ``ecd`` offset): this position loop turns the position error
into a rotor-speed set point, and the rotor-speed PI of :mod:`drivers.dji.pi` turns that into
the current.  Everything is in the **motor (rotor) frame**: rad and rad/s of the rotor.

.. math::

    e = \\theta_{target} - \\theta, \\qquad
    \\omega_{target} = \\operatorname{clip}\\left(\\omega_{ff} + k_p e
        + k_d (\\omega_{ff} - \\omega), \\; -\\omega_{max}, \\omega_{max}\\right)

``omega_ff`` is the commanded angle's rate (the driver takes it from the change of the target
between cycles), so :math:`\\omega_{ff} - \\omega` is the rate of the error: the derivative
term uses the measured rotor speed instead of differentiating the 13-bit position, and a
steadily turning target is followed without lag.  Both gains are the same in the rotor frame
and at the wheel's plane (a gear ratio scales the error and the speeds alike).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from types import MappingProxyType
from typing import TYPE_CHECKING

from drivers.dji.codec import COUNTS_PER_REV
from gateway.core.options import OptionSpec

if TYPE_CHECKING:
    from collections.abc import Mapping

#: Protocol keys that only a steering actuator takes.  The defaults are tuned with the speed
#: loop's default ``kp`` / ``ki``: in :mod:`drivers.dji.sim` a 0.5 rad step of the wheel's plane
#: settles to 2 % in about 0.3 s with under 1 % overshoot, through an M3508's or an M2006's own
#: gearbox (and twice that ratio), at loop rates of 50 Hz to 1 kHz.
STEERING_OPTIONS: Mapping[str, OptionSpec] = MappingProxyType(
    {
        "steer_kp": OptionSpec(
            float,
            35.0,
            minimum=0.0,
            help="steering actuators: position gain, rad/s of rotor speed per rad of error",
        ),
        "steer_kd": OptionSpec(
            float,
            0.7,
            minimum=0.0,
            help="steering actuators: damping, rad/s of rotor speed per rad/s of error rate",
        ),
    }
)


@dataclass(frozen=True, slots=True)
class PositionLoop:
    """Gains and speed limit of one steering actuator's position loop.

    :param kp_1_s: proportional gain, rad/s of rotor speed per rad of rotor position error
        (1/s, >= 0).
    :param kd: derivative gain, rad/s of rotor speed per rad/s of error rate (>= 0).
    :param max_speed_rad_s: limit of the speed set point, rotor rad/s (> 0; from ``max_rpm``).
    """

    kp_1_s: float
    kd: float
    max_speed_rad_s: float

    def speed_target(self, error_rad: float, ff_rad_s: float, measured_rad_s: float) -> float:
        """The rotor-speed set point for the speed loop.

        :param error_rad: target minus measured rotor position (rad).
        :param ff_rad_s: the target's rate of change (rotor rad/s), 0 when unknown.
        :param measured_rad_s: the measured rotor speed (rad/s).
        :return: the speed set point (rad/s), within ``max_speed_rad_s``; 0 if an input is not
            finite.
        """
        speed = ff_rad_s + self.kp_1_s * error_rad + self.kd * (ff_rad_s - measured_rad_s)
        if not math.isfinite(speed):
            return 0.0
        limit = self.max_speed_rad_s
        if speed > limit:
            return limit
        return -limit if speed < -limit else speed


def power_up_position_rad(angle_count: int, zero_rad: float) -> float:
    """The absolute rotor position (rad) of a steering actuator's first feedback sample.

    The ESC reports the rotor angle within one turn only (13 bits), so the whole turns are
    unknown at power-up.  The driver takes the reading plus the whole number of turns that
    puts it within half a turn of ``zero_rad`` (exactly half a turn away counts as above it);
    later samples add the unwrapped change.  The result is right only if the actuator is
    powered up within half a rotor turn of its neutral position, i.e. within
    ``pi / gear_ratio`` of the wheel's neutral plane angle; anywhere else it is off by whole
    rotor turns (``2 pi / gear_ratio`` at the wheel's plane each), and nothing can tell.

    >>> power_up_position_rad(0, 0.0)
    0.0
    >>> round(power_up_position_rad(8192 - 100, 0.05), 4)  # just below the wrap: one turn less
    -0.0767

    :param angle_count: the first sample's rotor angle, 0..8191 for 0..2 pi.
    :param zero_rad: the actuator's ``zero_rad`` (rotor rad).
    :return: the rotor position in rad, within pi of ``zero_rad``.
    """
    reading = angle_count * 2.0 * math.pi / COUNTS_PER_REV
    turns = math.floor((zero_rad - reading) / (2.0 * math.pi) + 0.5)
    return reading + turns * 2.0 * math.pi
