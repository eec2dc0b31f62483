"""Reading the gateway's status from JSON: :func:`status_from_json` turns a ``status`` reply
(or its payload) into :class:`gateway.core.status.GatewayStatus`, and raises
:class:`~gateway.wire.socket.ProtocolError` for a malformed one, naming the key (as a path,
``status.motors[1].node_id``), what was expected and what came.  The format, key by key, and
what an older daemon may leave out, is :mod:`gateway.wire.socket.status`;
:mod:`gateway.wire.socket.status_write` writes it.  Pure: no I/O, no clock.
"""

from __future__ import annotations

import dataclasses
import math
from types import MappingProxyType
from typing import TYPE_CHECKING, Final, NoReturn, TypeVar

from gateway.core.kinematics.odometry import OdometryState, Pose
from gateway.core.protection import Guard, ProtectionState
from gateway.core.settings import TrackingLimits
from gateway.core.status import (
    BusErrorState,
    BusHealth,
    BusReport,
    CommandReport,
    ConfigReport,
    ControllerStop,
    Counters,
    Direction,
    FrameCount,
    GatewayStatus,
    LastError,
    MotorReport,
    ServerCounters,
    SocketReport,
    TimingReport,
    TrackingReport,
    state_name,
)
from gateway.core.types import DriveFault, DriveState, ErrorCode, GatewayState, Twist
from gateway.wire.socket.messages import ProtocolError, quoted, short_json

if TYPE_CHECKING:
    import enum
    from collections.abc import Mapping

__all__ = ["status_from_json"]

_E = TypeVar("_E", bound="enum.Enum")
_MISSING: Final = object()
#: The keys of ``counters`` that are not event counters.
_NESTED_COUNTERS = ("rejected_frames", "commands_not_followed")
#: The keys of ``bus`` that carry :class:`BusHealth`.
_HEALTH_KEYS = ("healthy", "error_state", "error_frames", "last_error_frame")
_SERVER_COUNTERS = tuple(f.name for f in dataclasses.fields(ServerCounters))


def _fail(where: str, expected: str, value: object) -> NoReturn:
    got = "nothing" if value is _MISSING else short_json(value)
    raise ProtocolError(f"{where}: expected {expected}, got {got}")


def _is_number(value: object) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _names(kind: type[_E]) -> dict[str, _E]:
    return {state_name(m): m for m in kind}


_DRIVE_STATES = _names(DriveState)
_GATEWAY_STATES = _names(GatewayState)
_ERROR_CODES = _names(ErrorCode)
_FAULTS = {state_name(f): f for f in DriveFault if f.value and f.value & (f.value - 1) == 0}


class _Obj:
    """A JSON object being read, with its path for messages."""

    __slots__ = ("_items", "where")

    def __init__(self, value: object, where: str) -> None:
        if not isinstance(value, dict):
            _fail(where, "an object", value)
        self._items: dict[str, object] = value
        self.where = where

    def has(self, key: str) -> bool:
        return key in self._items

    def raw(self, key: str) -> object:
        return self._items.get(key, _MISSING)

    def path(self, key: str) -> str:
        return f"{self.where}.{key}"

    def obj(self, key: str) -> _Obj:
        return _Obj(self.raw(key), self.path(key))

    def text(self, key: str) -> str:
        value = self.raw(key)
        if not isinstance(value, str):
            _fail(self.path(key), "a string", value)
        return value

    def integer(self, key: str, default: int | None = None) -> int:
        value = self.raw(key)
        if value is _MISSING and default is not None:
            return default
        if not isinstance(value, int) or isinstance(value, bool):
            _fail(self.path(key), "an integer", value)
        return value

    def flag(self, key: str) -> bool:
        value = self.raw(key)
        if not isinstance(value, bool):
            _fail(self.path(key), "true or false", value)
        return value

    def number(self, key: str, default: float | None = None) -> float:
        """A number; ``null`` (a float that was not finite) is NaN."""
        value = self.raw(key)
        if value is _MISSING and default is not None:
            return default
        if value is None:
            return math.nan
        if not _is_number(value):
            _fail(self.path(key), "a number", value)
        return value  # type: ignore[return-value]

    def maybe_number(self, key: str) -> float | None:
        """A number, or ``None`` for ``null``."""
        value = self.raw(key)
        if value is None:
            return None
        if not _is_number(value):
            _fail(self.path(key), "a number or null", value)
        return value  # type: ignore[return-value]

    def choice(self, key: str, choices: Mapping[str, _E]) -> _E:
        value = self.raw(key)
        if not isinstance(value, str) or value not in choices:
            _fail(self.path(key), f"one of {quoted(choices)}", value)
        return choices[value]

    def array(self, key: str) -> list[object]:
        value = self.raw(key)
        if not isinstance(value, list):
            _fail(self.path(key), "an array", value)
        return value

    def as_counts(self, skip: tuple[str, ...] = ()) -> Mapping[str, int]:
        """This object as counts by name, in its order (``skip``: keys that are not counts)."""
        out: dict[str, int] = {}
        for name, value in self._items.items():
            if name in skip:
                continue
            if not isinstance(value, int) or isinstance(value, bool):
                _fail(self.path(name), "an integer count", value)
            out[name] = value
        return MappingProxyType(out)

    def nested_counts(self, key: str) -> Mapping[str, Mapping[str, int]]:
        """An object of objects of counts (absent: empty)."""
        if not self.has(key):
            return MappingProxyType({})
        outer = self.obj(key)
        return MappingProxyType({name: outer.obj(name).as_counts() for name in outer._items})


def _read_twist(obj: _Obj) -> Twist:
    return Twist(obj.number("vx_m_s"), obj.number("vy_m_s"), obj.number("wz_rad_s"))


_GUARDS = {g.value: g for g in Guard}
_PROTECTION_STATES = {p.value: p for p in ProtectionState}


def _read_motor(obj: _Obj) -> MotorReport:
    name, node_id = obj.text("name"), obj.integer("node_id")
    state = obj.choice("state", _DRIVE_STATES)
    faults = DriveFault.NONE
    for k, item in enumerate(obj.array("faults")):
        if not isinstance(item, str) or item not in _FAULTS:
            _fail(f"{obj.path('faults')}[{k}]", f"one of {quoted(_FAULTS)}", item)
        faults |= _FAULTS[item]
    detail, age = obj.text("detail"), obj.maybe_number("feedback_age_s")
    position, velocity = obj.maybe_number("position_rad"), obj.maybe_number("velocity_rad_s")
    stop = None
    if obj.raw("controller_stop") not in (None, _MISSING):
        s = obj.obj("controller_stop")
        stop = ControllerStop(s.choice("guard", _GUARDS), s.maybe_number("timeout_s"),
                              s.choice("state", _PROTECTION_STATES))
    return MotorReport(name, node_id, state, faults, detail, age, position, velocity, stop)


def _read_tracking(obj: _Obj) -> TrackingReport:
    limits = TrackingLimits(obj.number("tolerance_rad_s"), obj.number("tolerance_ratio"),
                            obj.number("time_s"), obj.number("steer_tolerance_rad"))
    return TrackingReport(limits, obj.number("worst_ratio"),
                          obj.number("steer_worst_ratio", default=0.0))


def _read_odometry(obj: _Obj) -> OdometryState:
    return OdometryState(
        Pose(obj.number("x"), obj.number("y"), obj.number("theta")),
        Twist(obj.number("vx"), obj.number("vy"), obj.number("wz")),
        obj.number("slip"), obj.number("distance"), obj.number("t"))


def _read_timing(obj: _Obj) -> TimingReport:
    n, i = obj.number, obj.integer
    return TimingReport(
        i("cycles"), i("missed"), n("rate_hz"), n("achieved_hz"), n("lateness_p50_us"),
        n("lateness_p99_us"), n("lateness_max_us"), n("cost_p50_us"), n("cost_p99_us"),
        n("cost_max_us"), i("latency_samples"), n("latency_p50_us"), n("latency_p99_us"),
        n("latency_max_us"), i("late_on_cpu", 0), i("late_runnable", 0), i("late_asleep", 0),
        n("burst_gap_max_ms") if obj.has("burst_gap_max_ms") else None)


def _read_socket(obj: _Obj) -> SocketReport:
    counters = ServerCounters(**{name: obj.integer(name, 0) for name in _SERVER_COUNTERS})
    return SocketReport(obj.text("path"), counters)


_DIRECTIONS = {d.value: d for d in Direction}
_ERROR_STATES = {e.value: e for e in BusErrorState}


def _read_bus(obj: _Obj) -> BusReport:
    interface, channel, bitrate = obj.text("interface"), obj.text("channel"), obj.integer("bitrate")
    health = None
    if any(obj.has(key) for key in _HEALTH_KEYS):
        health = BusHealth(obj.flag("healthy"), obj.choice("error_state", _ERROR_STATES),
                           obj.obj("error_frames").as_counts(), obj.text("last_error_frame"))
    bits, time_s = obj.integer("bits"), obj.number("time_s")
    frames = []
    for k, item in enumerate(obj.array("frames")):
        f = _Obj(item, f"{obj.path('frames')}[{k}]")
        frames.append(FrameCount(f.integer("id"), f.flag("extended"),
                                 f.choice("direction", _DIRECTIONS), f.integer("count")))
    return BusReport(interface, channel, bitrate, health, bits, time_s, tuple(frames))


def _read_last_error(obj: _Obj) -> LastError | None:
    if obj.raw("last_error") is None:
        return None
    e = obj.obj("last_error")
    return LastError(e.choice("code", _ERROR_CODES), e.text("message"))


def status_from_json(value: object) -> GatewayStatus:
    """Read a status (a ``status`` reply, or its payload) into the model.

    :raises ProtocolError: naming the first key that is missing or wrong, what was expected
        and what came.
    """
    obj = _Obj(value, "status")
    robot, state = obj.text("robot"), obj.choice("state", _GATEWAY_STATES)
    reason, cmd = obj.text("reason"), obj.obj("command")
    command = CommandReport(_read_twist(cmd.obj("target")), _read_twist(cmd.obj("applied")),
                            cmd.flag("cmd_timeout_active"), cmd.number("speed_scale"),
                            cmd.number("accel_scale"))
    motors = tuple(_read_motor(_Obj(m, f"status.motors[{k}]"))
                   for k, m in enumerate(obj.array("motors")))
    tracking = _read_tracking(obj.obj("tracking")) if obj.has("tracking") else None
    odometry = _read_odometry(obj.obj("odometry"))
    c = obj.obj("counters")
    counters = Counters(c.as_counts(skip=_NESTED_COUNTERS), c.nested_counts("rejected_frames"),
                        c.nested_counts("commands_not_followed"))
    socket, timing = _read_socket(obj.obj("socket")), _read_timing(obj.obj("timing"))
    last_error = _read_last_error(obj)
    realtime: list[str] = []
    for k, line in enumerate(obj.array("realtime")):
        if not isinstance(line, str):
            _fail(f"status.realtime[{k}]", "a string", line)
        realtime.append(line)
    config = None
    if obj.has("config"):  # (optional: a daemon of an earlier release does not say)
        c = obj.obj("config")
        config = ConfigReport(c.text("path"), c.text("fingerprint"))
    return GatewayStatus(robot, state, reason, command, motors, tracking, odometry, counters,
                         socket, timing, last_error, tuple(realtime), _read_bus(obj.obj("bus")),
                         config)
