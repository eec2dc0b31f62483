"""The ``struct`` codec of the five wheelgate messages: :class:`WgCodec`.  Pure: no I/O, no clock.

Each payload layout is one precompiled :class:`struct.Struct` below; the DBC describes the same
layouts and ``tests/wire/test_wgproto_messages.py`` checks that both agree.  The encoders of what
the gateway sends saturate; the twist encoder and every decoder raise (see :mod:`gateway.wire.can`).
"""

from __future__ import annotations

import enum
import math
import struct
from typing import TYPE_CHECKING, TypeVar

from gateway.core.can_ids import CanIds
from gateway.core.errors import DecodeError, EncodeError
from gateway.core.kinematics.odometry import Pose
from gateway.core.types import ConstraintCode, ErrorCode, Frame, GatewayState, Twist
from gateway.wire.can.messages import (
    ANGLE_SCALE,
    DLC,
    ERROR,
    I16_MAX,
    I16_MIN,
    NO_TWIST_COUNTER,
    NO_WHEEL,
    ODOM_POSE,
    ODOM_VELOCITY,
    POSITION_SCALE,
    POSITION_WRAP_M,
    SPEED_SCALE,
    STATUS,
    TWIST_CMD,
    U8_MAX,
    U16_MAX,
    ErrorReport,
    OdomVelocity,
    StatusFlags,
    StatusReport,
    TwistCommand,
    TwistFlags,
)

if TYPE_CHECKING:
    from collections.abc import Callable

    from gateway.wire.can.messages import WgMessage

_TWIST = struct.Struct("<hhhBB")
_POSE = struct.Struct("<3s3sh")
_VELOCITY = struct.Struct("<hhhH")
_STATUS = struct.Struct("<BBBBHH")
_ERROR = struct.Struct("<BBBBHH")

_E = TypeVar("_E", bound=enum.IntEnum)
_TWIST_FLAGS_MASK = sum(f.value for f in TwistFlags)
_STATUS_FLAGS_MASK = sum(f.value for f in StatusFlags)


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

