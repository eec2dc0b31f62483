"""Binds a motor block's names to the messages and signals of its DBC file.

:func:`bind_motor` loads the DBC (through a :class:`~drivers.dbc.database.DatabaseCache`, so
motors that share a file parse it once), looks up every configured message and signal, computes
the frame IDs on the wire from the node ID, and the range each signal can carry.  Names that do
not exist raise :class:`~gateway.core.errors.ConfigError` listing the names that do; so do
signals the driver cannot use: a multiplexed signal, a scale of zero or one too large for a
float (:mod:`drivers.dbc.signals`), an enable, disable or mode value between two steps of its
signal, a velocity command too narrow for the motor's ``max_rpm`` (:func:`check_command`),
position signals too narrow for a steering actuator's travel (:func:`check_travel`).  The
result is a frozen :class:`MotorBinding`, the only input the pure codec needs; the codec then
encodes each message it sends once (:meth:`drivers.dbc.codec.DbcCodec._try_sends`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from drivers.dbc.database import resolve_path
from drivers.dbc.signals import check_enable_values, check_value, checked_range, multiplexing
from drivers.dbc.units import UnitConversion
from gateway.core.errors import ConfigError
from gateway.core.types import MAX_EXTENDED_ID, MAX_STANDARD_ID
from gateway.drive.setpoints import bounds

if TYPE_CHECKING:
    from drivers.dbc.database import DatabaseCache
    from drivers.dbc.options import DbcOptions
    from gateway.core.types import MotorConfig

#: Share of a command signal's range edge by which a command value may pass it: the rounding of
#: the unit conversions and of the speed limits (the codec sends such a value as the edge).
ROUNDING = 1e-6


@dataclass(frozen=True, slots=True)
class SignalRef:
    """One configured signal of one message, as it goes on the wire for one node.

    :param message: the cantools ``Message``.
    :param signal: the cantools ``Signal`` inside it.
    :param frame_id: the arbitration ID on the wire (DBC ID plus the node part).
    :param minimum: smallest physical value the signal carries (DBC range and bit width).
    :param maximum: largest physical value the signal carries.
    """

    message: Any
    signal: Any
    frame_id: int
    minimum: float
    maximum: float

    @property
    def name(self) -> str:
        """The signal's name."""
        return str(self.signal.name)

    @property
    def message_name(self) -> str:
        """The message's name."""
        return str(self.message.name)

    @property
    def is_extended(self) -> bool:
        """Whether the message uses a 29-bit identifier."""
        return bool(self.message.is_extended_frame)

    @property
    def is_float(self) -> bool:
        """Whether the raw value is an IEEE-754 float."""
        return bool(self.signal.is_float)

    @property
    def scale(self) -> float:
        """Physical units per raw step."""
        return float(self.signal.scale)

    def to_physical(self, raw: float) -> float:
        """The physical value of a raw value."""
        return float(self.signal.conversion.raw_to_scaled(raw, False))


@dataclass(frozen=True, slots=True)
class MotorBinding:
    """Everything the codec needs to know about one motor.

    :param node_id: the controller's node ID.
    :param label: the wheel's name, for messages.
    :param command: the velocity command signal (a drive motor), else ``None``.
    :param velocity: the velocity feedback signal.
    :param position: the position feedback signal.
    :param fault: the fault-code signal, if configured.
    :param enable: the arming signal, if configured.
    :param enable_value: value of ``enable`` that arms.
    :param disable_value: value of ``enable`` that disarms.
    :param target: the position command signal (a steering actuator), else ``None``.
    :param mode: the signals that select position control, each with the value that does.
    :param where: file and key path of the motor block, for messages.
    :param path: the DBC file, for messages.
    """

    node_id: int
    label: str
    command: SignalRef | None
    velocity: SignalRef
    position: SignalRef
    fault: SignalRef | None = None
    enable: SignalRef | None = None
    enable_value: float = 1.0
    disable_value: float = 0.0
    target: SignalRef | None = None
    mode: tuple[tuple[SignalRef, float], ...] = ()
    where: str = ""
    path: str = ""

    @property
    def steering(self) -> bool:
        """Whether this motor is commanded in position (a steering actuator)."""
        return self.target is not None


def command_range(ref: SignalRef) -> tuple[float, float]:
    """The command values the codec takes for ``ref``: its range with each edge widened by
    :data:`ROUNDING` of itself (a value beyond an edge, but within that, is sent as the edge)."""
    return ref.minimum - abs(ref.minimum) * ROUNDING, ref.maximum + abs(ref.maximum) * ROUNDING


def _known(names: list[str]) -> str:
    return ", ".join(sorted(names)) or "none"


def _message(db: Any, name: str, key: str, path: str, where: str) -> Any:
    try:
        return db.get_message_by_name(name)
    except KeyError:
        known = _known([m.name for m in db.messages])
        raise ConfigError(
            f"{where}.{key}: no message {name!r} in {path}; known messages: {known}"
        ) from None


def _signal(
    db: Any,
    msg_name: str,
    sig_name: str,
    keys: tuple[str, str],
    path: str,
    where: str,
    motor: MotorConfig,
    opts: DbcOptions,
) -> SignalRef:
    msg = _message(db, msg_name, keys[0], path, where)
    try:
        sig = msg.get_signal_by_name(sig_name)
    except KeyError:
        known = _known([s.name for s in msg.signals])
        raise ConfigError(
            f"{where}.{keys[1]}: message {msg_name!r} has no signal {sig_name!r}; "
            f"known signals: {known} (in {path})"
        ) from None
    how = multiplexing(msg, sig)
    if how is not None:
        raise ConfigError(
            f"{where}.{keys[1]}: expected a signal that is not multiplexed, got signal "
            f"{sig_name!r} of message {msg_name!r} in {path}, {how}; this driver does not "
            "support multiplexed messages"
        )
    ranges: dict[str, tuple[float, float]] = {}
    for each in (sig, *msg.signals):  # cantools divides by it to encode (the whole message)
        key, beside = (keys[1], "") if each is sig else (keys[0], f" (beside {sig_name!r})")
        if each.scale == 0:
            raise ConfigError(
                f"{where}.{key}: expected a non-zero scale for signal {each.name!r}{beside} of "
                f"message {msg_name!r} in {path}, got {each.scale:g}"
            )
        ranges[each.name] = checked_range(
            each, f"{each.name!r}{beside}", msg_name, key, path, where
        )
    frame_id = int(msg.frame_id)
    if opts.node_id_in_frame == "add":
        frame_id += motor.node_id << opts.node_id_shift
    top = MAX_EXTENDED_ID if msg.is_extended_frame else MAX_STANDARD_ID
    if frame_id > top:
        raise ConfigError(
            f"{where}.{keys[0]}: expected a frame ID of at most 0x{top:X} for message "
            f"{msg_name!r} (0x{msg.frame_id:X}) with node {motor.node_id}, "
            f"got 0x{frame_id:X}"
        )
    return SignalRef(msg, sig, frame_id, *ranges[sig.name])


def bind_motor(
    motor: MotorConfig, opts: DbcOptions, cache: DatabaseCache, where: str
) -> MotorBinding:
    """Look up every configured name of ``motor`` in its DBC file.

    :param motor: the motor block (node ID, wheel name).
    :param opts: its validated protocol keys.
    :param cache: where loaded databases are kept.
    :param where: file and key path of the block for messages.
    :raises ConfigError: for a missing or invalid file, an unknown message or signal (the
        message lists the known names), a frame ID out of range, a position signal that
        cannot wrap as configured, a multiplexed signal, a value that does not fit its signal
        or is between two of its steps, enable and disable values that go out alike, a signal
        of a bound message with a scale of zero or too large for a float (whose physical
        values are not all finite), a velocity command too narrow for ``max_rpm``
        (:func:`check_command`), or (a steering actuator) position signals too small for its
        travel (:func:`check_travel`).
    """
    path = resolve_path(opts)
    db = cache.load(path, where)

    def ref(msg: str, sig: str, keys: tuple[str, str]) -> SignalRef:
        return _signal(db, msg, sig, keys, path, where, motor, opts)

    command = (
        ref(opts.command_message, opts.command_signal, ("command_message", "command_signal"))
        if opts.command_message
        else None
    )
    target = (
        ref(
            opts.position_command_message,
            opts.position_command_signal,
            ("position_command_message", "position_command_signal"),
        )
        if opts.position_command_message
        else None
    )
    keys = ("position_mode_message", "position_mode_values")
    mode = tuple(
        (ref(opts.position_mode_message, name, keys), value)
        for name, value in opts.position_mode_values
    )
    velocity = ref(
        opts.feedback_message, opts.velocity_signal, ("feedback_message", "velocity_signal")
    )
    position = ref(
        opts.position_message, opts.position_signal, ("position_message", "position_signal")
    )
    bits = opts.position_wrap_bits
    if bits and (position.is_float or bits > position.signal.length):
        raise ConfigError(
            f"{where}.position_wrap_bits: expected 0 or 1..{position.signal.length} for "
            f"{'float ' if position.is_float else ''}signal {position.name!r}, got {bits}"
        )
    fault = (
        ref(opts.fault_message, opts.fault_signal, ("fault_message", "fault_signal"))
        if opts.fault_signal
        else None
    )
    enable = (
        ref(opts.enable_message, opts.enable_signal, ("enable_message", "enable_signal"))
        if opts.enable_message
        else None
    )
    if enable is not None:  # in range, on a step, and not the same on the wire
        values = (opts.enable_value, opts.disable_value)
        check_enable_values(enable.signal, enable.message_name, values, path, where)
    for sig, value in mode:
        key = f"position_mode_values.{sig.name}"
        check_value(sig.signal, sig.message_name, key, value, path, where)
    if command is not None:
        check_command(motor, opts, command, path, where)
    if target is not None:
        check_travel(motor, opts, target, position, path, where)
    return MotorBinding(
        node_id=motor.node_id,
        label=motor.wheel,
        command=command,
        velocity=velocity,
        position=position,
        fault=fault,
        enable=enable,
        enable_value=opts.enable_value,
        disable_value=opts.disable_value,
        target=target,
        mode=mode,
        where=where,
        path=path,
    )


def check_command(
    motor: MotorConfig, opts: DbcOptions, command: SignalRef, path: str, where: str
) -> None:
    """Check that a drive motor's velocity command signal carries every speed up to ``max_rpm``.

    The driver takes wheel speeds up to :func:`gateway.drive.setpoints.bounds` (``max_rpm``
    through the gear ratio, with a rounding slack) and sends each as
    :meth:`UnitConversion.wheel_to_command`, which the codec takes within :func:`command_range`;
    the conversion is monotonic, so both ends of the speeds decide for all of them.

    :raises ConfigError: naming the key, the signal, its message and the DBC file, what the
        signal carries and what ``max_rpm`` needs.
    """
    units = UnitConversion.build(motor, opts)
    (top,) = bounds((motor,))
    low, high = command_range(command)
    if all(low <= units.wheel_to_command(w) <= high for w in (-top, top)):
        return
    edge = motor.max_wheel_rad_s  # shown without the slack
    need = sorted(units.wheel_to_command(w) for w in (-edge, edge))
    unit = f" {command.signal.unit}" if command.signal.unit else ""
    raise ConfigError(
        f"{where}.command_signal: signal {command.name!r} of message {command.message_name!r} "
        f"in {path} carries {command.minimum:g} to {command.maximum:g}{unit}, but max_rpm "
        f"{motor.max_rpm:g} needs {_shown(need[0], command.minimum)} to "
        f"{_shown(need[1], command.maximum)}{unit} (command_unit {opts.command_unit}); use a "
        "wider signal or DBC range, or a lower max_rpm"
    )


def _shown(value: float, edge: float) -> str:
    """``value`` for a message, with the digits that tell it from ``edge``."""
    text = f"{value:g}"
    return f"{value:.12g}" if text == f"{edge:g}" and value != edge else text


def check_travel(
    motor: MotorConfig,
    opts: DbcOptions,
    target: SignalRef,
    position: SignalRef,
    path: str,
    where: str,
) -> None:
    """Check that a steering actuator's position signals can carry its whole travel.

    The travel is every steering angle the actuator's wheels allow (``steer_range_rad``, from
    their ``steer_min`` and ``steer_max``), i.e. the motor positions from
    ``steer_to_motor_rad(steer_min)`` to ``steer_to_motor_rad(steer_max)``.  The position
    command must carry every one of them.  The position feedback is absolute: a signal that
    wraps must not wrap within the travel (else the angle at start-up is ambiguous), and one
    that does not wrap must carry every position too.

    :raises ConfigError: naming the key, the signal, its message and the DBC file, what the
        travel needs and what the signal carries.
    """
    units = UnitConversion.build(motor, opts)
    low, high = motor.steer_range_rad
    ends = (motor.steer_to_motor_rad(low), motor.steer_to_motor_rad(high))
    span = (
        f"steering angles from {low:g} to {high:g} rad (motor positions {min(ends):g} to "
        f"{max(ends):g} rad)"
    )
    hint = "; use a wider signal, or narrow the wheel's steering limits"

    def carries(key: str, signal: SignalRef, need: list[float]) -> None:
        if need[0] < signal.minimum or need[1] > signal.maximum:
            raise ConfigError(
                f"{where}.{key}: signal {signal.name!r} of message {signal.message_name!r} in "
                f"{path} carries {signal.minimum:g} to {signal.maximum:g}, but {span} need "
                f"{need[0]:g} to {need[1]:g}{hint}"
            )

    carries("position_command_signal", target, sorted(units.motor_to_target(x) for x in ends))
    bits = opts.position_wrap_bits
    if position.is_float:
        return
    if bits:
        wrap = abs((1 << bits) * position.scale)
        width = abs(units.motor_to_position(ends[1]) - units.motor_to_position(ends[0]))
        if wrap <= width:
            raise ConfigError(
                f"{where}.position_wrap_bits: signal {position.name!r} of message "
                f"{position.message_name!r} in {path} wraps every {wrap:g} (2**{bits} steps), "
                f"but the absolute position of {span} spans {width:g}{hint}"
            )
        return
    carries("position_signal", position, sorted(units.motor_to_position(x) for x in ends))
