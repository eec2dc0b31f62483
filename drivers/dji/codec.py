"""Pure codec of the DJI RoboMaster C620 / C610 CAN protocol (no I/O, no clock).

Reference: DJI's own example firmware, `RoboMaster/Development-Board-C-Examples
<https://github.com/RoboMaster/Development-Board-C-Examples>`_ ``14.CAN/application/
CAN_receive.{h,c}`` (``CAN_cmd_chassis``, ``get_motor_measure``), and `RoboRTS-Firmware
<https://github.com/RoboMaster/RoboRTS-Firmware>`_ ``components/devices/motor.c`` for the
angle unwrapping; summarised in the RoboMaster C620/C610 user guides' CAN protocol sections.

Frames are classical CAN, 11-bit IDs, DLC 8, big endian:

* command ``0x200`` carries ESCs 1-4 and ``0x1FF`` ESCs 5-8, one int16 torque-current set point
  each (C620: -16384..16384 = -20..20 A; C610: -10000..10000 = -10..10 A);
* feedback ``0x200 + esc_id`` (``0x201..0x208``) at about 1 kHz: u16 rotor angle 0..8191,
  i16 rotor speed [rpm], i16 actual current (command scale), u8 temperature [degC], u8 reserved.

``0x700`` (quick ID-setting mode) is named in :class:`DjiFrameId` only so that tests can prove
it is never produced; nothing in this package builds it.
"""

from __future__ import annotations

import enum
import math
import struct
from dataclasses import dataclass
from typing import TYPE_CHECKING

from gateway.core.errors import DecodeError, EncodeError
from gateway.core.types import Frame

if TYPE_CHECKING:
    from collections.abc import Iterable, Mapping, Sequence

#: Encoder counts per rotor turn (13-bit angle).
COUNTS_PER_REV = 8192
#: Half a turn: the unwrapping threshold.
HALF_REV_COUNTS = COUNTS_PER_REV // 2
#: ESC IDs (set with the ESC's button) and the driver's node IDs.
ESC_ID_MIN = 1
ESC_ID_MAX = 8
#: ESCs per command frame.
ESCS_PER_GROUP = 4
#: Feedback identifier of ESC ``n`` is ``FEEDBACK_ID_BASE + n``.
FEEDBACK_ID_BASE = 0x200
#: Each ESC's feedback frames a second (the user guides: 1 kHz), fixed in the ESC.
FEEDBACK_HZ = 1000.0
#: rad/s per rpm.
RAD_S_PER_RPM = 2.0 * math.pi / 60.0
#: M3508 planetary gearbox ratio (rotor turns per output turn), 3591/187 ~ 19.2032.
M3508_GEAR_RATIO = 3591.0 / 187.0
#: M2006 gearbox ratio.
M2006_GEAR_RATIO = 36.0


class DjiFrameId(enum.IntEnum):
    """Fixed arbitration IDs of the protocol."""

    #: Current set points of ESC 1-4.
    COMMAND_ESC_1_4 = 0x200
    #: Current set points of ESC 5-8 (shared with GM6020 IDs 1-4 on a mixed bus).
    COMMAND_ESC_5_8 = 0x1FF
    #: Puts C620s into quick ID-setting mode.  NEVER sent by wheelgate.
    QUICK_ID_SET = 0x700


@dataclass(frozen=True, slots=True)
class EscModel:
    """Scaling of one ESC type.

    :param name: config name, ``"c620"`` or ``"c610"``.
    :param full_scale_raw: largest raw current value (both signs).
    :param full_scale_a: current in A that ``full_scale_raw`` stands for.
    :param reports_temperature: whether feedback byte 6 carries a temperature.
    :param motor: the motor this ESC drives, for messages.
    :param gear_ratio: that motor's gearbox ratio (rotor turns per output turn).
    """

    name: str
    full_scale_raw: int
    full_scale_a: float
    reports_temperature: bool
    motor: str
    gear_ratio: float

    def amps_to_raw(self, current_a: float) -> int:
        """Raw set point for ``current_a`` (rounded, not clamped)."""
        return round(current_a * self.full_scale_raw / self.full_scale_a)

    def raw_to_amps(self, raw: int) -> float:
        """Current in A for a raw value."""
        return raw * self.full_scale_a / self.full_scale_raw


C620 = EscModel("c620", 16384, 20.0, True, "M3508", M3508_GEAR_RATIO)
C610 = EscModel("c610", 10000, 10.0, False, "M2006", M2006_GEAR_RATIO)
#: ESC types by config name.
ESC_MODELS: Mapping[str, EscModel] = {m.name: m for m in (C620, C610)}


@dataclass(frozen=True, slots=True)
class DjiFeedback:
    """One decoded feedback frame, raw device units.

    :param esc_id: 1..8.
    :param angle_count: rotor angle, 0..8191 for 0..360 degrees.
    :param speed_rpm: rotor speed in rpm (motor side, before the gearbox).
    :param current_raw: actual torque current, command scale.
    :param temperature_c: temperature in degC (C620; 0 on a C610).
    """

    esc_id: int
    angle_count: int
    speed_rpm: int
    current_raw: int
    temperature_c: int


# Field tables (one source of truth per layout).
#: Four int16 current set points, big endian.
COMMAND_STRUCT = struct.Struct(">hhhh")
#: angle u16, speed i16, current i16, temperature u8, reserved u8, big endian.
FEEDBACK_STRUCT = struct.Struct(">HhhBB")
_INT16_MIN, _INT16_MAX = -0x8000, 0x7FFF
_FEEDBACK_UNPACK = FEEDBACK_STRUCT.unpack
_FEEDBACK_SIZE = FEEDBACK_STRUCT.size


def feedback_id(esc_id: int) -> int:
    """The feedback arbitration ID of ``esc_id``."""
    return FEEDBACK_ID_BASE + esc_id


def unwrap_delta(last_count: int, count: int) -> int:
    """Signed count change between two 13-bit angles, taking the shorter way round.

    >>> unwrap_delta(8100, 50)
    142
    >>> unwrap_delta(50, 8100)
    -142

    :param last_count: previous angle, 0..8191.
    :param count: new angle, 0..8191.
    :return: the change in counts, -4096..4096.
    """
    d = count - last_count
    if d > HALF_REV_COUNTS:
        d -= COUNTS_PER_REV
    elif d < -HALF_REV_COUNTS:
        d += COUNTS_PER_REV
    return d


def _check_esc_id(esc_id: int) -> None:
    if isinstance(esc_id, bool) or not isinstance(esc_id, int):
        raise EncodeError(f"Expected an int ESC ID, but got {esc_id!r}.")
    if not ESC_ID_MIN <= esc_id <= ESC_ID_MAX:
        raise EncodeError(
            f"Expected ESC ID between {ESC_ID_MIN} and {ESC_ID_MAX}, but got {esc_id}."
        )


def encode_feedback(fb: DjiFeedback) -> Frame:
    """The feedback frame an ESC sends (used by the simulator and tests).

    :raises EncodeError: if a field does not fit its wire type.
    """
    _check_esc_id(fb.esc_id)
    checks = (
        ("angle", fb.angle_count, 0, COUNTS_PER_REV - 1),
        ("speed", fb.speed_rpm, _INT16_MIN, _INT16_MAX),
        ("current", fb.current_raw, _INT16_MIN, _INT16_MAX),
        ("temperature", fb.temperature_c, 0, 0xFF),
    )
    for name, value, lo, hi in checks:
        if not lo <= value <= hi:
            raise EncodeError(
                f"Expected {name} for ESC {fb.esc_id} between {lo} and {hi}, but got {value}."
            )
    data = FEEDBACK_STRUCT.pack(fb.angle_count, fb.speed_rpm, fb.current_raw, fb.temperature_c, 0)
    return Frame(feedback_id(fb.esc_id), data)


def _check_shape(frame: Frame, what: str) -> None:
    if frame.is_extended_id:
        raise DecodeError(
            f"Expected an 11-bit ID for DJI {what} 0x{frame.arbitration_id:03X}, "
            "but got a 29-bit ID."
        )
    if frame.is_remote_frame:
        raise DecodeError(
            f"Expected a data frame for DJI {what} 0x{frame.arbitration_id:03X}, "
            "but got a remote frame."
        )
    if len(frame.data) != FEEDBACK_STRUCT.size:
        raise DecodeError(
            f"Expected 8 data bytes for DJI {what} 0x{frame.arbitration_id:03X}, "
            f"but got {len(frame.data)}."
        )


def feedback_fields(frame: Frame) -> tuple[int, int, int, int, int]:
    """The fields of an ESC feedback frame, whatever its ID: rotor angle (0..8191), rotor speed
    (rpm), actual current (command scale), temperature (degC) and the reserved byte.

    The driver calls this for every feedback frame (no object beyond the tuple).

    :raises DecodeError: for a 29-bit ID, RTR, DLC other than 8, or an angle above 8191.
    """
    data = frame.data
    # Every feedback frame: _check_shape's three tests inline, the call only to raise.
    if frame.is_extended_id or frame.is_remote_frame or len(data) != _FEEDBACK_SIZE:
        _check_shape(frame, "feedback")
    fields: tuple[int, int, int, int, int] = _FEEDBACK_UNPACK(data)
    if fields[0] >= COUNTS_PER_REV:
        raise DecodeError(
            f"Expected rotor angle for ESC {frame.arbitration_id - FEEDBACK_ID_BASE} between 0 "
            f"and {COUNTS_PER_REV - 1}, but got {fields[0]}."
        )
    return fields


def decode_feedback(frame: Frame) -> DjiFeedback | None:
    """Decode an ESC feedback frame (:func:`feedback_fields` as a :class:`DjiFeedback`).

    :return: the feedback, or ``None`` if the ID is not ``0x201..0x208``.
    :raises DecodeError: for a feedback ID with a 29-bit ID, RTR, DLC other than 8, or an
        angle above 8191.
    """
    esc_id = frame.arbitration_id - FEEDBACK_ID_BASE
    if not ESC_ID_MIN <= esc_id <= ESC_ID_MAX:
        return None
    angle, speed, current, temp, _reserved = feedback_fields(frame)
    return DjiFeedback(esc_id, angle, speed, current, temp)


def decode_command(frame: Frame) -> dict[int, int] | None:
    """Decode a current command frame (the ESC's view; used by the simulator).

    :return: ESC ID -> raw current for the four slots, or ``None`` if the ID is neither
        ``0x200`` nor ``0x1FF``.
    :raises DecodeError: for a 29-bit ID, RTR or a DLC other than 8.
    """
    if frame.arbitration_id == DjiFrameId.COMMAND_ESC_1_4:
        first = 1
    elif frame.arbitration_id == DjiFrameId.COMMAND_ESC_5_8:
        first = 1 + ESCS_PER_GROUP
    else:
        return None
    _check_shape(frame, "command")
    values = COMMAND_STRUCT.unpack(frame.data)
    return {first + k: v for k, v in enumerate(values)}


#: The command frames' IDs as plain ints, by group (ESC 1-4, ESC 5-8): the sending order.
COMMAND_IDS = (int(DjiFrameId.COMMAND_ESC_1_4), int(DjiFrameId.COMMAND_ESC_5_8))
_COMMAND_PACK = COMMAND_STRUCT.pack


def group_of(esc_id: int) -> int:
    """The command group (index into :data:`COMMAND_IDS`) that carries ``esc_id`` (1..8)."""
    return (esc_id - 1) // ESCS_PER_GROUP


def encode_command(raw: Sequence[int], groups: Iterable[int]) -> list[Frame]:
    """The current command frames of ``groups``, in the order given.

    The driver calls this every cycle, so nothing is checked that its current limit already
    guarantees: every value must be within its ESC's full scale (C620 16384, C610 10000).

    :param raw: the raw current set points of ESC 1..8 (``raw[esc_id - 1]``), 8 ints.
    :param groups: which frames: 0 for ``0x200`` (ESC 1-4), 1 for ``0x1FF`` (ESC 5-8).
    :raises EncodeError: for a value that does not fit an int16.
    """
    frames = []
    try:
        for g in groups:
            k = g * ESCS_PER_GROUP
            frames.append(Frame(COMMAND_IDS[g], _COMMAND_PACK(raw[k], raw[k + 1], raw[k + 2],
                                                              raw[k + 3])))
    except struct.error as err:
        raise EncodeError(
            f"Expected int16 current set points for DJI ESCs, but got {list(raw)}: {err}."
        ) from err
    return frames


def message_name(arbitration_id: int) -> str | None:
    """The protocol's name of an 11-bit frame: a :class:`DjiFrameId` name, or
    ``FEEDBACK_ESC_<n>`` for ``0x200 + n``; ``None`` for any other ID."""
    try:
        return DjiFrameId(arbitration_id).name
    except ValueError:
        esc = arbitration_id - FEEDBACK_ID_BASE
        return f"FEEDBACK_ESC_{esc}" if ESC_ID_MIN <= esc <= ESC_ID_MAX else None
