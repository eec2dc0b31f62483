"""Keyboard teleoperation (``wheelgate jog``), pure part: key map, speeds and deadman.

The keys are those of ROS ``teleop_twist_keyboard``::

    Moving around:        Holonomic (shift):
       u    i    o           U    I    O
       j    k    l           J    K    L
       m    ,    .           M    <    >

``k``, space and any other key stop; ``q``/``z`` scale both speeds by 1.1 / 0.9, ``w``/``x``
the linear speed only, ``e``/``c`` the angular speed only; ``t``/``b`` (z up and down) do not
apply to a ground robot and stop.  Because ``q`` speeds up, as in teleop_twist_keyboard, the
session ends with Ctrl-C, Ctrl-D or Esc, and always with a stop.  The first speeds are
teleop_twist_keyboard's ``speed`` and ``turn`` parameters, 0.5 m/s and 1.0 rad/s
(``jog --speed`` and ``--turn``; ros-teleop/teleop_twist_keyboard, ``teleop_twist_keyboard.py``:
``speed = rospy.get_param("~speed", 0.5)``, ``turn = rospy.get_param("~turn", 1.0)``), within
the robot's limits (:func:`step_error`).

Deadman: a motion key drives for as long as it keeps arriving (terminal auto-repeat); the
current twist is re-sent every :data:`SEND_PERIOD_S`; when no motion key has come for the
deadman time, stop is sent once.  Speed keys change the speed of the current motion but do not
keep it alive, so holding ``q`` cannot drive the robot.  The daemon's ``cmd_timeout_s`` is the
second safety net, should this program stop sending altogether.

Nothing here does I/O or reads the clock: :class:`JogState` takes keys with their times and
returns the requests to send.  The screen is drawn by :mod:`gateway.apps.jog.screen`, the terminal
handled by :mod:`gateway.cli.commands.jog`.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from gateway.core.cadence import next_due
from gateway.core.kinematics.limits import Limits, speed_scale
from gateway.core.types import Twist
from gateway.wire.socket import MAX_TWIST_COMPONENT

if TYPE_CHECKING:
    from collections.abc import Mapping

    from gateway.core.kinematics.model import RobotModel
    from gateway.core.settings import GatewayConfig

#: Non-holonomic moves, key -> (x, yaw) direction (teleop_twist_keyboard's moveBindings).
MOVE_BINDINGS: Mapping[str, tuple[int, int]] = {
    "i": (1, 0), "o": (1, -1), "j": (0, 1), "l": (0, -1),
    "u": (1, 1), ",": (-1, 0), ".": (-1, 1), "m": (-1, -1),
}
#: Holonomic moves (shift), key -> (x, y) direction.
HOLONOMIC_BINDINGS: Mapping[str, tuple[int, int]] = {
    "O": (1, -1), "I": (1, 0), "J": (0, 1), "L": (0, -1),
    "U": (1, 1), "<": (-1, 0), ">": (-1, -1), "M": (-1, 1),
}
#: Speed keys, key -> (factor on the linear speed, factor on the angular speed).
SPEED_BINDINGS: Mapping[str, tuple[float, float]] = {
    "q": (1.1, 1.1), "z": (0.9, 0.9), "w": (1.1, 1.0), "x": (0.9, 1.0),
    "e": (1.0, 1.1), "c": (1.0, 0.9),
}
#: The "key" of a motion the gamepad holds (``jog --joystick``, :mod:`gateway.apps.jog.pad`).
PAD_KEY = "joystick"
#: Keys that end the session (each sends stop first), key -> its name.
QUIT_KEYS: Mapping[str, str] = {"\x03": "Ctrl-C", "\x04": "Ctrl-D", "\x1b": "Esc"}
#: teleop_twist_keyboard's z keys; a ground robot has no z.
Z_KEYS = frozenset("tb")

DEFAULT_LINEAR_M_S = 0.5
DEFAULT_ANGULAR_RAD_S = 1.0
DEFAULT_DEADMAN_S = 0.6
#: Label of a speed that no configured limit caps (the socket's own maximum applies).
NO_LIMIT = "no limit set"
#: How often a held motion key re-sends its twist (10 Hz).
SEND_PERIOD_S = 0.1


@dataclass(frozen=True, slots=True)
class JogLimits:
    """What the robot allows the jog speeds to be.

    :param max_linear_m_s: largest straight-ahead speed, m/s.
    :param max_angular_rad_s: largest turn-in-place rate, rad/s.
    :param linear_by: which limit sets ``max_linear_m_s`` (for the screen).
    :param angular_by: which limit sets ``max_angular_rad_s``.
    :param holonomic: whether the drive follows a sideways twist (shift keys allowed).
    :param drive: the drive's name, for messages.
    :param model: the robot, to tell how much the limits scale a combined move.
    :param limits: its limits.
    """

    max_linear_m_s: float = MAX_TWIST_COMPONENT
    max_angular_rad_s: float = MAX_TWIST_COMPONENT
    linear_by: str = NO_LIMIT
    angular_by: str = NO_LIMIT
    holonomic: bool = True
    drive: str = "generic"
    model: RobotModel | None = field(default=None, compare=False)
    limits: Limits | None = field(default=None, compare=False)

    def command_scale(self, twist: Twist) -> float | None:
        """The factor the daemon's speed limits will put on ``twist`` (``None``: unknown or
        infeasible)."""
        if self.model is None or self.limits is None:
            return None
        result = self.model.try_ik(twist)
        return None if result is None else speed_scale(self.model, result, self.limits)


def _cap(model: RobotModel, limits: Limits, unit: Twist, config_cap: float, key: str
         ) -> tuple[float, str]:
    """The largest multiple of ``unit`` within every speed limit, and which limit sets it."""
    probe = unit.scaled(MAX_TWIST_COMPONENT)  # the largest component the socket accepts
    result = model.try_ik(probe)
    if result is None:  # the drive cannot do this move alone; only the config caps it
        if config_cap < MAX_TWIST_COMPONENT:
            return config_cap, f"{key}; infeasible alone"
        return MAX_TWIST_COMPONENT, "infeasible alone"
    cap = MAX_TWIST_COMPONENT * speed_scale(model, result, limits)
    if config_cap <= cap * (1.0 + 1e-9):
        return cap, key
    return cap, "motor max_rpm" if cap < MAX_TWIST_COMPONENT else NO_LIMIT


def jog_limits(config: GatewayConfig) -> JogLimits:
    """The jog limits of a configured robot: ``limits.max_linear_m_s`` and
    ``max_angular_rad_s`` and every motor's ``max_rpm``, through
    :func:`~gateway.core.kinematics.limits.speed_scale`."""
    model, limits = config.model, config.limits
    lin, lin_by = _cap(model, limits, Twist(1.0, 0.0, 0.0), limits.max_linear_m_s,
                       "limits.max_linear_m_s")
    ang, ang_by = _cap(model, limits, Twist(0.0, 0.0, 1.0), limits.max_angular_rad_s,
                       "limits.max_angular_rad_s")
    return JogLimits(lin, ang, lin_by, ang_by, model.feasible(Twist(0.0, 0.1, 0.0)),
                     config.drive, model, limits)


def step_error(value: float, cap: float, by: str, what: str, unit: str) -> str:
    """Why ``value`` cannot be the first speed of a key (``jog --speed`` or ``--turn``); ``""``
    when it can: above 0, finite and within the robot's limit.

    :param cap: the limit (m/s or rad/s); the message shows it rounded down to 0.001.
    :param by: what sets the limit (:attr:`JogLimits.linear_by`).
    :param what: the speed with its article, ``"a linear"`` or ``"an angular"``.
    :param unit: ``"m/s"`` or ``"rad/s"``.

    >>> step_error(0.5, 4.654211, "motor max_rpm", "a linear", "m/s")
    ''
    >>> step_error(5.0, 4.654211, "motor max_rpm", "a linear", "m/s")
    'expected a linear speed above 0 and at most 4.654 m/s (motor max_rpm), got 5.0'
    """
    if math.isfinite(value) and 0.0 < value <= cap:
        return ""
    shown = math.floor(cap * 1000.0) / 1000.0  # a limit that, typed back, is accepted
    why = "the control socket's largest twist" if by == NO_LIMIT else by
    return (f"expected {what} speed above 0 and at most {shown:g} {unit} ({why}), "
            f"got {value!r}")


def steps_errors(limits: JogLimits, linear_m_s: float | None, angular_rad_s: float | None
                 ) -> list[tuple[str, str]]:
    """(option, why) for ``jog --speed`` (``linear_m_s``) and ``--turn`` when given and not
    a first speed :func:`step_error` accepts."""
    out = []
    for option, value, cap, by, what, unit in (
            ("--speed", linear_m_s, limits.max_linear_m_s, limits.linear_by, "a linear", "m/s"),
            ("--turn", angular_rad_s, limits.max_angular_rad_s, limits.angular_by, "an angular",
             "rad/s")):
        why = "" if value is None else step_error(value, cap, by, what, unit)
        if why:
            out.append((option, why))
    return out


@dataclass(frozen=True, slots=True)
class Request:
    """One request for the daemon: ``op`` is ``"twist"`` or ``"stop"``."""

    op: str
    twist: Twist = field(default_factory=Twist)

    def payload(self) -> dict[str, object]:
        """The control-socket message."""
        if self.op == "twist":
            t = self.twist
            return {"op": "twist", "vx": t.vx_m_s, "vy": t.vy_m_s, "wz": t.wz_rad_s}
        return {"op": self.op}


STOP = Request("stop")


def key_name(key: str) -> str:
    """A key as the screen shows it."""
    if key == " ":
        return "space"
    if key == PAD_KEY:
        return key
    if key in QUIT_KEYS:
        return QUIT_KEYS[key]
    if len(key) > 1:
        return "escape sequence"
    if ord(key) < 0x20:
        return f"Ctrl-{chr(ord(key) + 0x40)}"
    return repr(key)


def split_keys(data: bytes) -> list[str]:
    """Cut what the terminal sent into keys.  An escape sequence (arrows, function keys,
    Alt+key) is one key, so it stops rather than quits; a lone Esc at the end is Esc."""
    text = data.decode("latin-1")
    keys: list[str] = []
    i = 0
    while i < len(text):
        if text[i] != "\x1b" or i + 1 == len(text):
            keys.append(text[i])
            i += 1
            continue
        j = i + 1
        if text[j] == "[":  # CSI: parameter and intermediate bytes, then a final byte
            j += 1
            while j < len(text) and "\x20" <= text[j] <= "\x3f":
                j += 1
        elif text[j] == "O":  # SS3: one final byte
            j += 1
        keys.append(text[i : j + 1])
        i = j + 1
    return keys


@dataclass(frozen=True, slots=True)
class Step:
    """The outcome of one event: the new state and what to send, in order."""

    state: JogState
    requests: tuple[Request, ...] = ()


@dataclass(frozen=True, slots=True)
class JogState:
    """The jog session: speeds, current motion and the deadman, on times given by the caller.

    :param limits: the robot's jog limits.
    :param linear_m_s: linear speed for a full key (m/s), within ``limits``.
    :param angular_rad_s: angular speed for a full key (rad/s), within ``limits``.
    :param deadman_s: a motion stops when no motion key came for this long.
    :param period_s: how often a held motion is re-sent.
    :param key: the motion key being held, ``""`` when stopped.
    :param direction: (x, y, yaw) of that key, each -1, 0 or 1 (of the pad: fractions of
        full travel, -1 to 1).
    :param last_key_s: when that key last arrived.
    :param next_send_s: when the motion is re-sent next.
    :param message: what the last event did, for the screen.
    :param ended: why the session ended, ``""`` while it runs.
    """

    limits: JogLimits
    linear_m_s: float = DEFAULT_LINEAR_M_S
    angular_rad_s: float = DEFAULT_ANGULAR_RAD_S
    deadman_s: float = DEFAULT_DEADMAN_S
    period_s: float = SEND_PERIOD_S
    key: str = ""
    direction: tuple[float, float, float] = (0, 0, 0)
    last_key_s: float = -math.inf
    next_send_s: float = math.inf
    message: str = ""
    ended: str = ""

    @classmethod
    def start(cls, limits: JogLimits, linear_m_s: float | None = None,
              angular_rad_s: float | None = None,
              deadman_s: float = DEFAULT_DEADMAN_S) -> JogState:
        """A stopped session whose speeds (``None``: teleop_twist_keyboard's) are clamped to
        ``limits`` (the message says so)."""
        linear_m_s = DEFAULT_LINEAR_M_S if linear_m_s is None else linear_m_s
        angular_rad_s = DEFAULT_ANGULAR_RAD_S if angular_rad_s is None else angular_rad_s
        lin = min(linear_m_s, limits.max_linear_m_s)
        ang = min(angular_rad_s, limits.max_angular_rad_s)
        notes = [f"{what} speed {want:g} {unit} clamped to {got:.3g} {unit} by {by}"
                 for what, want, got, unit, by in (
                     ("linear", linear_m_s, lin, "m/s", limits.linear_by),
                     ("angular", angular_rad_s, ang, "rad/s", limits.angular_by)) if got < want]
        return cls(limits, lin, ang, deadman_s, message="; ".join(notes) or "ready")

    @property
    def moving(self) -> bool:
        """Whether a motion is being held."""
        return bool(self.key)

    @property
    def twist(self) -> Twist:
        """The twist being held (zero when stopped)."""
        x, y, yaw = self.direction
        return Twist(x * self.linear_m_s, y * self.linear_m_s, yaw * self.angular_rad_s)

    def next_deadline_s(self) -> float:
        """When :meth:`on_tick` has something to do next (``inf``: only on a key)."""
        if not self.moving:
            return math.inf
        return min(self.next_send_s, self.last_key_s + self.deadman_s)

    def _stopped(self, message: str, ended: str = "") -> Step:
        state = dataclasses.replace(self, key="", direction=(0, 0, 0), next_send_s=math.inf,
                                    message=message, ended=ended or self.ended)
        return Step(state, (STOP,))

    def on_key(self, key: str, now_s: float) -> Step:
        """One key from the terminal at ``now_s``."""
        if key in QUIT_KEYS:
            return self.on_quit(QUIT_KEYS[key])
        if key in MOVE_BINDINGS:
            x, yaw = MOVE_BINDINGS[key]
            return self._move(key, (x, 0, yaw), now_s)
        if key in HOLONOMIC_BINDINGS:
            if not self.limits.holonomic:
                return self._stopped(f"{key!r} is a holonomic (sideways) key: this "
                                     f"{self.limits.drive} drive cannot follow vy; sent stop")
            x, y = HOLONOMIC_BINDINGS[key]
            return self._move(key, (x, y, 0), now_s)
        if key in SPEED_BINDINGS:
            return self._speed(*SPEED_BINDINGS[key])
        if key in Z_KEYS:
            return self._stopped(f"{key!r} moves along z in teleop_twist_keyboard; "
                                 "a ground robot has none: sent stop")
        if key in ("k", " "):
            return self._stopped(f"{key_name(key)}: stop")
        return self._stopped(f"{key_name(key)} is not a jog key: sent stop")

    def _move(self, key: str, direction: tuple[float, float, float], now_s: float) -> Step:
        held = (self.moving and direction == self.direction
                and now_s - self.last_key_s < self.deadman_s)
        state = dataclasses.replace(self, key=key, direction=direction, last_key_s=now_s)
        if held:  # auto-repeat of the held key: keeps it alive; on_tick re-sends it
            return Step(state)
        state = dataclasses.replace(state, next_send_s=now_s + self.period_s,
                                    message=f"{key_name(key)}: move")
        return Step(state, (Request("twist", state.twist),))

    def _speed(self, lin_factor: float, ang_factor: float) -> Step:
        lim = self.limits
        lin = min(self.linear_m_s * lin_factor, lim.max_linear_m_s)
        ang = min(self.angular_rad_s * ang_factor, lim.max_angular_rad_s)
        notes = [f"linear {lin:.3g} m/s, angular {ang:.3g} rad/s"]
        if lin_factor > 1.0 and lin >= lim.max_linear_m_s:
            notes.append(f"linear speed limit reached ({lim.linear_by})")
        if ang_factor > 1.0 and ang >= lim.max_angular_rad_s:
            notes.append(f"angular speed limit reached ({lim.angular_by})")
        state = dataclasses.replace(self, linear_m_s=lin, angular_rad_s=ang,
                                    message="; ".join(notes))
        if not self.moving or state.twist == self.twist:
            return Step(state)
        return Step(state, (Request("twist", state.twist),))

    def on_tick(self, now_s: float) -> Step:
        """Time passes: re-send a held motion, or stop it when its key stopped coming."""
        if not self.moving:
            return Step(self)
        if now_s - self.last_key_s >= self.deadman_s:
            return self._stopped(f"deadman: no key for {self.deadman_s:g} s: sent stop")
        if now_s < self.next_send_s:
            return Step(self)
        state = dataclasses.replace(self, next_send_s=next_due(self.next_send_s, now_s,
                                                                self.period_s))
        return Step(state, (Request("twist", self.twist),))

    def on_pad(self, direction: tuple[float, float, float] | None, now_s: float,
               lost: str = "") -> Step:
        """The pad's motion at ``now_s`` (:meth:`gateway.apps.jog.pad.Pad.direction`; ``None``:
        not enabled), given on every pass of the loop: while it is held its motion stays alive
        as a repeating key's does, and goes out at the send period; let go, centred or
        ``lost`` (why the pad cannot be read), it stops the motion it started (not a key's)."""
        ours = self.moving and self.key == PAD_KEY
        if direction is None or not any(direction):
            if not ours:
                return Step(self)
            why = ("sticks centred" if direction is not None else
                   lost or "enable button released")
            return self._stopped(f"joystick: {why}: sent stop")
        if ours:  # (a new direction goes out at the next send, within the period)
            return Step(dataclasses.replace(self, direction=direction, last_key_s=now_s))
        return self._move(PAD_KEY, direction, now_s)

    def on_quit(self, reason: str) -> Step:
        """End the session (a quit key, end of input, a hang-up or a signal): stop."""
        return self._stopped(f"{reason}: quit, sent stop", ended=reason)

