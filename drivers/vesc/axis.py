"""What the VESC driver keeps per motor: one :class:`Axis` record, with the motor's constants.

The conversions between wheel units and the VESC's (https://github.com/vedderb/bldc, read at
``b9d287b3``): SET_RPM and STATUS carry electrical RPM (mechanical RPM times the motor's pole
pairs); the STATUS_5 tachometer counts 6 steps per electrical revolution (``mcpwm_foc.c``: one
step per 60 degrees of the electrical angle), an int32 that wraps, unwrapped here modulo 2**32
so odometry is exact to one step.  Pure: no I/O, no clock.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

from drivers.vesc.codec import RPM_PER_RAD_S, TACHO_STEPS_PER_EREV, VescStatus, VescStatus5
from drivers.vesc.settings import missing_status

if TYPE_CHECKING:
    from drivers.vesc.settings import VescOptions
    from gateway.core.types import MotorConfig

__all__ = ["Axis"]


@dataclass(slots=True)
class Axis:
    """One VESC's constants and state.

    :param index: the motor's position in the driver's ``motors``.
    :param node_id: its controller ID.
    :param wheel: its wheel's name, for messages.
    :param command_period_s: the keep-alive period (``command_period_s``).
    :param min_erpm: ``s_pid_min_erpm`` as stated (``min_erpm``).
    :param erpm_per_rad_s: SET_RPM per wheel rad/s (sign and gear included).
    :param rad_s_per_erpm: wheel rad/s per STATUS eRPM.
    :param rad_per_step: wheel rad per tachometer step.
    """

    index: int
    node_id: int
    wheel: str
    command_period_s: float
    min_erpm: float
    erpm_per_rad_s: float
    rad_s_per_erpm: float
    rad_per_step: float
    #: The last SET_RPM sent, and when (``None``: the stream is stopped).
    erpm: int = 0
    sent_s: float | None = None
    #: When the last STATUS and STATUS_5 arrived (``None``: never).
    status_s: float | None = None
    status5_s: float | None = None
    #: STATUS as received: eRPM, current * 10, duty * 1000; and the wheel speed (rad/s).
    status: tuple[int, int, int] = (0, 0, 0)
    velocity_rad_s: float = 0.0
    #: STATUS_5 as received: tachometer, input voltage * 10, reserved.
    status5: tuple[int, int, int] = (0, 0, 0)
    #: The unwrapped tachometer steps since the first STATUS_5, and the wheel angle (rad).
    steps: int = 0
    position_rad: float = 0.0
    #: Whether the missing-status hint was logged since the last enable.
    hinted: bool = False

    @classmethod
    def of(cls, index: int, motor: MotorConfig, opts: VescOptions, scale: float) -> Axis:
        """The record of ``motor``; ``scale`` is its ``gear_ratio * sign`` (motor = wheel *
        scale)."""
        erpm_per_motor_rad_s = RPM_PER_RAD_S * opts.pole_pairs
        return cls(
            index,
            motor.node_id,
            motor.wheel,
            opts.command_period_s,
            opts.min_erpm,
            erpm_per_rad_s=scale * erpm_per_motor_rad_s,
            rad_s_per_erpm=1.0 / (erpm_per_motor_rad_s * scale),
            rad_per_step=2.0 * math.pi / (TACHO_STEPS_PER_EREV * opts.pole_pairs * scale),
        )

    def missing(self) -> str:
        """What this VESC has never sent and how to switch it on ("" if nothing)."""
        return missing_status(self.status_s is not None, self.status5_s is not None)

    def last_status(self) -> VescStatus | None:
        """The latest STATUS (speed, current and duty), or ``None``."""
        if self.status_s is None:
            return None
        erpm, current, duty = self.status
        return VescStatus(self.node_id, erpm, current / 10.0, duty / 1000.0)

    def last_status5(self) -> VescStatus5 | None:
        """The latest STATUS_5 (tachometer and input voltage), or ``None``."""
        if self.status5_s is None:
            return None
        tacho, v_in, _ = self.status5
        return VescStatus5(self.node_id, tacho, v_in / 10.0)
