"""One DJI motor's constants and loop state, as one record (:class:`Axis`).

The driver (:mod:`drivers.dji.driver`) reads and writes these fields on every command and every
feedback frame, so they are plain slots, the constants worked out once from the motor block
(:class:`~gateway.core.types.MotorConfig`, :class:`~drivers.dji.options.DjiOptions`) and the ESC
type (the RoboMaster C620/C610 user guides: full-scale current, temperature byte).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

from drivers.dji.codec import RAD_S_PER_RPM, group_of
from drivers.dji.pi import SpeedPi
from drivers.dji.position import PositionLoop

if TYPE_CHECKING:
    from drivers.dji.codec import EscModel
    from drivers.dji.options import DjiOptions
    from gateway.core.types import MotorConfig

__all__ = ["Axis"]


@dataclass(slots=True)
class Axis:
    """One motor of a DJI driver.

    :param index: its position in the driver's motors.
    :param slot: its slot in the command groups' eight set points (ESC ID - 1).
    :param group: its command group (0: ``0x200``, 1: ``0x1FF``).
    :param esc: the ESC type.
    :param scale: wheel to rotor, ``gear_ratio * sign``.
    :param sign: -1.0 for an inverted motor, else 1.0.
    :param gear: ``gear_ratio``.
    :param zero_rad: a steering actuator's ``zero_rad``; 0 for a drive motor.
    :param loop: a steering actuator's position loop; ``None`` for a drive motor.
    :param pi: the rotor-speed loop.
    :param full_scale_raw: the ESC's largest raw set point, for A to raw.
    :param full_scale_a: the current it stands for (A).
    :param max_temp_c: the over-temperature limit (degC); infinite for an ESC that does not
        report its temperature (C610).
    """

    index: int
    slot: int
    group: int
    esc: EscModel
    scale: float
    sign: float
    gear: float
    zero_rad: float
    loop: PositionLoop | None
    pi: SpeedPi
    full_scale_raw: int
    full_scale_a: float
    max_temp_c: float
    #: The speed loop's integrator (A).
    integral_a: float = 0.0
    #: The current of the last frames built (A).
    current_a: float = 0.0
    #: The rotor speed of the latest sample (rad/s).
    rotor_rad_s: float = 0.0
    #: Rotor position (rad) of the latest sample, from ``origin_rad``.
    rotor_rad: float = 0.0
    #: Rotor position (rad) at the first sample: 0 for a drive motor (its position counts from
    #: there), the absolute power-up position for a steering actuator.
    origin_rad: float = 0.0
    #: Encoder counts turned since the first sample (unwrapped).
    count_sum: int = 0
    #: The latest sample's angle, 0..8191; -1 before the first.
    last_count: int = -1
    #: When the latest sample arrived (s).
    last_s: float = 0.0
    #: A steering actuator's rotor target of the previous cycle, for the feed-forward.
    last_target_rad: float | None = None
    #: The latest sample's fields (:func:`drivers.dji.codec.feedback_fields`).
    fields: tuple[int, int, int, int, int] | None = None
    #: Whether the over-temperature fault is set.
    hot: bool = False

    @classmethod
    def of(cls, index: int, motor: MotorConfig, opts: DjiOptions, scale: float) -> Axis:
        """The record of motor ``index``, from its block, its options and its
        ``gear_ratio * sign``."""
        esc = opts.model
        loop = (
            PositionLoop(opts.steer_kp, opts.steer_kd, motor.max_rpm * RAD_S_PER_RPM)
            if motor.steering else None
        )
        return cls(
            index=index,
            slot=motor.node_id - 1,
            group=group_of(motor.node_id),
            esc=esc,
            scale=scale,
            sign=motor.sign,
            gear=motor.gear_ratio,
            zero_rad=motor.zero_rad if motor.steering else 0.0,
            loop=loop,
            pi=SpeedPi(opts.kp, opts.ki, opts.current_limit_a),
            full_scale_raw=esc.full_scale_raw,
            full_scale_a=esc.full_scale_a,
            max_temp_c=opts.max_temp_c if esc.reports_temperature else math.inf,
        )
