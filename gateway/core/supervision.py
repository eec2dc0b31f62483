"""What the supervisor (:mod:`gateway.core.control`) answers, and what it reads of the motors.

Its answers are frozen values: :class:`Accepted` or :class:`Rejection` for a twist,
:class:`Fault` when a fault starts, :class:`Decision` for every cycle.  It reads the motors
through a :class:`MotorBoard`, which gives their states and feedback every cycle without
building a :class:`~gateway.core.types.MotorStatus` for each motor; the full statuses are read
only for a fault's message.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

from gateway.core.types import DriveState

if TYPE_CHECKING:
    from collections.abc import Sequence

    from gateway.core.errors import InfeasibleTwistError
    from gateway.core.kinematics import IkResult
    from gateway.core.types import (
        ErrorCode,
        MotorStatus,
        Twist,
        WheelFeedback,
    )

__all__ = ["Accepted", "Decision", "Fault", "MotorBoard", "Rejection", "Source", "StatusBoard",
           "motor_fault_text"]


class Source(enum.Enum):
    """Where a command came from."""

    SOCKET = "socket"
    CAN = "can"
    #: The Zenoh bridge (native keys or ROS 2).
    BRIDGE = "bridge"
    INTERNAL = "internal"


@dataclass(frozen=True, slots=True)
class Rejection:
    """Why a command was refused.

    :param code: the error class.
    :param message: a sentence for people.
    :param error: the kinematic error, for infeasible twists.
    """

    code: ErrorCode
    message: str
    error: InfeasibleTwistError | None = None


@dataclass(frozen=True, slots=True)
class Accepted:
    """A twist that will be followed.

    :param twist: the twist the gateway follows (the nearest feasible one when projected).
    :param projected: whether it was projected from an infeasible request.
    :param error: the kinematic error of the request, when projected.
    :param ik: the inverse kinematics of ``twist`` from the steering angles the check was given
        (``None`` when projected: the nearest twist is not solved here), so that the loop
        solves no twist twice.
    """

    twist: Twist
    projected: bool = False
    error: InfeasibleTwistError | None = None
    ik: IkResult | None = None


@dataclass(frozen=True, slots=True)
class Fault:
    """Why the gateway went to FAULT just now.

    :param code: the error class (``MOTOR_FAULT``, ``FEEDBACK_TIMEOUT``, ``TRACKING_ERROR``).
    :param message: a sentence naming every motor involved.
    """

    code: ErrorCode
    message: str


@dataclass(frozen=True, slots=True)
class Decision:
    """What to command this cycle.

    :param twist: the target twist.
    :param ramp: reach it through the acceleration limits (False: jump, for e-stop).
    :param armed: whether the drives should be enabled.
    :param cmd_timeout: whether the command timeout forced the zero target.
    """

    twist: Twist
    ramp: bool
    armed: bool
    cmd_timeout: bool


class MotorBoard(Protocol):
    """What the supervisor reads of the motors each cycle, in one order: the drive motors in
    model order of their wheels, then the steering actuators (the drive layer's drive set is
    one).  Only :meth:`troubled` and :meth:`motor_feedback` are read every cycle, :meth:`states`
    when troubled or enabling, :meth:`status` only for a fault's message."""

    def states(self, now_s: float) -> Sequence[DriveState]:
        """Every motor's state at ``now_s``."""

    def troubled(self, now_s: float) -> bool:
        """Whether any motor may be OFFLINE or FAULT at ``now_s`` (``False``: none is)."""

    def motor_feedback(self) -> Sequence[WheelFeedback | None]:
        """Every motor's latest feedback (``None``: none yet)."""

    def status(self, now_s: float) -> Sequence[MotorStatus]:
        """Every motor's full status at ``now_s``."""

    def enable_failed(self) -> Sequence[int]:
        """The motors (positions in this order) whose enable sequence ended without arming
        them: no use waiting for them until the next enable."""


@dataclass(frozen=True, slots=True)
class StatusBoard:
    """A :class:`MotorBoard` over statuses already taken (the same for every ``now_s``).

    :param statuses: every motor's status, drive motors first.
    """

    statuses: Sequence[MotorStatus]

    def states(self, now_s: float) -> list[DriveState]:
        """Every motor's state."""
        return [s.state for s in self.statuses]

    def troubled(self, now_s: float) -> bool:
        """Always ``True``: the states are at hand, read them."""
        return True

    def enable_failed(self) -> list[int]:
        """None: statuses say nothing of enable sequences."""
        return []

    def motor_feedback(self) -> list[WheelFeedback | None]:
        """Every motor's feedback."""
        return [s.feedback for s in self.statuses]

    def status(self, now_s: float) -> Sequence[MotorStatus]:
        """The statuses."""
        return self.statuses


def motor_fault_text(s: MotorStatus, why: str) -> str:
    """One motor's part of a fault's message: its name, ``why``, then what it says (a tracking
    fault's motor says nothing more: it is live, without fault flags).

    >>> from gateway.core.types import DriveFault, MotorStatus
    >>> print(motor_fault_text(MotorStatus("left", 1, DriveState.OFFLINE, DriveFault.NONE, "",
    ...                                    None, None), "did not enable within 5 s"))
    motor 'left' (node 1) did not enable within 5 s, and it has not answered (no feedback yet)
    """
    offline = s.state is DriveState.OFFLINE
    told = [why] if why else []
    if s.faults or not (offline or why):
        detail = s.detail or repr(s.faults)
        own = f"motor {s.name!r} ("  # a driver's detail may name the motor again
        if detail.startswith(own) and "): " in detail:
            detail = detail.split("): ", 1)[1]
        told.append(f"reports a fault: {detail}")
    if offline:
        told.append(s.silence or (
            "has not answered (no feedback yet)" if s.feedback_age_s is None
            else f"stopped answering (no feedback for {s.feedback_age_s:.3f} s)"))
    return f"motor {s.name!r} (node {s.node_id}) {', and it '.join(told)}"
