"""Named drives built on the general wheel model: each preset only places wheels.

Every preset turns natural geometry keys (wheel radius, track, wheelbase, ...) into
:class:`~gateway.core.kinematics.wheels.Wheel` objects; inverse and forward kinematics, feasibility
and odometry then come from :class:`~gateway.core.kinematics.model.RobotModel` alone.  There is no
per-drive code path anywhere else.

What each drive can follow (body twist ``(vx, vy, wz)`` at the reference point):

==============  ================================================  ===============================
preset          reference point                                   twists it follows
==============  ================================================  ===============================
differential    middle of the wheel axle                          ``vy = 0``; any ``vx``, ``wz``
skid_steer      middle of the effective axle                      ``vy = 0`` (turning slips by
                                                                  design: effective track)
synchro         centre of the wheel circle                        ``wz = 0``; any ``vx``, ``vy``
tricycle        middle of the rear axle                           ``vy = 0``; ``|wz| * wheelbase
                                                                  <= |v| tan(max_steer)``
ackermann       middle of the rear axle                           ``vy = 0``; curvature up to
                                                                  the inner wheel's max_steer
omni            centre                                            any twist
mecanum         centre                                            any twist
swerve          centre                                            any twist (steering in limits)
==============  ================================================  ===============================
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

from gateway.core.kinematics.wheels import Wheel, WheelType, forward_beta

if TYPE_CHECKING:
    from collections.abc import Callable, Mapping

#: A preset parameter value: numbers, or a word for choices.
Param = float | int | str


@dataclass(frozen=True, slots=True)
class Preset:
    """A named drive.

    :param name: the ``drive:`` value.
    :param params: geometry keys with their defaults (``None``: required).
    :param choices: keys whose value is a word, with the allowed words.
    :param build: turns validated parameters into wheels.
    :param summary: one line on the twists it can follow.
    """

    name: str
    params: Mapping[str, Param | None]
    choices: Mapping[str, tuple[str, ...]]
    build: Callable[[Mapping[str, Param]], list[Wheel]]
    summary: str

    def wheels(self, **params: Param) -> list[Wheel]:
        """The wheels for ``params`` with defaults filled in (no validation: the config
        loader validates user input).

        :raises KeyError: if a required key is missing.
        """
        values = {k: v for k, v in self.params.items() if v is not None}
        values.update(params)
        missing = sorted(set(self.params) - set(values))
        if missing:
            raise KeyError(f"{self.name} preset needs {', '.join(missing)}")
        return self.build(values)


def _f(p: Mapping[str, Param], key: str) -> float:
    return float(p[key])


def _corner(
    name: str,
    x: float,
    y: float,
    radius: float,
    wheel_type: WheelType,
    **kw: float | bool | str | None,
) -> Wheel:
    """A wheel at body position (x, y) that rolls forward along +x at neutral."""
    alpha = math.atan2(y, x)
    return Wheel(
        name=name,
        type=wheel_type,
        alpha=alpha,
        l=math.hypot(x, y),
        beta=forward_beta(alpha),
        radius=radius,
        **kw,  # type: ignore[arg-type]
    )


def _differential(p: Mapping[str, Param]) -> list[Wheel]:
    r, half = _f(p, "wheel_radius"), _f(p, "track") / 2
    return [
        _corner("left", 0.0, half, r, WheelType.FIXED),
        _corner("right", 0.0, -half, r, WheelType.FIXED),
    ]


def _skid_steer(p: Mapping[str, Param]) -> list[Wheel]:
    # Effective-track model: each side acts like one wheel on the y axis at half the
    # effective track; the real wheels' longitudinal offset shows up as slip, by design.
    r = _f(p, "wheel_radius")
    half = _f(p, "effective_track" if float(p["effective_track"]) > 0 else "track") / 2
    return [
        _corner(n, 0.0, half if "left" in n else -half, r, WheelType.FIXED)
        for n in ("front_left", "front_right", "rear_left", "rear_right")
    ]


def _synchro(p: Mapping[str, Param]) -> list[Wheel]:
    r, dist, count = _f(p, "wheel_radius"), _f(p, "wheel_distance"), int(p["wheel_count"])
    lim = _f(p, "max_steer")
    return [
        _corner(
            f"wheel_{k + 1}",
            dist * math.cos(2 * math.pi * k / count),
            dist * math.sin(2 * math.pi * k / count),
            r,
            WheelType.STEERABLE,
            steer_min=-lim,
            steer_max=lim,
            steer_group="synchro",
        )
        for k in range(count)
    ]


def _tricycle(p: Mapping[str, Param]) -> list[Wheel]:
    r, base, half = _f(p, "wheel_radius"), _f(p, "wheelbase"), _f(p, "track") / 2
    lim, front_driven = _f(p, "max_steer"), p["drive"] == "front"
    return [
        _corner(
            "front", base, 0.0, r, WheelType.STEERABLE,
            steer_min=-lim, steer_max=lim, driven=front_driven,
        ),
        _corner("rear_left", 0.0, half, r, WheelType.FIXED, driven=not front_driven),
        _corner("rear_right", 0.0, -half, r, WheelType.FIXED, driven=not front_driven),
    ]


def _ackermann(p: Mapping[str, Param]) -> list[Wheel]:
    r, base, half = _f(p, "wheel_radius"), _f(p, "wheelbase"), _f(p, "track") / 2
    lim, drive = _f(p, "max_steer"), p["drive"]
    front, rear = drive in ("front", "all"), drive in ("rear", "all")
    return [
        _corner(
            "front_left", base, half, r, WheelType.STEERABLE,
            steer_min=-lim, steer_max=lim, driven=front,
        ),
        _corner(
            "front_right", base, -half, r, WheelType.STEERABLE,
            steer_min=-lim, steer_max=lim, driven=front,
        ),
        _corner("rear_left", 0.0, half, r, WheelType.FIXED, driven=rear),
        _corner("rear_right", 0.0, -half, r, WheelType.FIXED, driven=rear),
    ]


def _omni(p: Mapping[str, Param]) -> list[Wheel]:
    # Positive wheel speed drives the robot counter-clockwise around its centre, as in the
    # seeds' omni robots (v_i = v_tras_i + L * wz): beta = pi turns Siegwart's rolling row
    # into (-sin(alpha), cos(alpha), l).
    r, dist, count = _f(p, "wheel_radius"), _f(p, "wheel_distance"), int(p["wheel_count"])
    first = _f(p, "first_wheel_angle")
    return [
        Wheel(
            name=f"wheel_{k + 1}",
            type=WheelType.SWEDISH,
            alpha=first + 2 * math.pi * k / count,
            l=dist,
            beta=math.pi,
            radius=r,
        )
        for k in range(count)
    ]


def _mecanum(p: Mapping[str, Param]) -> list[Wheel]:
    # Rollers in the usual "X" seen from above: front_left and rear_right at -gamma, the
    # others at +gamma, giving fl = vx - vy - (lx + ly) wz as in seeds 001 and 003.
    r, hx, hy, g = (
        _f(p, "wheel_radius"), _f(p, "wheelbase") / 2, _f(p, "track") / 2, _f(p, "roller_angle")
    )
    corners = (
        ("front_left", hx, hy, -g),
        ("front_right", hx, -hy, g),
        ("rear_left", -hx, hy, g),
        ("rear_right", -hx, -hy, -g),
    )
    return [_corner(n, x, y, r, WheelType.SWEDISH, gamma=gm) for n, x, y, gm in corners]


def _swerve(p: Mapping[str, Param]) -> list[Wheel]:
    r, hx, hy = _f(p, "wheel_radius"), _f(p, "wheelbase") / 2, _f(p, "track") / 2
    lim, rate = _f(p, "max_steer"), _f(p, "max_steer_rate")
    corners = (
        ("front_left", hx, hy),
        ("front_right", hx, -hy),
        ("rear_left", -hx, hy),
        ("rear_right", -hx, -hy),
    )
    return [
        _corner(
            n, x, y, r, WheelType.STEERABLE,
            steer_min=-lim, steer_max=lim, max_steer_rate=rate,
        )
        for n, x, y in corners
    ]


_R = {"wheel_radius": None}

PRESETS: dict[str, Preset] = {
    p.name: p
    for p in (
        Preset("differential", {**_R, "track": None}, {}, _differential,
               "vy = 0; any vx and wz"),
        Preset("skid_steer", {**_R, "track": None, "wheelbase": None, "effective_track": 0.0},
               {}, _skid_steer, "vy = 0; turning slips by design (effective track)"),
        Preset("synchro",
               {**_R, "wheel_distance": None, "wheel_count": 3, "max_steer": math.pi},
               {}, _synchro, "wz = 0; any vx and vy (the turret carries the heading)"),
        Preset("tricycle",
               {**_R, "wheelbase": None, "track": None, "max_steer": math.pi / 2,
                "drive": "front"},
               {"drive": ("front", "rear")}, _tricycle,
               "vy = 0; curvature limited by max_steer"),
        Preset("ackermann",
               {**_R, "wheelbase": None, "track": None, "max_steer": 0.6, "drive": "rear"},
               {"drive": ("front", "rear", "all")}, _ackermann,
               "vy = 0; curvature limited by the inner wheel's max_steer; no turning in place"),
        Preset("omni",
               {**_R, "wheel_distance": None, "wheel_count": 3, "first_wheel_angle": 0.0},
               {}, _omni, "any twist"),
        Preset("mecanum",
               {**_R, "wheelbase": None, "track": None, "roller_angle": math.pi / 4},
               {}, _mecanum, "any twist"),
        Preset("swerve",
               {**_R, "wheelbase": None, "track": None, "max_steer": math.pi,
                "max_steer_rate": math.inf},
               {}, _swerve, "any twist, steering within limits"),
    )
}
