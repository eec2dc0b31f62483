"""Frozen message and command dataclasses and the enums shared by every part of wheelgate.

Units are SI and appear in field names (``_m_s``, ``_rad_s``, ``_rad``, ``_s``).  Device units
(turns/s, eRPM, counts) never leave a driver.
"""

from __future__ import annotations

import enum
import functools
import math
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import TYPE_CHECKING, NamedTuple

from gateway.core.numfmt import short

if TYPE_CHECKING:
    from collections.abc import Callable, Mapping

#: Largest 11-bit and 29-bit CAN identifiers.
MAX_STANDARD_ID = 0x7FF
MAX_EXTENDED_ID = 0x1FFFFFFF


class _FrameFields(NamedTuple):
    arbitration_id: int
    data: bytes
    is_extended_id: bool
    is_remote_frame: bool
    dlc: int
    timestamp_s: float


def hex_id(can_id: int, extended: bool) -> str:
    """A CAN identifier as wheelgate writes it: ``0x021``, or ``0x00001117`` (29-bit)."""
    return f"0x{can_id:08X}" if extended else f"0x{can_id:03X}"


class Frame(_FrameFields):
    """One classical CAN frame as the pure core sees it: immutable, compared by value.

    python-can's ``Message`` compares by identity and is mutable, so it is used only at the
    edge (:mod:`gateway.bus.can_bus`).  This is an immutable tuple rather than a frozen dataclass
    because a frame is built on every command of every cycle: constructing it costs about a
    third of a frozen dataclass (``tools/bench_codec.py`` prints both).  Equality and hashing
    ignore the receive time, so golden tests compare frames with ``==``.

    :param arbitration_id: 11-bit or 29-bit identifier.
    :param data: payload, 0 to 8 bytes (empty for a remote frame).
    :param is_extended_id: 29-bit identifier when true.
    :param is_remote_frame: RTR frame; ``dlc`` then gives the requested length.
    :param dlc: data length code; ``len(data)`` when omitted.
    :param timestamp_s: receive time in seconds (monotonic at the edge); not compared.
    """

    __slots__ = ()

    def __new__(
        cls,
        arbitration_id: int,
        data: bytes = b"",
        is_extended_id: bool = False,
        is_remote_frame: bool = False,
        dlc: int = -1,
        timestamp_s: float = 0.0,
    ) -> Frame:
        return tuple.__new__(
            cls,
            (
                arbitration_id,
                data,
                is_extended_id,
                is_remote_frame,
                len(data) if dlc < 0 else dlc,
                timestamp_s,
            ),
        )

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Frame) and self[:5] == other[:5]

    def __ne__(self, other: object) -> bool:
        return not self == other

    def __hash__(self) -> int:
        return hash(self[:5])

    def stamped(self, timestamp_s: float) -> Frame:
        """The same frame with another receive time."""
        return self._replace(timestamp_s=timestamp_s)

    def to_cansend(self) -> str:
        """The frame in can-utils ``cansend`` syntax.

        >>> Frame(0x06D, bytes.fromhex("0000204100000000")).to_cansend()
        '06D#0000204100000000'
        >>> Frame(0x317, bytes.fromhex("000002BC"), is_extended_id=True).to_cansend()
        '00000317#000002BC'
        >>> Frame(0x069, is_remote_frame=True).to_cansend()
        '069#R'
        """
        ident = (
            f"{self.arbitration_id:08X}" if self.is_extended_id else f"{self.arbitration_id:03X}"
        )
        if self.is_remote_frame:
            return f"{ident}#R" if self.dlc == 0 else f"{ident}#R{self.dlc}"
        return f"{ident}#{self.data.hex().upper()}"


#: A frame from all six fields, in :class:`Frame` order and every one given (``dlc`` too):
#: ``frame_of((arbitration_id, data, is_extended_id, is_remote_frame, dlc, timestamp_s))``.
#: A C call past ``Frame.__new__`` (a Python function, about half the cost of a frame), for
#: the frames built every cycle (``tests/drive/test_fast_paths_frames.py`` checks it against
#: ``Frame(...)``).
frame_of: Callable[[tuple[int, bytes, bool, bool, int, float]], Frame] = functools.partial(
    tuple.__new__, Frame
)


#: Largest accepted twist component magnitude (m/s or rad/s) from any outside source (the
#: control socket, the bridge, the CLI); larger is surely a mistake.
MAX_TWIST_COMPONENT = 100.0


@dataclass(frozen=True, slots=True)
class Twist:
    """A body twist in the REP-103 body frame: x forward, y left, z up, CCW positive.

    :param vx_m_s: forward speed in m/s.
    :param vy_m_s: leftward speed in m/s.
    :param wz_rad_s: yaw rate in rad/s, counter-clockwise positive.
    """

    vx_m_s: float = 0.0
    vy_m_s: float = 0.0
    wz_rad_s: float = 0.0

    def is_finite(self) -> bool:
        """Whether every component is a finite number."""
        return (
            math.isfinite(self.vx_m_s)
            and math.isfinite(self.vy_m_s)
            and math.isfinite(self.wz_rad_s)
        )

    def scaled(self, factor: float) -> Twist:
        """This twist multiplied by ``factor`` (keeps direction and curvature)."""
        return Twist(self.vx_m_s * factor, self.vy_m_s * factor, self.wz_rad_s * factor)

    def __str__(self) -> str:
        """``(vx=0.5 m/s, vy=0 m/s, wz=0.25 rad/s)``, to 0.1 mm/s and 0.1 mrad/s."""
        return (
            f"(vx={short(self.vx_m_s, 4)} m/s, vy={short(self.vy_m_s, 4)} m/s, "
            f"wz={short(self.wz_rad_s, 4)} rad/s)"
        )


class DriveFault(enum.IntFlag):
    """Protocol-independent fault classes; each driver maps its own flags onto these."""

    NONE = 0
    OVER_TEMPERATURE = enum.auto()
    OVER_CURRENT = enum.auto()
    OVER_VOLTAGE = enum.auto()
    UNDER_VOLTAGE = enum.auto()
    ENCODER = enum.auto()
    MOTOR = enum.auto()
    CONTROLLER = enum.auto()
    WATCHDOG = enum.auto()
    COMMUNICATION = enum.auto()
    ESTOP = enum.auto()
    OTHER = enum.auto()


class DriveState(enum.IntEnum):
    """What the gateway knows of one motor controller."""

    #: No feedback yet, or feedback stopped for longer than the liveness timeout.
    OFFLINE = 0
    #: Answering, not armed.
    DISABLED = 1
    #: The enable sequence is under way.
    ENABLING = 2
    #: Armed and following velocity commands.
    ENABLED = 3
    #: The controller reports a fault.
    FAULT = 4


class WheelFeedback(NamedTuple):
    """Decoded encoder feedback of one wheel, wheel side, after unwrapping.

    Immutable; a named tuple rather than a frozen dataclass for the reason :class:`Frame` is:
    the drivers build one for every feedback frame (eight per 1 ms cycle on a CiA 402 robot),
    and it costs about 40 % less to construct (``timeit``: 0.19 us against 0.31 us for the
    frozen dataclass it was).

    :param position_rad: wheel angle in rad, unwrapped, counted from the first sample.
    :param velocity_rad_s: wheel angular speed in rad/s.
    :param timestamp_s: when the frame carrying its position was received (s): the time the
        odometry integrates it at.  A controller that sends its speed in another frame (VESC
        STATUS and STATUS_5, CiA 402 TPDOs, DBC messages) refreshes the speed in a new
        feedback with the same time, so that the odometry does not take an old position for a
        new one (a sample's wheels would be staggered by up to a frame period: zig-zag and
        false distance); how old the other frames are is the liveness's
        (:class:`gateway.drive.liveness.Liveness`), which the feedback's age in a report takes
        into account (:meth:`gateway.drive.driver.MotorDriver.status`).
    """

    position_rad: float
    velocity_rad_s: float
    timestamp_s: float


@dataclass(frozen=True, slots=True)
class MotorStatus:
    """A snapshot of one motor controller's state for status reports.

    :param name: the wheel's name.
    :param node_id: the controller's node ID on the bus.
    :param state: what the driver believes.
    :param faults: protocol-independent fault flags.
    :param detail: protocol-specific fault text (flag names), empty when healthy.
    :param feedback_age_s: seconds since the last feedback frame, ``None`` before the first.
    :param feedback: latest wheel feedback, ``None`` before the first.
    :param silence: an OFFLINE motor that still sends some of its liveness streams: what it
        sends and what not (and how to switch that on); empty otherwise.
    """

    name: str
    node_id: int
    state: DriveState
    faults: DriveFault
    detail: str
    feedback_age_s: float | None
    feedback: WheelFeedback | None
    silence: str = ""


def _frozen_mapping() -> Mapping[str, object]:
    return MappingProxyType({})


class MotorRole(enum.Enum):
    """What a motor does: turn a wheel (speed commands) or steer one (angle commands)."""

    #: Turns its wheel; commanded in wheel rad/s, feedback is the wheel's angle and speed.
    DRIVE = "drive"
    #: Turns a wheel's plane (a steering actuator); commanded with the steering angle in rad
    #: from the wheel's neutral plane angle, feedback is that angle and its rate.
    STEER = "steer"


@dataclass(frozen=True, slots=True)
class MotorConfig:
    """The motor block of one wheel, or of one steering actuator, validated.

    :param wheel: name of the wheel this motor turns; for a steering actuator, the name of the
        block (a wheel or a steer group) followed by ``" steering"``.
    :param driver: registry name of the protocol driver, e.g. ``"odrive"``.
    :param node_id: the controller's node ID (protocol-specific range).
    :param gear_ratio: motor turns per wheel turn (> 0); for a steering actuator, motor turns
        per turn of the wheel's plane.
    :param invert: the motor turns backwards for a positive wheel speed (a steering actuator:
        for a positive, counter-clockwise, steering angle).
    :param max_rpm: the motor's speed limit in RPM at the motor (> 0).
    :param options: protocol keys, validated by the driver (read-only mapping).
    :param role: turns a wheel, or steers.
    :param zero_rad: a steering actuator's motor position (rad at the motor, in the
        controller's own position frame) at which its wheels stand at their neutral plane angle.
    :param steers: the wheels a steering actuator turns (model names; empty for a drive motor).
    :param steer_range_rad: a steering actuator's travel: the smallest and largest steering
        angle it is commanded (rad, from its wheels' ``steer_min`` and ``steer_max``).
    :param linkage: how a steering actuator's angle turns its wheels: ``"direct"`` (each wheel
        at the actuator's angle) or ``"ackermann"`` (a steering linkage: the actuator's angle
        is that of a virtual wheel in the middle of the wheels' axle, see
        :mod:`gateway.core.linkage`).
    """

    wheel: str
    driver: str
    node_id: int
    gear_ratio: float = 1.0
    invert: bool = False
    max_rpm: float = 3000.0
    options: Mapping[str, object] = field(default_factory=_frozen_mapping)
    role: MotorRole = MotorRole.DRIVE
    zero_rad: float = 0.0
    steers: tuple[str, ...] = ()
    steer_range_rad: tuple[float, float] = (-math.pi, math.pi)
    linkage: str = "direct"

    @property
    def steering(self) -> bool:
        """Whether this is a steering actuator."""
        return self.role is MotorRole.STEER

    def steer_to_motor_rad(self, steer_rad: float) -> float:
        """The motor position (rad, controller frame) for a steering angle (rad)."""
        return self.zero_rad + steer_rad * self.gear_ratio * self.sign

    def motor_to_steer_rad(self, motor_rad: float) -> float:
        """The steering angle (rad) at a motor position (rad, controller frame)."""
        return (motor_rad - self.zero_rad) * self.sign / self.gear_ratio

    @property
    def sign(self) -> float:
        """-1.0 for an inverted motor, else 1.0."""
        return -1.0 if self.invert else 1.0

    def wheel_to_motor_rad_s(self, wheel_rad_s: float) -> float:
        """Motor shaft speed (rad/s, with inversion) for a wheel speed (rad/s)."""
        return wheel_rad_s * self.gear_ratio * self.sign

    def motor_to_wheel_rad_s(self, motor_rad_s: float) -> float:
        """Wheel speed (rad/s) for a motor shaft speed (rad/s, with inversion)."""
        return motor_rad_s * self.sign / self.gear_ratio

    @property
    def max_wheel_rad_s(self) -> float:
        """The wheel speed limit in rad/s that ``max_rpm`` at the motor allows."""
        return self.max_rpm * 2.0 * math.pi / 60.0 / self.gear_ratio


class GatewayState(enum.IntEnum):
    """What the gateway as a whole is doing (on the wire in the status frame and replies)."""

    #: Drives disarmed; twists are refused until an enable.
    DISABLED = 0
    #: The drives' enable sequences are under way.
    ENABLING = 1
    #: Following twists.
    RUNNING = 2
    #: A motor faulted or stopped answering; wheels commanded to zero.
    FAULT = 3
    #: Emergency stop latched: zero and disarm until an explicit enable.
    ESTOP = 4
    #: Shutting down.
    STOPPING = 5


class ErrorCode(enum.IntEnum):
    """Error classes reported to twist senders (socket replies and the CAN error frame)."""

    NONE = 0
    INFEASIBLE_TWIST = 1
    MOTOR_FAULT = 2
    FEEDBACK_TIMEOUT = 3
    ESTOP = 4
    BUS_ERROR = 5
    BAD_COMMAND = 6
    COMMAND_TIMEOUT = 7
    NOT_ENABLED = 8
    TRACKING_ERROR = 9


class ConstraintCode(enum.IntEnum):
    """Which kinematic constraint an infeasible twist breaks."""

    NONE = 0
    SLIDING = 1
    STEERING_LIMIT = 2
    STEERING_COUPLING = 3

    @classmethod
    def from_name(cls, constraint: str) -> ConstraintCode:
        """The code for an :class:`~gateway.core.errors.InfeasibleTwistError` constraint name."""
        return {
            "sliding": cls.SLIDING,
            "steering limit": cls.STEERING_LIMIT,
            "steering coupling": cls.STEERING_COUPLING,
        }.get(constraint, cls.NONE)
