"""Gamepad teleoperation (``wheelgate jog --joystick``), pure part: the Linux joystick events
and the motion a held pad asks for.

The device is the kernel's joydev interface (``/dev/input/jsN``; Linux,
``Documentation/input/joydev/joystick-api.rst``): every event is 8 bytes, ``struct js_event
{__u32 time; __s16 value; __u8 type; __u8 number;}`` in the machine's byte order, ``type`` a
button (0x01) or an axis (0x02), or'ed with 0x80 (``JS_EVENT_INIT``) for the events the driver
sends at open to give the state of every button and axis.  An axis runs from -32767 to 32767;
a button is 1 while pressed.  On the usual pads (Xbox on ``xpad``, PlayStation on
``hid-playstation``) axes 0 and 1 are the left stick's x and y, axis 3 the right stick's x,
pushing up or left reads negative, and button 4 is the left shoulder button (LB, L1).

The map is ROS ``teleop_twist_joy``'s (ros2/teleop_twist_joy: ``require_enable_button``,
``enable_button``, ``axis_linear.x``/``.y``, ``axis_angular.yaw``) with the signs ROS
``joy_linux`` gives the axes (up and left positive, REP-103's forward, left and
counter-clockwise): by default the left stick drives (up forward, left sideways on a holonomic
drive), the right stick turns, and LB must be held.  A full stick is the session's linear or
angular speed (``--speed``, ``--turn`` and the speed keys); inside :attr:`PadMap.deadzone` of
the centre an axis reads zero, beyond it the rest of the travel is scaled to the full range.

Safety: the pad drives only while the enable button is held *and* was pressed since the
device was opened: a button already down at open (the INIT events), or when an unplugged pad
comes back, does not drive until it is released and pressed again.  Releasing it, or a pad
that stops being readable, stops the robot at once (:meth:`gateway.apps.jog.keys.JogState.on_pad`).
"""

from __future__ import annotations

import dataclasses
import struct
from dataclasses import dataclass

#: ``struct js_event`` in the machine's byte order.
EVENT = struct.Struct("=IhBB")
BUTTON = 0x01
AXIS = 0x02
INIT = 0x80
#: The types an event of a joydev device can have.
TYPES = frozenset({BUTTON, AXIS, BUTTON | INIT, AXIS | INIT})
#: An axis at full travel.
FULL = 32767

#: ``teleop_twist_joy``-style defaults: LB (L1) to enable, the left stick's y and x for vx and
#: vy, the right stick's x for wz.
DEFAULT_ENABLE = 4
DEFAULT_AXES = (1, 0, 3)
DEFAULT_DEADZONE = 0.05


class PadError(ValueError):
    """Bytes from a device that does not speak joydev (an ``/dev/input/event*`` node, a file)."""


@dataclass(frozen=True, slots=True)
class PadEvent:
    """One ``js_event``: ``kind`` is :data:`BUTTON` or :data:`AXIS`; ``init``: the state at
    open, not a change."""

    kind: int
    number: int
    value: int
    init: bool


def parse_events(data: bytes) -> tuple[list[PadEvent], bytes]:
    """The whole events in ``data``, and the bytes of an event not yet complete.

    :raises PadError: for an event of a type joydev never sends.
    """
    whole = len(data) - len(data) % EVENT.size
    events = []
    for _time, value, kind, number in EVENT.iter_unpack(data[:whole]):
        if kind not in TYPES:
            raise PadError(f"expected joystick events (type 0x01, 0x02, 0x81 or 0x82), got "
                           f"type {kind:#04x}: not a joydev device (/dev/input/jsN)")
        events.append(PadEvent(kind & ~INIT, number, value, bool(kind & INIT)))
    return events, data[whole:]


@dataclass(frozen=True, slots=True)
class PadMap:
    """Which button enables and which axes drive (joydev numbers, from 0).

    :param enable: the button to hold.
    :param vx: the axis for ``vx`` (forward when pushed up).
    :param vy: the axis for ``vy`` (left when pushed left; holonomic drives only).
    :param wz: the axis for ``wz`` (counter-clockwise when pushed left).
    :param deadzone: the part of each axis's travel around the centre that reads zero.
    """

    enable: int = DEFAULT_ENABLE
    vx: int = DEFAULT_AXES[0]
    vy: int = DEFAULT_AXES[1]
    wz: int = DEFAULT_AXES[2]
    deadzone: float = DEFAULT_DEADZONE

    def describe(self) -> str:
        """The map in words, for the screen."""
        return (f"hold button {self.enable}; axis {self.vx} vx, axis {self.vy} vy, "
                f"axis {self.wz} wz")


@dataclass(frozen=True, slots=True)
class Pad:
    """The state of a pad as far as the map reads it.

    :param map: the map.
    :param axes: the raw value of the mapped axes, ``(vx, vy, wz)``.
    :param held: whether the enable button is down.
    :param armed: whether it went down since the device was opened (and is still down).
    :param seen: the highest button and axis numbers the device reported at open, ``(-1,
        -1)`` before its INIT events.
    """

    map: PadMap = PadMap()
    axes: tuple[int, int, int] = (0, 0, 0)
    held: bool = False
    armed: bool = False
    seen: tuple[int, int] = (-1, -1)

    def apply(self, events: list[PadEvent]) -> Pad:
        """The pad after ``events``."""
        pad = self
        m = pad.map
        for e in events:
            if e.kind == BUTTON:
                if e.init:
                    pad = dataclasses.replace(pad, seen=(max(pad.seen[0], e.number), pad.seen[1]))
                if e.number == m.enable:
                    down = e.value != 0
                    pad = dataclasses.replace(pad, held=down,
                                              armed=down and (pad.armed or not e.init))
            else:
                if e.init:
                    pad = dataclasses.replace(pad, seen=(pad.seen[0], max(pad.seen[1], e.number)))
                axes = tuple(e.value if e.number == n else v
                             for n, v in zip((m.vx, m.vy, m.wz), pad.axes, strict=True))
                pad = dataclasses.replace(pad, axes=(axes[0], axes[1], axes[2]))
        return pad

    def direction(self, holonomic: bool) -> tuple[float, float, float] | None:
        """``(x, y, yaw)`` of full-speed fractions the pad asks for, ``None`` while it does not
        enable motion; ``y`` is 0 on a drive that cannot move sideways."""
        if not self.armed:
            return None
        dz = self.map.deadzone
        x, y, yaw = (_fraction(-v, dz) for v in self.axes)
        return x, (y if holonomic else 0.0), yaw

    def missing(self) -> str:
        """The mapped button or axes the device did not report at open, in words (``""``:
        none, or no INIT events yet)."""
        buttons, axes = self.seen
        if buttons < 0 and axes < 0:
            return ""
        m = self.map
        gone = ([f"button {m.enable}"] if m.enable > buttons else []) + [
            f"axis {n}" for n in (m.vx, m.vy, m.wz) if n > axes]
        return ", ".join(gone)


def _fraction(value: int, deadzone: float) -> float:
    """An axis's value as a fraction of full travel, zero inside the dead zone, the rest of the
    travel scaled to 0..1."""
    f = max(-1.0, min(1.0, value / FULL))
    size = abs(f)
    if size <= deadzone:
        return 0.0
    scaled = (size - deadzone) / (1.0 - deadzone)
    return scaled if f > 0 else -scaled
