"""The building blocks of the DBC codec (:mod:`drivers.dbc.codec`): what a configured signal
carries, the messages that carry them, and the values a frame gives.

A :class:`Group` is one frame ID with the configured signals (:class:`Member` s) it carries;
:meth:`Group.read` checks and decodes a received frame with cantools and :meth:`Group.frame`
encodes one.  A feedback group also lists, per motor, where its values are
(:class:`FeedbackSlot`), so a received frame is read without building anything per motor.

DBC format reference: Vector "DBC File Format Documentation" v1.0.5; cantools:
https://cantools.readthedocs.io/en/latest/
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import cantools

from drivers.dbc.binding import command_range
from drivers.dbc.signals import signal_range
from gateway.core.errors import DecodeError, EncodeError
from gateway.core.types import Frame

if TYPE_CHECKING:
    from drivers.dbc.binding import SignalRef


class Role(enum.IntEnum):
    """What a configured signal carries."""

    COMMAND = 1
    ENABLE = 2
    VELOCITY = 3
    POSITION = 4
    FAULT = 5
    #: The position command of a steering actuator.
    POSITION_COMMAND = 6
    #: A signal that selects position control (a fixed value per motor).
    MODE = 7


#: The roles of the command signals (velocity, or position for a steering actuator).
COMMANDS = (Role.COMMAND, Role.POSITION_COMMAND)


@dataclass(frozen=True, slots=True)
class DbcReading:
    """What one received frame says about one motor; ``None`` where it says nothing.

    :param node_id: the motor's node ID.
    :param velocity: velocity signal, physical value (signal units).
    :param position_raw: position signal, raw value (int; float for float signals), so
        that wrap-around can be undone exactly.
    :param fault: fault-code signal, raw value (0 = healthy).
    """

    node_id: int
    velocity: float | None = None
    position_raw: int | float | None = None
    fault: int | None = None


@dataclass(frozen=True, slots=True)
class DbcRequest:
    """A command or arming value decoded on the device side.

    :param node_id: the addressed motor's node ID.
    :param role: :attr:`Role.COMMAND`, :attr:`Role.POSITION_COMMAND`, :attr:`Role.ENABLE` or
        :attr:`Role.MODE`.
    :param value: the signal's physical value.
    """

    node_id: int
    role: Role
    value: float


@dataclass(frozen=True, slots=True)
class Member:
    """One configured signal of one motor in a group.

    :param index: the motor's position in the codec's bindings.
    :param fixed: the value a :attr:`Role.MODE` signal always carries.
    :param enable: the (arm, disarm) values of a :attr:`Role.ENABLE` signal, else ``None``.
    """

    index: int
    node_id: int
    role: Role
    ref: SignalRef
    label: str
    fixed: float = 0.0
    enable: tuple[float, float] | None = None
    #: ``ref.name``, read once (the property builds a str on every call).
    name: str = field(init=False)
    #: The physical range the signal carries (``ref.minimum``, ``ref.maximum``).
    low: float = field(init=False)
    high: float = field(init=False)
    #: The command values the codec takes (``binding.command_range``: the range, widened for
    #: rounding; sent clamped into the range).
    take_low: float = field(init=False)
    take_high: float = field(init=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "name", self.ref.name)
        object.__setattr__(self, "low", self.ref.minimum)
        object.__setattr__(self, "high", self.ref.maximum)
        take_low, take_high = command_range(self.ref)
        object.__setattr__(self, "take_low", take_low)
        object.__setattr__(self, "take_high", take_high)


@dataclass(frozen=True, slots=True)
class FeedbackSlot:
    """Where one motor's values are in a decoded feedback frame (signal names, ``None`` when
    the frame does not carry that value).

    :param scale: the velocity signal's factor (raw to physical).
    :param offset: the velocity signal's offset.
    :param fault_signal: the cantools fault signal (its value table names the codes).
    """

    index: int
    velocity: str | None
    scale: float
    offset: float
    position: str | None
    fault: str | None
    fault_signal: Any = None


class Group:
    """The configured signals that travel in one frame ID."""

    def __init__(self, ref: SignalRef) -> None:
        self.message: Any = ref.message
        self.frame_id = ref.frame_id
        self.extended = bool(ref.message.is_extended_frame)
        self.length = int(ref.message.length)
        self.members: list[Member] = []
        self.defaults: dict[str, float] = {s.name: _default(s) for s in ref.message.signals}
        #: Whether cantools must check the values while encoding: only when a default is
        #: outside its signal's range (every configured value is checked before).
        self.strict = not all(_carries(s, self.defaults[s.name]) for s in ref.message.signals)
        #: Per motor whose feedback this frame carries, where it is (:meth:`compile`).
        self.slots: tuple[FeedbackSlot, ...] = ()
        #: The float signals :meth:`read` checks: (name, scale, offset, member).
        self._checks: tuple[tuple[str, Any, Any, Member], ...] = ()

    def stray_default(self) -> tuple[Any, float, float, float] | None:
        """The first signal no member sets whose initial value is outside its range (which
        makes cantools refuse every frame), as (signal, value, low, high); else ``None``."""
        if not self.strict:
            return None
        members = {m.name for m in self.members}
        for s in self.message.signals:
            value = self.defaults[s.name]
            if s.name not in members and not _carries(s, value):
                return (s, value, *signal_range(s))
        return None

    def describe(self) -> str:
        return f'message "{self.message.name}" (0x{self.frame_id:X})'

    def compile(self) -> None:
        """Work out :attr:`slots` and the finiteness checks of a feedback group."""
        by_motor: dict[int, dict[Role, Member]] = {}
        for m in self.members:
            by_motor.setdefault(m.index, {})[m.role] = m
        slots = []
        for index, roles in by_motor.items():
            vel = roles.get(Role.VELOCITY)
            pos = roles.get(Role.POSITION)
            fault = roles.get(Role.FAULT)
            conv = None if vel is None else vel.ref.signal.conversion
            slots.append(FeedbackSlot(
                index,
                None if vel is None else vel.name,
                1 if conv is None else conv.scale,
                0 if conv is None else conv.offset,
                None if pos is None else pos.name,
                None if fault is None else fault.name,
                None if fault is None else fault.ref.signal,
            ))
        self.slots = tuple(slots)
        checks = []
        for m in self.members:
            if m.ref.is_float:  # an integer signal is always finite
                conv = m.ref.signal.conversion
                scale, offset = (conv.scale, conv.offset) if m.role == Role.VELOCITY else (1, 0)
                checks.append((m.name, scale, offset, m))
        self._checks = tuple(checks)

    def read(self, frame: Frame) -> dict[str, Any]:
        """The raw signal values of ``frame`` (of this group's ID and ID type).

        :raises DecodeError: for a remote frame, the wrong length, data cantools cannot
            decode, or a configured feedback value that is not finite.
        """
        if frame.is_remote_frame:
            raise DecodeError(
                f"Expected a data frame for {self.describe()}, but got a remote frame."
            )
        if len(frame.data) != self.length:
            raise DecodeError(
                f"Expected {self.length} bytes for {self.describe()}, but got "
                f"{len(frame.data)}."
            )
        try:
            raw: dict[str, Any] = self.message.decode(
                frame.data, decode_choices=False, scaling=False
            )
        except (cantools.database.DecodeError, ValueError) as err:
            raise DecodeError(f"Cannot decode {self.describe()}: {err}") from err
        for name, scale, offset, m in self._checks:
            finite(raw[name] * scale + offset, m.ref, self)
        return raw

    def frame(self, data: dict[str, float], strict: bool = False) -> Frame:
        """The frame that carries ``data`` (every signal of the message).

        :param strict: let cantools check every value (else only if :attr:`strict`).
        :raises EncodeError: if cantools cannot encode it.
        """
        try:
            payload = self.message.encode(
                data, scaling=True, padding=False, strict=strict or self.strict
            )
        except (cantools.database.EncodeError, OverflowError, ValueError) as err:
            raise EncodeError(f"Cannot encode {self.describe()}: {err}") from err
        return Frame(self.frame_id, payload, is_extended_id=self.extended)


def _carries(signal: Any, value: float) -> bool:
    low, high = signal_range(signal)
    return low <= value <= high


def _default(signal: Any) -> float:
    if signal.raw_initial is not None:
        return float(signal.conversion.raw_to_scaled(signal.raw_initial, False))
    lo = float(signal.minimum) if signal.minimum is not None else -math.inf
    hi = float(signal.maximum) if signal.maximum is not None else math.inf
    return min(max(0.0, lo), hi)


def range_error(value: object, m: Member, group: Group) -> EncodeError:
    """The error for a value outside member ``m``'s signal range."""
    unit = m.ref.signal.unit or ""
    return EncodeError(
        f'Expected signal "{m.name}" of {group.describe()} for node {m.node_id} '
        f'("{m.label}") between {m.low:g} and {m.high:g}'
        f"{' ' + unit if unit else ''}, but got {value!r}."
    )


def finite(value: Any, ref: SignalRef, group: Group) -> Any:
    """``value``, if it is not a float that is infinite or NaN.

    :raises DecodeError: naming the signal and message.
    """
    if isinstance(value, float) and not math.isfinite(value):
        raise DecodeError(
            f'Expected a finite value for signal "{ref.name}" of {group.describe()}, '
            f"but got {value!r}."
        )
    return value
