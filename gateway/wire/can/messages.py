"""The five wheelgate messages as data: scales, names, flag enums, IDs and decoded forms.

What each message carries is tabled in :mod:`gateway.wire.can`; the byte layouts live in
:mod:`gateway.wire.can.codec`.  Pure: no I/O, no clock.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass
from typing import TYPE_CHECKING, TypeAlias

from gateway.core.types import (
    ConstraintCode,
    ErrorCode,
    GatewayState,
    Twist,
)

if TYPE_CHECKING:

    from gateway.core.kinematics.odometry import Pose

#: Scales (one LSB) of the physical signals, as in the DBC.
SPEED_SCALE = 0.001
POSITION_SCALE = 0.001
ANGLE_SCALE = 0.0001
I16_MIN, I16_MAX = -0x8000, 0x7FFF
U16_MAX = 0xFFFF
U8_MAX = 0xFF
#: One turn of the wrapping pose x and y on the wire, m.
POSITION_WRAP_M = (1 << 24) * POSITION_SCALE
#: ``wheel`` and ``twist_counter`` of an error report that concerns no wheel / no CAN twist.
NO_WHEEL = 0xFF
NO_TWIST_COUNTER = 0xFF
DLC = 8

TWIST_CMD = "WG_Twist_Cmd"
ODOM_POSE = "WG_Odom_Pose"
ODOM_VELOCITY = "WG_Odom_Velocity"
STATUS = "WG_Status"
ERROR = "WG_Error"


class TwistFlags(enum.IntFlag):
    """Request bits of ``WG_Twist_Cmd``; ``ESTOP`` takes precedence over the others."""

    NONE = 0
    #: Emergency stop: zero and disarm, latched until an ``ENABLE``.
    ESTOP = 0x01
    #: Arm the drives (also clears a latched emergency stop).
    ENABLE = 0x02
    #: Zero twist, drives stay armed.
    STOP = 0x04


class StatusFlags(enum.IntFlag):
    """Condition bits of ``WG_Status``."""

    NONE = 0
    #: No valid twist within the command timeout; the wheels ramp to zero.
    CMD_TIMEOUT_ACTIVE = 0x01
    #: The twist being followed is scaled down by a speed or acceleration limit.
    SPEED_LIMITED = 0x02
    #: An infeasible twist was projected onto the nearest feasible one.
    PROJECTED = 0x04
    #: CAN bus errors were seen recently.
    BUS_ERRORS_RECENT = 0x08



@dataclass(frozen=True, slots=True)
class TwistCommand:
    """A decoded ``WG_Twist_Cmd``.

    :param twist: commanded body twist (ignored by the gateway under ``ESTOP`` or ``STOP``).
    :param counter: rolling counter 0..255, +1 per message.
    :param flags: request bits.
    """

    twist: Twist
    counter: int
    flags: TwistFlags = TwistFlags.NONE


@dataclass(frozen=True, slots=True)
class OdomVelocity:
    """A decoded ``WG_Odom_Velocity``.

    :param twist: measured body twist.
    :param slip_m_s: slip estimate, m/s (the maximum means "at least this much").
    """

    twist: Twist
    slip_m_s: float


@dataclass(frozen=True, slots=True)
class StatusReport:
    """``WG_Status``.

    :param state: what the gateway is doing.
    :param faulted_motors: bit i set when the motor of wheel i is faulted; wheels 8 and
        beyond are folded into bit 7 on the wire.
    :param counter: rolling counter (taken modulo 256 when encoded).
    :param flags: condition bits.
    :param missed_cycles: control cycles that missed their deadline (saturates at 65535).
    :param infeasible_count: infeasible twists received (saturates at 65535).
    """

    state: GatewayState
    faulted_motors: int = 0
    counter: int = 0
    flags: StatusFlags = StatusFlags.NONE
    missed_cycles: int = 0
    infeasible_count: int = 0

    def faulted_wheels(self) -> tuple[int, ...]:
        """Indices of the wheels whose bit is set in :attr:`faulted_motors`."""
        mask = self.faulted_motors
        return tuple(i for i in range(mask.bit_length()) if mask >> i & 1)


@dataclass(frozen=True, slots=True)
class ErrorReport:
    """``WG_Error``.

    :param code: error class.
    :param wheel: index of the wheel concerned, :data:`NO_WHEEL` for none (an index outside
        0..254 is sent as :data:`NO_WHEEL`).
    :param constraint: constraint an infeasible twist breaks.
    :param twist_counter: counter of the rejected ``WG_Twist_Cmd``, :data:`NO_TWIST_COUNTER`
        when the error did not come from a CAN twist (255 is also a valid counter).
    :param residual_m_s: constraint violation as a sliding speed, m/s (saturates at 65.535).
    :param count: errors so far; sent modulo 65536, a sequence number.
    """

    code: ErrorCode
    wheel: int = NO_WHEEL
    constraint: ConstraintCode = ConstraintCode.NONE
    twist_counter: int = NO_TWIST_COUNTER
    residual_m_s: float = 0.0
    count: int = 0


#: What :meth:`WgCodec.decode` returns for a frame of one of the five messages.
WgMessage: TypeAlias = "TwistCommand | Pose | OdomVelocity | StatusReport | ErrorReport"
