"""The pure codec of the generic DBC driver: frames for and from the configured signals.

Messages are described by the user's DBC file; :mod:`drivers.dbc.binding` resolves the names,
so this module only groups the configured signals by frame (several motors may share one
message, e.g. a dual-channel controller with ``Left_Speed`` and ``Right_Speed`` signals) and
calls cantools ``Message.encode`` / ``Message.decode``.  Signals of a message that no motor
configures are sent with their DBC initial value (``GenSigStartValue``), else 0 clamped into
the signal's range.

Both directions are here: the gateway side (:meth:`DbcCodec.encode_command`,
:meth:`DbcCodec.encode_enable`, :meth:`DbcCodec.encode_mode`, :meth:`DbcCodec.decode`) and the
device side used by the simulator (:meth:`DbcCodec.decode_request`,
:meth:`DbcCodec.encode_feedback`).

A motor's command signal is its velocity command (a drive motor) or its position command (a
steering actuator, :attr:`Role.POSITION_COMMAND`); the signals that select position control
(:attr:`Role.MODE`) always carry their configured value.

DBC format reference: Vector "DBC File Format Documentation" v1.0.5; cantools:
https://cantools.readthedocs.io/en/latest/
"""

from __future__ import annotations

import enum
import logging
import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import cantools

from gateway.core.errors import ConfigError, DecodeError, EncodeError
from gateway.core.types import DriveFault, Frame
from gateway.drive.codec import MotorCodec

if TYPE_CHECKING:
    from collections.abc import Iterable, Mapping, Sequence

    from drivers.dbc.binding import MotorBinding, SignalRef

log = logging.getLogger(__name__)


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


_COMMANDS = (Role.COMMAND, Role.POSITION_COMMAND)
#: Roles that several motors may share on the same signal (a board-wide enable, fault or mode).
_SHAREABLE = (Role.ENABLE, Role.FAULT, Role.MODE)


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
class _Member:
    node_id: int
    role: Role
    ref: SignalRef
    label: str
    #: The value a :attr:`Role.MODE` signal always carries.
    fixed: float = 0.0
    #: ``ref.name``, read once: the property builds a str on every call, and every received
    #: frame looks up each member's signal by name.
    name: str = field(init=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "name", self.ref.name)


class _Group:
    """The configured signals that travel in one frame ID."""

    def __init__(self, ref: SignalRef) -> None:
        self.message: Any = ref.message
        self.frame_id = ref.frame_id
        self.members: list[_Member] = []
        self.defaults: dict[str, float] = {s.name: _default(s) for s in ref.message.signals}

    def describe(self) -> str:
        return f'message "{self.message.name}" (0x{self.frame_id:X})'


def _default(signal: Any) -> float:
    if signal.raw_initial is not None:
        return float(signal.conversion.raw_to_scaled(signal.raw_initial, False))
    lo = float(signal.minimum) if signal.minimum is not None else -math.inf
    hi = float(signal.maximum) if signal.maximum is not None else math.inf
    return min(max(0.0, lo), hi)


class DbcCodec(MotorCodec[tuple[DbcReading, ...]]):
    """Encoder and decoder for the signals the motor blocks name.

    :param bindings: one per motor, from :func:`drivers.dbc.binding.bind_motor`.
    :raises ConfigError: if two motors put different messages on one frame ID, configure the
        same command or feedback signal, or a frame ID is used in both directions.
    """

    def __init__(self, bindings: Sequence[MotorBinding]) -> None:
        self.bindings = tuple(bindings)
        self._tx: dict[int, _Group] = {}
        self._rx: dict[int, _Group] = {}
        for b in self.bindings:
            if b.command is not None:
                self._add(self._tx, b, Role.COMMAND, b.command)
            if b.target is not None:
                self._add(self._tx, b, Role.POSITION_COMMAND, b.target)
            for ref, value in b.mode:
                self._add(self._tx, b, Role.MODE, ref, value)
            if b.enable is not None:
                self._add(self._tx, b, Role.ENABLE, b.enable)
            self._add(self._rx, b, Role.VELOCITY, b.velocity)
            self._add(self._rx, b, Role.POSITION, b.position)
            if b.fault is not None:
                self._add(self._rx, b, Role.FAULT, b.fault)
        #: (frame ID, extended) of every feedback message :meth:`decode` takes.
        self.received_ids: frozenset[tuple[int, bool]] = frozenset(
            (i, bool(g.message.is_extended_frame)) for i, g in self._rx.items())
        both = sorted(set(self._tx) & set(self._rx))
        if both:
            raise ConfigError(
                f"frame ID 0x{both[0]:X} is configured both as a command "
                f"({self._tx[both[0]].describe()}) and as feedback "
                f"({self._rx[both[0]].describe()})"
            )
        self._enable_values = {b.node_id: (b.enable_value, b.disable_value) for b in bindings}
        self._command_role = {
            b.node_id: Role.COMMAND if b.command is not None else Role.POSITION_COMMAND
            for b in bindings
        }

    @staticmethod
    def _add(
        table: dict[int, _Group], b: MotorBinding, role: Role, ref: SignalRef, fixed: float = 0.0
    ) -> None:
        group = table.get(ref.frame_id)
        if group is None:
            group = table[ref.frame_id] = _Group(ref)
        elif group.message is not ref.message:
            raise ConfigError(
                f"frame ID 0x{ref.frame_id:X} of node {b.node_id} ({b.label!r}) message "
                f'"{ref.message_name}" is already used by {group.describe()}'
            )
        for m in group.members:
            if (
                m.ref.name == ref.name
                and m.node_id != b.node_id
                and not (role == m.role and role in _SHAREABLE and fixed == m.fixed)
            ):
                raise ConfigError(
                    f'signal "{ref.name}" of {group.describe()} is configured for node '
                    f"{m.node_id} ({m.label!r}) and node {b.node_id} ({b.label!r})"
                )
        group.members.append(_Member(b.node_id, role, ref, b.label, fixed))

    # ----------------------------------------------------------------- gateway side

    def encode_command(
        self, commands: Mapping[int, float], armed: Mapping[int, bool] | None = None
    ) -> tuple[Frame, ...]:
        """Command frames, one per command message touched, in configuration order.

        :param commands: node ID -> command signal value (physical, signal units): the
            velocity command of a drive motor, the position command of a steering actuator.
            A motor that shares a message with a commanded one but is absent gets the default.
        :param armed: node ID -> armed; sets enable signals that share the command message.
        :raises EncodeError: for a value that is not finite or outside the signal's range.
        """
        role = self._command_role
        values: dict[tuple[int, Role], float] = {
            (node, role[node]): value for node, value in commands.items()
        }
        for node, on in (armed or {}).items():
            values[(node, Role.ENABLE)] = self._enable_values[node][0 if on else 1]
        return self._encode(self._tx, values, set(commands), _COMMANDS)

    def encode_enable(
        self, node_ids: Iterable[int], enable: bool, hold: Mapping[int, float] | None = None
    ) -> tuple[Frame, ...]:
        """Arming (``enable``) or disarming frames for the motors that have an enable signal.

        Velocity commands that share the message are sent as zero, position commands as
        ``hold`` (never the default: that would move a steering actuator).

        :param node_ids: the motors to arm or disarm.
        :param hold: node ID -> position command value (signal units) of steering actuators.
        :raises EncodeError: if a configured value does not fit the signal.
        """
        values = self._held(node_ids, hold)
        nodes = {node for node, _ in values}
        for node in nodes:
            values[(node, Role.ENABLE)] = self._enable_values[node][0 if enable else 1]
        return self._encode(self._tx, values, nodes, (Role.ENABLE,))

    def encode_mode(
        self, node_ids: Iterable[int], hold: Mapping[int, float] | None = None
    ) -> tuple[Frame, ...]:
        """Frames that select position control, for the motors that have mode signals.

        Commands that share the message are sent as in :meth:`encode_enable`.

        :param node_ids: the motors to switch.
        :param hold: as for :meth:`encode_enable`.
        :raises EncodeError: if a configured value does not fit the signal.
        """
        values = self._held(node_ids, hold)
        return self._encode(self._tx, values, {n for n, _ in values}, (Role.MODE,))

    def decode(self, frame: Frame) -> tuple[DbcReading, ...] | None:
        """Feedback in ``frame``, one reading per motor whose signals it carries.

        :return: the readings, or ``None`` if no configured feedback message has this ID.
        :raises DecodeError: for the wrong ID type, a remote frame, the wrong length, or a
            value that is not finite.
        """
        group = self._rx.get(frame.arbitration_id)
        if group is None or frame.is_extended_id != bool(group.message.is_extended_frame):
            return None  # another ID, or the same number as the other ID type: not ours
        raw = _decode_raw(group, frame)
        per_node: dict[int, dict[str, Any]] = {}
        for m in group.members:
            value = raw[m.name]
            slot = per_node.setdefault(m.node_id, {})
            role = m.role
            if role == Role.VELOCITY:
                slot["velocity"] = _finite(m.ref.to_physical(value), m.ref, group)
            elif role == Role.POSITION:
                slot["position_raw"] = _finite(value, m.ref, group)
            else:
                slot["fault"] = int(value)
        return tuple(DbcReading(node, **fields) for node, fields in per_node.items())

    # ----------------------------------------------------------------- device side

    def decode_request(self, frame: Frame) -> tuple[DbcRequest, ...] | None:
        """Command and arming values in a frame the gateway sent (simulator side).

        :return: the requests, or ``None`` if no configured command message has this ID.
        :raises DecodeError: as :meth:`decode`.
        """
        group = self._tx.get(frame.arbitration_id)
        if group is None or frame.is_extended_id != bool(group.message.is_extended_frame):
            return None
        raw = _decode_raw(group, frame)
        return tuple(
            DbcRequest(m.node_id, m.role, _finite(m.ref.to_physical(raw[m.ref.name]), m.ref, group))
            for m in group.members
        )

    def encode_feedback(self, readings: Sequence[DbcReading]) -> tuple[Frame, ...]:
        """Feedback frames that carry ``readings`` (simulator side).

        :param readings: per motor, the values to send; ``None`` fields get the default.
        :raises EncodeError: for a value outside its signal's range.
        """
        values: dict[tuple[int, Role], float] = {}
        for r in readings:
            if r.velocity is not None:
                values[(r.node_id, Role.VELOCITY)] = r.velocity
            if r.position_raw is not None:
                values[(r.node_id, Role.POSITION)] = r.position_raw
            if r.fault is not None:
                values[(r.node_id, Role.FAULT)] = r.fault
        nodes = {r.node_id for r in readings}
        return self._encode(self._rx, values, nodes, None)

    # ----------------------------------------------------------------- internals

    def _held(
        self, node_ids: Iterable[int], hold: Mapping[int, float] | None
    ) -> dict[tuple[int, Role], float]:
        """Zero velocity commands and held position commands of ``node_ids``."""
        values: dict[tuple[int, Role], float] = {}
        for node in node_ids:
            role = self._command_role[node]
            if role == Role.COMMAND:
                values[(node, role)] = 0.0
            elif hold is not None and node in hold:
                values[(node, role)] = hold[node]
            else:
                raise EncodeError(
                    f"Expected a position to hold for node {node}, a steering actuator, "
                    "but got none."
                )
        return values

    def _encode(
        self,
        table: dict[int, _Group],
        values: dict[tuple[int, Role], float],
        nodes: set[int],
        needed: tuple[Role, ...] | None,
    ) -> tuple[Frame, ...]:
        frames = []
        for group in table.values():
            if not any(
                m.node_id in nodes and (needed is None or m.role in needed)
                for m in group.members
            ):
                continue
            data = dict(group.defaults)
            for m in group.members:
                if m.role == Role.MODE:
                    if m.node_id in nodes:
                        data[m.name] = m.fixed
                    continue
                key = (m.node_id, m.role)
                if key not in values:
                    continue
                value = values[key]
                if m.role in (Role.POSITION, Role.FAULT):
                    value = m.ref.to_physical(value)
                _check_range(value, m, group)
                data[m.name] = value
            try:
                payload = group.message.encode(data, scaling=True, padding=False, strict=True)
            except (cantools.database.EncodeError, OverflowError, ValueError) as err:
                raise EncodeError(f"Cannot encode {group.describe()}: {err}") from err
            frames.append(
                Frame(
                    group.frame_id,
                    bytes(payload),
                    is_extended_id=bool(group.message.is_extended_frame),
                )
            )
        return tuple(frames)


def describe_fault(signal: Any, raw: int) -> tuple[DriveFault, str]:
    """Fault flags and text for a raw fault code.

    A code listed in the signal's value table (``VAL_``) is named by it; otherwise the code is
    split into the single-bit entries of the table (a bit field), with any bits left over shown
    in hex.  A name equal to a :class:`~gateway.core.types.DriveFault` member (``OVER_CURRENT``,
    ``ENCODER``, ...) maps onto it; every other name maps onto ``DriveFault.OTHER``.

    :param signal: the cantools fault signal.
    :param raw: its raw value; 0 means healthy.
    :return: the flags and a text such as ``"Fault_Code=OVER_TEMPERATURE|0x40"``.
    """
    if raw == 0:
        return DriveFault.NONE, ""
    choices = {int(k): str(v) for k, v in (signal.choices or {}).items()}
    names: list[str] = []
    if raw in choices:
        names.append(choices[raw])
    elif raw > 0:
        rest = raw
        for bit in sorted(k for k in choices if k > 0 and k & (k - 1) == 0):
            if raw & bit:
                names.append(choices[bit])
                rest &= ~bit
        if rest:
            names.append(f"0x{rest:X}")
    else:
        names.append(str(raw))
    flags = DriveFault.NONE
    for name in names:
        flags |= DriveFault.__members__.get(name.upper(), DriveFault.OTHER)
    return flags or DriveFault.OTHER, f"{signal.name}={'|'.join(names)}"


def _check_range(value: float, m: _Member, group: _Group) -> None:
    ref = m.ref
    if not (isinstance(value, (int, float)) and ref.minimum <= value <= ref.maximum):
        unit = ref.signal.unit or ""
        raise EncodeError(
            f'Expected signal "{ref.name}" of {group.describe()} for node {m.node_id} '
            f'("{m.label}") between {ref.minimum:g} and {ref.maximum:g}'
            f"{' ' + unit if unit else ''}, but got {value!r}."
        )


def _finite(value: Any, ref: SignalRef, group: _Group) -> Any:
    if isinstance(value, float) and not math.isfinite(value):
        raise DecodeError(
            f'Expected a finite value for signal "{ref.name}" of {group.describe()}, '
            f"but got {value!r}."
        )
    return value


def _decode_raw(group: _Group, frame: Frame) -> dict[str, Any]:
    msg = group.message
    if frame.is_extended_id != bool(msg.is_extended_frame):
        want, got = (
            ("an extended", "a standard")
            if msg.is_extended_frame
            else ("a standard", "an extended")
        )
        raise DecodeError(f"Expected {want} ID for {group.describe()}, but got {got} ID.")
    if frame.is_remote_frame:
        raise DecodeError(f"Expected a data frame for {group.describe()}, but got a remote frame.")
    if len(frame.data) != msg.length:
        raise DecodeError(
            f"Expected {msg.length} bytes for {group.describe()}, but got {len(frame.data)}."
        )
    try:
        return dict(msg.decode(frame.data, decode_choices=False, scaling=False))
    except (cantools.database.DecodeError, ValueError) as err:
        raise DecodeError(f"Cannot decode {group.describe()}: {err}") from err
