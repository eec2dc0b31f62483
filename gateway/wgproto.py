"""Pure codec of wheelgate's own CAN messages: no I/O, no clock.

The published description is ``config/wheelgate.dbc`` (cantools and other DBC tools read the
traffic with it); ``tests/test_wgproto.py`` proves that this hand-written ``struct`` codec and
cantools agree on every message, both ways.  Every payload is little endian with DLC 8:

====================  =====  ===========================================================
message               ID     payload (i: signed, u: unsigned, bits)
====================  =====  ===========================================================
``WG_Twist_Cmd``      0x100  vx, vy i16 mm/s; wz i16 mrad/s; counter u8; flags u8
``WG_Odom_Pose``      0x101  x, y i24 mm (wrapping); theta i16 in 0.1 mrad
``WG_Odom_Velocity``  0x102  vx, vy i16 mm/s; wz i16 mrad/s; slip u16 mm/s
``WG_Status``         0x103  state, faulted motors, counter, flags u8; two u16 counts
``WG_Error``          0x104  code, wheel, constraint, twist counter u8; residual, count u16
====================  =====  ===========================================================

Twist commands come from other devices, so :meth:`WgCodec.encode_twist` raises
:class:`~gateway.errors.EncodeError` for a value it cannot send, and :meth:`WgCodec.decode_twist`
raises :class:`~gateway.errors.DecodeError` for a malformed frame.  Everything the gateway
sends (odometry, status, error) comes from the control loop, which must never fail on its
output path: those encoders saturate instead of raising (NaN speeds encode as 0; a NaN or huge
slip or residual as the maximum, "at least this much").  Pose x and y wrap modulo 2**24 mm
(16777.216 m) on the wire; :func:`unwrap_position_m` undoes it on the receiving side.  The
error ``count`` wraps modulo 65536 (a sequence number), the status counts saturate.
"""

from __future__ import annotations

import enum
import math
import struct
from dataclasses import dataclass
from typing import TYPE_CHECKING, TypeAlias, TypeVar

from gateway.errors import ConfigError, DecodeError, EncodeError
from gateway.kinematics.odometry import Pose
from gateway.types import (
    MAX_EXTENDED_ID,
    MAX_STANDARD_ID,
    ConstraintCode,
    ErrorCode,
    Frame,
    GatewayState,
    Twist,
)

if TYPE_CHECKING:
    from collections.abc import Callable, Mapping

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

_TWIST = struct.Struct("<hhhBB")
_POSE = struct.Struct("<3s3sh")
_VELOCITY = struct.Struct("<hhhH")
_STATUS = struct.Struct("<BBBBHH")
_ERROR = struct.Struct("<BBBBHH")


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


_E = TypeVar("_E", bound=enum.IntEnum)
_TWIST_FLAGS_MASK = sum(f.value for f in TwistFlags)
_STATUS_FLAGS_MASK = sum(f.value for f in StatusFlags)
#: The ID keys of :class:`CanIds` (and of the ``gateway.can_ids`` block), in wire order.
ID_KEYS = ("twist", "odom_pose", "odom_velocity", "status", "error")


@dataclass(frozen=True, slots=True)
class CanIds:
    """The arbitration IDs of the five messages; the defaults are the DBC's.

    :param twist: ``WG_Twist_Cmd``.
    :param odom_pose: ``WG_Odom_Pose``.
    :param odom_velocity: ``WG_Odom_Velocity``.
    :param status: ``WG_Status``.
    :param error: ``WG_Error``.
    :param extended: 29-bit identifiers instead of 11-bit ones.
    :raises ConfigError: if an ID is not an int in range for its type, or two are equal.
    """

    twist: int = 0x100
    odom_pose: int = 0x101
    odom_velocity: int = 0x102
    status: int = 0x103
    error: int = 0x104
    extended: bool = False

    def __post_init__(self) -> None:
        self.validate()

    def validate(self) -> None:
        """Check the IDs (the constructor calls this).

        :raises ConfigError: naming the key, the expected range and the value.
        """
        if not isinstance(self.extended, bool):
            raise ConfigError(f"gateway.can_ids.extended: expected a bool, got {self.extended!r}")
        limit, kind = (MAX_EXTENDED_ID, "29-bit") if self.extended else (MAX_STANDARD_ID, "11-bit")
        seen: dict[int, str] = {}
        for name in ID_KEYS:
            value = getattr(self, name)
            if not isinstance(value, int) or isinstance(value, bool) or not 0 <= value <= limit:
                raise ConfigError(
                    f"gateway.can_ids.{name}: expected a {kind} CAN ID between 0x0 and "
                    f"{limit:#x}, got {value!r}"
                )
            if value in seen:
                raise ConfigError(
                    f"gateway.can_ids.{name}: expected an ID no other message uses, got "
                    f"{value:#x} (also {seen[value]})"
                )
            seen[value] = name

    @classmethod
    def from_mapping(cls, block: Mapping[str, object]) -> CanIds:
        """The IDs of a ``gateway.can_ids`` block (missing keys take their defaults).

        :param block: key to value, as :attr:`gateway.config.LoopConfig.can_ids` holds it.
        :raises ConfigError: for an unknown key or a bad value.
        """
        known = [*ID_KEYS, "extended"]
        for key in block:
            if key not in known:
                raise ConfigError(f"gateway.can_ids: expected keys {', '.join(known)}, got {key!r}")
        return cls(**block)  # type: ignore[arg-type]


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


def unwrap_position_m(previous_m: float, received_m: float) -> float:
    """The unwrapped pose coordinate nearest ``previous_m`` that is sent as ``received_m``.

    Correct while the robot moves less than half a wrap (8388.608 m) between two frames.

    >>> unwrap_position_m(8388.0, -8388.216)
    8389.0
    """
    turns = round((previous_m - received_m) / POSITION_WRAP_M)
    return received_m + turns * POSITION_WRAP_M


def _saturate(value: float, scale: float, lo: int, hi: int, nan_raw: int) -> int:
    """``round(value / scale)`` clipped to ``lo..hi``; ``nan_raw`` for NaN."""
    if math.isnan(value):
        return nan_raw
    raw = value / scale
    if raw >= hi:
        return hi
    if raw <= lo:
        return lo
    return round(raw)


def _speed(value: float) -> int:
    return _saturate(value, SPEED_SCALE, I16_MIN, I16_MAX, 0)


def _clip(value: int, hi: int) -> int:
    return 0 if value < 0 else min(value, hi)


def _wrap24(value: float) -> bytes:
    """A position as 3 little-endian bytes, modulo 2**24 LSB (non-finite: 0)."""
    raw = value / POSITION_SCALE
    return ((round(raw) if math.isfinite(raw) else 0) & 0xFFFFFF).to_bytes(3, "little")


def _check_command(name: str, value: float, unit: str) -> int:
    lo, hi = I16_MIN * SPEED_SCALE, I16_MAX * SPEED_SCALE
    try:
        ok = lo <= value <= hi  # False for NaN
    except TypeError:
        ok = False
    if not ok:
        raise EncodeError(
            f'Expected "{name}" in {TWIST_CMD} between {lo} and {hi} {unit}, but got {value!r}.'
        )
    return round(value / SPEED_SCALE)


def _enum(cls: type[_E], raw: int, message: str, signal: str) -> _E:
    try:
        return cls(raw)
    except ValueError:
        valid = ", ".join(f"{m.value} ({m.name})" for m in cls)
        raise DecodeError(
            f'Expected "{signal}" in {message} to be one of {valid}, but got {raw}.'
        ) from None


class WgCodec:
    """Encoder and decoder of the five wheelgate messages under one set of IDs.

    Decoders return ``None`` for a frame that is not theirs (other ID, or a 29-bit frame
    when 11-bit IDs are configured and vice versa) and raise :class:`DecodeError` for a
    malformed one of theirs (remote frame, DLC other than 8, reserved bits, unknown enum).

    :param ids: arbitration IDs; the defaults when omitted.
    """

    def __init__(self, ids: CanIds | None = None) -> None:
        self.ids = CanIds() if ids is None else ids
        self._ext = self.ids.extended
        self._decoders: dict[int, Callable[[Frame], WgMessage | None]] = {
            self.ids.twist: self.decode_twist,
            self.ids.odom_pose: self.decode_pose,
            self.ids.odom_velocity: self.decode_velocity,
            self.ids.status: self.decode_status,
            self.ids.error: self.decode_error,
        }

    # ------------------------------------------------------------------ encoders

    def encode_twist(self, cmd: TwistCommand) -> Frame:
        """The ``WG_Twist_Cmd`` frame of a command (what a controller sends).

        :param cmd: twist within ±32.767 m/s (rad/s), counter 0..255, known flags only.
        :raises EncodeError: for a value out of range or not finite, cantools style.
        """
        tw = cmd.twist
        vx = _check_command("Vx", tw.vx_m_s, "m/s")
        vy = _check_command("Vy", tw.vy_m_s, "m/s")
        wz = _check_command("Wz", tw.wz_rad_s, "rad/s")
        counter = cmd.counter
        if not isinstance(counter, int) or not 0 <= counter <= U8_MAX:
            raise EncodeError(
                f'Expected "Counter" in {TWIST_CMD} between 0 and 255, but got {counter!r}.'
            )
        flags = int(cmd.flags)
        if flags & ~_TWIST_FLAGS_MASK:
            raise EncodeError(
                f"Expected {TWIST_CMD} flags within {_TWIST_FLAGS_MASK:#04x} "
                f"(ESTOP, ENABLE, STOP), but got {flags:#04x}."
            )
        return Frame(self.ids.twist, _TWIST.pack(vx, vy, wz, counter, flags), self._ext)

    def encode_pose(self, pose: Pose) -> Frame:
        """The ``WG_Odom_Pose`` frame; never raises.

        x and y wrap modulo 16777.216 m, theta is wrapped to [-pi, pi]; a non-finite value
        is sent as 0.

        :param pose: odometry pose.
        """
        theta = math.remainder(pose.theta_rad, math.tau) if math.isfinite(pose.theta_rad) else 0.0
        raw_theta = _saturate(theta, ANGLE_SCALE, I16_MIN, I16_MAX, 0)
        data = _POSE.pack(_wrap24(pose.x_m), _wrap24(pose.y_m), raw_theta)
        return Frame(self.ids.odom_pose, data, self._ext)

    def encode_velocity(self, twist: Twist, slip_m_s: float) -> Frame:
        """The ``WG_Odom_Velocity`` frame; never raises.

        Speeds saturate at ±32.767 (NaN: 0); the slip saturates at 65.535 m/s and a NaN
        slip is sent as that maximum (negative: 0).

        :param twist: measured body twist.
        :param slip_m_s: slip estimate, m/s.
        """
        slip = _saturate(slip_m_s, SPEED_SCALE, 0, U16_MAX, U16_MAX)
        data = _VELOCITY.pack(
            _speed(twist.vx_m_s), _speed(twist.vy_m_s), _speed(twist.wz_rad_s), slip
        )
        return Frame(self.ids.odom_velocity, data, self._ext)

    def encode_status(self, report: StatusReport) -> Frame:
        """The ``WG_Status`` frame; never raises.

        The counter is taken modulo 256, the counts saturate at 65535, unknown flag bits are
        dropped and faulted wheels 8 and beyond set bit 7.

        :param report: the status.
        """
        mask = max(report.faulted_motors, 0)
        if mask > U8_MAX:
            mask = mask & 0x7F | 0x80
        data = _STATUS.pack(
            int(report.state),
            mask,
            report.counter & U8_MAX,
            int(report.flags) & _STATUS_FLAGS_MASK,
            _clip(report.missed_cycles, U16_MAX),
            _clip(report.infeasible_count, U16_MAX),
        )
        return Frame(self.ids.status, data, self._ext)

    def encode_error(self, report: ErrorReport) -> Frame:
        """The ``WG_Error`` frame; never raises.

        :param report: the error; see :class:`ErrorReport` for the saturation and wrapping.
        """
        wheel = report.wheel if 0 <= report.wheel <= U8_MAX else NO_WHEEL
        twist_counter = (
            report.twist_counter if 0 <= report.twist_counter <= U8_MAX else NO_TWIST_COUNTER
        )
        data = _ERROR.pack(
            int(report.code),
            wheel,
            int(report.constraint),
            twist_counter,
            _saturate(report.residual_m_s, SPEED_SCALE, 0, U16_MAX, U16_MAX),
            report.count & U16_MAX,
        )
        return Frame(self.ids.error, data, self._ext)

    # ------------------------------------------------------------------ decoders

    def decode(self, frame: Frame) -> WgMessage | None:
        """Decode any of the five messages; ``None`` for a frame that is none of them.

        :raises DecodeError: for a malformed frame of one of them.
        """
        if frame.is_extended_id != self._ext:
            return None
        decoder = self._decoders.get(frame.arbitration_id)
        return None if decoder is None else decoder(frame)

    def decode_twist(self, frame: Frame) -> TwistCommand | None:
        """A ``WG_Twist_Cmd``; reserved flag bits are a :class:`DecodeError`.

        :raises DecodeError: for a malformed frame of this message.
        """
        data = self._payload(frame, self.ids.twist, TWIST_CMD)
        if data is None:
            return None
        vx, vy, wz, counter, flags = _TWIST.unpack(data)
        _check_flags(flags, _TWIST_FLAGS_MASK, TWIST_CMD, frame)
        return TwistCommand(_twist(vx, vy, wz), counter, TwistFlags(flags))

    def decode_pose(self, frame: Frame) -> Pose | None:
        """A ``WG_Odom_Pose``, x and y still wrapped (see :func:`unwrap_position_m`).

        :raises DecodeError: for a malformed frame of this message.
        """
        data = self._payload(frame, self.ids.odom_pose, ODOM_POSE)
        if data is None:
            return None
        x, y, theta = _POSE.unpack(data)
        return Pose(
            int.from_bytes(x, "little", signed=True) * POSITION_SCALE,
            int.from_bytes(y, "little", signed=True) * POSITION_SCALE,
            theta * ANGLE_SCALE,
        )

    def decode_velocity(self, frame: Frame) -> OdomVelocity | None:
        """A ``WG_Odom_Velocity``.

        :raises DecodeError: for a malformed frame of this message.
        """
        data = self._payload(frame, self.ids.odom_velocity, ODOM_VELOCITY)
        if data is None:
            return None
        vx, vy, wz, slip = _VELOCITY.unpack(data)
        return OdomVelocity(_twist(vx, vy, wz), slip * SPEED_SCALE)

    def decode_status(self, frame: Frame) -> StatusReport | None:
        """A ``WG_Status``; reserved flag bits or an unknown state are a :class:`DecodeError`.

        :raises DecodeError: for a malformed frame of this message.
        """
        data = self._payload(frame, self.ids.status, STATUS)
        if data is None:
            return None
        state, mask, counter, flags, missed, infeasible = _STATUS.unpack(data)
        _check_flags(flags, _STATUS_FLAGS_MASK, STATUS, frame)
        return StatusReport(
            _enum(GatewayState, state, STATUS, "State"),
            mask,
            counter,
            StatusFlags(flags),
            missed,
            infeasible,
        )

    def decode_error(self, frame: Frame) -> ErrorReport | None:
        """A ``WG_Error``; an unknown code or constraint is a :class:`DecodeError`.

        :raises DecodeError: for a malformed frame of this message.
        """
        data = self._payload(frame, self.ids.error, ERROR)
        if data is None:
            return None
        code, wheel, constraint, twist_counter, residual, count = _ERROR.unpack(data)
        return ErrorReport(
            _enum(ErrorCode, code, ERROR, "Code"),
            wheel,
            _enum(ConstraintCode, constraint, ERROR, "Constraint"),
            twist_counter,
            residual * SPEED_SCALE,
            count,
        )

    def _payload(self, frame: Frame, can_id: int, name: str) -> bytes | None:
        """The 8 data bytes of a frame of message ``name``, ``None`` if it is not one."""
        if frame.arbitration_id != can_id or frame.is_extended_id != self._ext:
            return None
        if frame.is_remote_frame:
            raise DecodeError(
                f"Expected a data frame for {name} (ID {can_id:#x}), but got a remote frame."
            )
        if len(frame.data) != DLC:
            raise DecodeError(
                f"Expected {DLC} data bytes in {name} (ID {can_id:#x}), but got {len(frame.data)}."
            )
        return frame.data


def _twist(vx: int, vy: int, wz: int) -> Twist:
    return Twist(vx * SPEED_SCALE, vy * SPEED_SCALE, wz * SPEED_SCALE)


def _check_flags(flags: int, mask: int, name: str, frame: Frame) -> None:
    if flags & ~mask:
        raise DecodeError(
            f"Expected {name} (ID {frame.arbitration_id:#x}) flags within {mask:#04x}, "
            f"but got {flags:#04x} (reserved bits {flags & ~mask:#04x} set)."
        )


class CounterKind(enum.Enum):
    """How a ``WG_Twist_Cmd`` counter relates to the previous one."""

    #: The previous counter + 1 (mod 256), or the first counter seen.
    NEW = "new"
    #: Equal to the previous counter: a repeated frame; it must not refresh the timeout.
    DUPLICATE = "duplicate"
    #: Anything else: accepted, the frames in between are counted as lost.
    JUMP = "jump"


def classify_counter(last: int | None, counter: int) -> tuple[CounterKind, int]:
    """The kind of ``counter`` after ``last`` (``None``: none yet) and the frames lost.

    >>> classify_counter(254, 1)
    (<CounterKind.JUMP: 'jump'>, 2)
    """
    if last is None or counter == (last + 1) & U8_MAX:
        return CounterKind.NEW, 0
    if counter == last:
        return CounterKind.DUPLICATE, 0
    return CounterKind.JUMP, (counter - last - 1) & U8_MAX


class CounterTracker:
    """Classifies the counters of successive ``WG_Twist_Cmd`` frames (pure, no clock).

    Call :meth:`reset` when the sender is considered gone (e.g. on a command timeout), so
    that its next frame counts as the first one.
    """

    def __init__(self) -> None:
        #: The last counter fed, ``None`` before the first or after :meth:`reset`.
        self.last: int | None = None
        #: Frames counted as lost by jumps so far.
        self.lost_frames = 0
        #: Duplicates seen so far.
        self.duplicates = 0

    def feed(self, counter: int) -> tuple[CounterKind, int]:
        """Classify the next counter and remember it.

        :param counter: 0..255.
        :return: the kind and the frames lost before this one (non-zero for a jump only).
        :raises DecodeError: for a counter outside 0..255.
        """
        if not 0 <= counter <= U8_MAX:
            raise DecodeError(
                f'Expected "Counter" in {TWIST_CMD} between 0 and 255, but got {counter!r}.'
            )
        kind, lost = classify_counter(self.last, counter)
        self.lost_frames += lost
        if kind is CounterKind.DUPLICATE:
            self.duplicates += 1
        self.last = counter
        return kind, lost

    def reset(self) -> None:
        """Forget the last counter (the totals stay)."""
        self.last = None
