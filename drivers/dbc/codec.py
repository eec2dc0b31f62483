"""The pure codec of the generic DBC driver: frames for and from the configured signals.

Messages are described by the user's DBC file; :mod:`drivers.dbc.binding` resolves the names,
so this module only groups the configured signals by frame (several motors may share one
message, e.g. a dual-channel controller with ``Left_Speed`` and ``Right_Speed`` signals) and
calls cantools ``Message.encode`` / ``Message.decode``.  Signals of a message that no motor
configures are sent with their DBC initial value (``GenSigStartValue``), else 0 clamped into
the signal's range.

Motors are named by their position in the bindings (the driver's motor order).  Both
directions are here: the gateway side (:meth:`DbcCodec.encode_command`,
:meth:`DbcCodec.encode_enable`, :meth:`DbcCodec.encode_mode`, and the received frames:
:attr:`DbcCodec.rx`, :meth:`DbcCodec.decode`) and the device side used by the simulator
(:meth:`DbcCodec.decode_request`, :meth:`DbcCodec.encode_feedback`).  Which frames each
operation sends is worked out once, when the codec is built.

A motor's command signal is its velocity command (a drive motor) or its position command (a
steering actuator, :attr:`Role.POSITION_COMMAND`); the signals that select position control
(:attr:`Role.MODE`) always carry their configured value.

DBC format reference: Vector "DBC File Format Documentation" v1.0.5; cantools:
https://cantools.readthedocs.io/en/latest/
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from drivers.dbc.frames import (
    COMMANDS,
    DbcReading,
    DbcRequest,
    Group,
    Member,
    Role,
    finite,
    range_error,
)
from gateway.core.errors import ConfigError, EncodeError
from gateway.core.types import DriveFault

if TYPE_CHECKING:
    from collections.abc import Sequence

    from drivers.dbc.binding import MotorBinding, SignalRef
    from gateway.core.types import Frame

__all__ = ["DbcCodec", "DbcReading", "DbcRequest", "Role", "describe_fault"]

#: Roles that several motors may share on the same signal (a board-wide enable, fault or mode).
_SHAREABLE = (Role.ENABLE, Role.FAULT, Role.MODE)


#: The command messages one operation sends (enable, mode, command), in configuration order.
_Plan = tuple[Group, ...]

#: The key of the motor block that names the message of a signal of each role.
_MESSAGE_KEYS = {
    Role.COMMAND: "command_message",
    Role.POSITION_COMMAND: "position_command_message",
    Role.MODE: "position_mode_message",
    Role.ENABLE: "enable_message",
}


class DbcCodec:
    """Encoder and decoder for the signals the motor blocks name.

    :param bindings: one per motor, from :func:`drivers.dbc.binding.bind_motor`.
    :raises ConfigError: if two motors put different messages on one frame ID, configure the
        same command or feedback signal, a frame ID is used in both directions, or a command
        message cannot be encoded (:meth:`_try_sends`).
    """

    def __init__(self, bindings: Sequence[MotorBinding]) -> None:
        self.bindings = tuple(bindings)
        self.tx: dict[int, Group] = {}
        #: The feedback messages, by frame ID: what :meth:`decode` and the driver take.
        self.rx: dict[int, Group] = {}
        for i, b in enumerate(self.bindings):
            if b.command is not None:
                self._add(self.tx, i, b, Role.COMMAND, b.command)
            if b.target is not None:
                self._add(self.tx, i, b, Role.POSITION_COMMAND, b.target)
            for ref, value in b.mode:
                self._add(self.tx, i, b, Role.MODE, ref, value)
            if b.enable is not None:
                self._add(self.tx, i, b, Role.ENABLE, b.enable)
            self._add(self.rx, i, b, Role.VELOCITY, b.velocity)
            self._add(self.rx, i, b, Role.POSITION, b.position)
            if b.fault is not None:
                self._add(self.rx, i, b, Role.FAULT, b.fault)
        both = sorted(set(self.tx) & set(self.rx))
        if both:
            raise ConfigError(
                f"frame ID 0x{both[0]:X} is configured both as a command "
                f"({self.tx[both[0]].describe()}) and as feedback "
                f"({self.rx[both[0]].describe()})"
            )
        for group in self.rx.values():
            group.compile()
        self._steering = tuple(b.steering for b in self.bindings)
        self._command = self._plan(COMMANDS)
        self._enable = self._plan((Role.ENABLE,))
        self._mode = self._plan((Role.MODE,))
        self._try_sends()

    @staticmethod
    def _add(
        table: dict[int, Group],
        index: int,
        b: MotorBinding,
        role: Role,
        ref: SignalRef,
        fixed: float = 0.0,
    ) -> None:
        group = table.get(ref.frame_id)
        if group is None:
            group = table[ref.frame_id] = Group(ref)
        elif group.message is not ref.message:
            raise ConfigError(
                f"frame ID 0x{ref.frame_id:X} of node {b.node_id} ({b.label!r}) message "
                f'"{ref.message_name}" is already used by {group.describe()}'
            )
        for m in group.members:
            if (
                m.name == ref.name
                and m.node_id != b.node_id
                and not (role == m.role and role in _SHAREABLE and fixed == m.fixed)
            ):
                raise ConfigError(
                    f'signal "{ref.name}" of {group.describe()} is configured for node '
                    f"{m.node_id} ({m.label!r}) and node {b.node_id} ({b.label!r})"
                )
        enable = (b.enable_value, b.disable_value) if role == Role.ENABLE else None
        group.members.append(Member(index, b.node_id, role, ref, b.label, fixed, enable))

    def _try_sends(self) -> None:
        """Encode once every command message, as the driver sends it: the commands at rest
        (zero, within the signal's range) armed and disarmed, the arming and disarming frames,
        the mode frames.  A message cantools cannot encode (an unconfigured signal whose
        initial value is outside its range, a multiplexer that no value selects) is refused
        here, with the configuration, and not when the driver first sends it (at run time
        only the command values change, and they are checked against their signal's range).

        :raises ConfigError: naming the key of the first motor in the message, the message, the
            DBC file and the signal and value that cantools refuses.
        """
        rest = [_rest(b.command if b.target is None else b.target) for b in self.bindings]
        hold = [v if steer else None for v, steer in zip(rest, self._steering, strict=True)]
        drive = [0.0 if h is None else h for h in hold]  # as encode_enable
        n = len(rest)
        trials: list[tuple[_Plan, list[float | None], list[bool] | None, str]] = [
            (self._command, [*rest], [True] * n, "commands at rest, armed"),
            (self._command, [*rest], [False] * n, "commands at rest, disarmed"),
            (self._enable, [*drive], [True] * n, "arming"),
            (self._enable, [*drive], [False] * n, "disarming"),
            (self._mode, hold, None, "position mode"),
        ]
        for plan, values, armed, what in trials:
            for group in plan:
                try:
                    self._frames((group,), values, armed)
                except EncodeError as err:
                    raise self._refusal(group, what, err) from err

    def _refusal(self, group: Group, what: str, err: EncodeError) -> ConfigError:
        first = group.members[0]
        b = self.bindings[first.index]
        head = (
            f"{b.where}.{_MESSAGE_KEYS[first.role]}: cannot send message "
            f"{group.message.name!r} of {b.path}"
        )
        stray = group.stray_default()
        if stray is None:
            return ConfigError(f"{head} ({what}): {err}")
        signal, value, low, high = stray
        return ConfigError(
            f"{head}: signal {signal.name!r}, which no key configures, goes out with its "
            f"initial value (GenSigStartValue); expected a value between {low:g} and "
            f"{high:g}, got {value:g}"
        )

    def _plan(self, roles: tuple[Role, ...]) -> _Plan:
        """The command messages that carry a signal of ``roles``."""
        return tuple(g for g in self.tx.values() if any(m.role in roles for m in g.members))

    # ----------------------------------------------------------------- gateway side

    def encode_command(
        self, values: Sequence[float], armed: Sequence[bool] | None = None
    ) -> list[Frame]:
        """Command frames, one per command message, in configuration order.

        :param values: per motor, the command signal value (physical, signal units): the
            velocity command of a drive motor, the position command of a steering actuator.
        :param armed: per motor, whether it is armed: sets enable signals that share the
            command message (``None``: their default).
        :raises EncodeError: for a value that is not finite or outside the signal's range (a
            value beyond an edge by rounding, :func:`~drivers.dbc.binding.command_range`, is
            sent as the edge).
        """
        return self._frames(self._command, values, armed)

    @property
    def command_ids(self) -> frozenset[int]:
        """The identifiers of the command messages (which go out every cycle)."""
        return frozenset(group.frame_id for group in self._command)

    def encode_enable(
        self, enable: bool, hold: Sequence[float | None] | None = None
    ) -> list[Frame]:
        """Arming (``enable``) or disarming frames for the motors that have an enable signal.

        Velocity commands that share the message are sent as zero, position commands as
        ``hold`` (never the default: that would move a steering actuator).

        :param hold: per motor, the position command value (signal units) of a steering
            actuator (``None`` for a drive motor).
        :raises EncodeError: if a steering actuator has no position to hold.
        """
        values = [0.0 if not steer else self._held(i, hold)
                  for i, steer in enumerate(self._steering)]
        return self._frames(self._enable, values, [enable] * len(values))

    def encode_mode(self, hold: Sequence[float | None] | None = None) -> list[Frame]:
        """Frames that select position control, for the steering actuators that have mode
        signals; their position commands that share the message are sent as ``hold``.

        :param hold: as for :meth:`encode_enable`.
        :raises EncodeError: as :meth:`encode_enable`.
        """
        values = [self._held(i, hold) if steer else None
                  for i, steer in enumerate(self._steering)]
        return self._frames(self._mode, values, None)

    def decode(self, frame: Frame) -> tuple[DbcReading, ...] | None:
        """Feedback in ``frame``, one reading per motor whose signals it carries.

        :return: the readings, or ``None`` if no configured feedback message has this ID.
        :raises DecodeError: for the wrong ID type, a remote frame, the wrong length, or a
            value that is not finite.
        """
        group = self.rx.get(frame.arbitration_id)
        if group is None or frame.is_extended_id != group.extended:
            return None  # another ID, or the same number as the other ID type: not ours
        raw = group.read(frame)
        return tuple(
            DbcReading(
                self.bindings[s.index].node_id,
                None if s.velocity is None else raw[s.velocity] * s.scale + s.offset,
                None if s.position is None else raw[s.position],
                None if s.fault is None else int(raw[s.fault]),
            )
            for s in group.slots
        )

    # ----------------------------------------------------------------- device side

    def decode_request(self, frame: Frame) -> tuple[DbcRequest, ...] | None:
        """Command and arming values in a frame the gateway sent (simulator side).

        :return: the requests, or ``None`` if no configured command message has this ID.
        :raises DecodeError: as :meth:`decode`.
        """
        group = self.tx.get(frame.arbitration_id)
        if group is None or frame.is_extended_id != group.extended:
            return None
        raw = group.read(frame)
        return tuple(
            DbcRequest(m.node_id, m.role, finite(m.ref.to_physical(raw[m.name]), m.ref, group))
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
        frames = []
        for group in self.rx.values():
            if not any(m.node_id in nodes for m in group.members):
                continue
            data = dict(group.defaults)
            for m in group.members:
                value = values.get((m.node_id, m.role))
                if value is None:
                    continue
                if m.role != Role.VELOCITY:  # raw values
                    value = m.ref.to_physical(value)
                if not m.low <= value <= m.high:
                    raise range_error(value, m, group)
                data[m.name] = value
            frames.append(group.frame(data, strict=True))
        return tuple(frames)

    # ----------------------------------------------------------------- internals

    def _held(self, index: int, hold: Sequence[float | None] | None) -> float:
        value = None if hold is None else hold[index]
        if value is None:
            raise EncodeError(
                f"Expected a position to hold for node {self.bindings[index].node_id}, a "
                "steering actuator, but got none."
            )
        return value

    @staticmethod
    def _frames(
        plan: _Plan, values: Sequence[float | None], armed: Sequence[bool] | None
    ) -> list[Frame]:
        """The frames of ``plan``: command signals from ``values`` (``None``: the default),
        enable signals from ``armed`` (``None``: the default), mode signals fixed."""
        frames = []
        for group in plan:
            data = group.defaults.copy()
            for m in group.members:
                if m.enable is not None:
                    if armed is not None:
                        data[m.name] = m.enable[0] if armed[m.index] else m.enable[1]
                elif m.role == Role.MODE:
                    data[m.name] = m.fixed
                else:
                    value = values[m.index]
                    if value is not None:
                        if not m.low <= value <= m.high:  # (nearly always in range)
                            if not m.take_low <= value <= m.take_high:  # also false for NaN
                                raise range_error(value, m, group)
                            value = m.low if value < m.low else m.high  # (rounding)
                        data[m.name] = value
            frames.append(group.frame(data))
        return frames


def _rest(ref: SignalRef | None) -> float | None:
    """A command signal's value at rest: zero, or the edge of its range nearest to zero."""
    return None if ref is None else min(max(0.0, ref.minimum), ref.maximum)


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
