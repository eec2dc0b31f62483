"""What ``wheelgate init`` writes into a configuration besides the example's own comments: what
each block means, and what to measure or fill in before the robot moves.

The lines that need doing are marked with the words of :data:`MEASURE` and :data:`FILL_IN`.
The meaning of a key comes from the key tables where they have one (``help`` of
:data:`gateway.config.keys.MOTOR_KEYS`, :data:`~gateway.config.keys.LIMIT_KEYS` and of each
driver's ``OPTIONS``); the geometry keys, which the presets declare without help, are
described here.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from gateway.config.keys import KINEMATICS_KEYS, LIMIT_KEYS, MOTOR_KEYS, STEERING_KEYS
from gateway.core.kinematics import PRESETS
from gateway.drive.registry import VALID_DRIVERS

if TYPE_CHECKING:
    from collections.abc import Mapping

    from gateway.core.options import OptionSpec

#: The mark of a value to measure on the robot.
MEASURE = "MEASURE"
#: The mark of a value to look up (data sheet, gearbox, controller settings) and fill in.
FILL_IN = "FILL IN"

#: The geometry keys of the presets: what each is and how to get it.
GEOMETRY: Mapping[str, str] = {
    "wheel_radius": f"m, {MEASURE}: rolling radius (10 turns' distance / 20 pi)",
    "track": f"m, {MEASURE}: left to right wheel, centre to centre",
    "wheelbase": f"m, {MEASURE}: front axle to rear axle",
    "effective_track": "m: the track turns in place need (calibrate); 0: track",
    "wheel_distance": f"m, {MEASURE}: robot centre to each wheel",
    "wheel_count": "wheels, evenly spaced on the circle",
    "first_wheel_angle": "rad: wheel_1's place, counter-clockwise from x",
    "max_steer": f"rad, {MEASURE}: the steering stop, either way",
    "max_steer_rate": "rad/s: the steering speed limit",
    "drive": "the driven axle",
    "roller_angle": "rad: the rollers' angle to the wheel's axle",
}

#: The limit keys' units, where the key table gives no help.
LIMITS: Mapping[str, str] = {
    "max_wheel_accel_rad_s2": "rad/s^2 at the wheel",
    "max_linear_m_s": "m/s: the robot's speed",
    "max_angular_rad_s": "rad/s: the robot's turn rate",
}

#: What the keys every driver takes need (instead of their help in the key table).
MOTOR_TODO: Mapping[str, str] = {
    "driver": f"the protocol: {', '.join(sorted(VALID_DRIVERS))}, or a plugin's",
    "gear_ratio": f"motor turns per wheel turn, {FILL_IN} (1: direct drive)",
    "max_rpm": f"at the motor, {FILL_IN}: its rated speed or less",
    "invert": "true: this motor turns its wheel backwards",
    "zero_rad": f"rad, {MEASURE}: motor position, wheels straight ahead",
}


def blocks(drive: str) -> Mapping[str, tuple[str, ...]]:
    """The comment above each top-level block of a configuration for ``drive`` (paragraphs,
    wrapped when written)."""
    presets = ", ".join(sorted(PRESETS))
    return {
        "name": ("The robot's name: status, logs and bridges show it; twist and jog refuse a "
                 "daemon that runs another robot.",),
        "drive": (f"The kinematics: a preset ({presets}) that places its wheels from "
                  "geometry:, or generic with each wheel in wheels:.",),
        "geometry": (f"{MEASURE} on your robot: the values are the example's.",),
        "wheels": (
            "One item per wheel (the general model): alpha, the polar angle of its mounting "
            "point (rad, counter-clockwise from x forward); l, its distance from the reference "
            "point (m); beta, the angle of the wheel's plane; radius (m); gamma, a Swedish "
            "wheel's roller angle; d, a castor's offset (m).",
            f"{MEASURE} l, radius and d.  A driven wheel has a motor: block: node_id, and "
            "invert: true where the motor turns its wheel backwards.",
        ),
        "motor_defaults": (
            "Merged into every drive motor's block (the motor's own key wins).  driver, "
            "gear_ratio, max_rpm and invert are every driver's keys; the others are the "
            "driver's own (README, Drivers).",
        ),
        "motors": (
            "One block per driven wheel: node_id, the controller's CAN node ID as set on it "
            "(`wheelgate scan` lists those that answer); invert: true where the motor turns "
            "its wheel backwards (a mirrored motor, as on the right side); a gear_ratio or "
            "max_rpm here is that motor's own.",
            f"{FILL_IN} the node IDs, then spin each wheel, lifted (`wheelgate spin -c FILE "
            "WHEEL`): it says whether invert and gear_ratio are right.",
        ),
        "steering_defaults": ("Merged into every steering actuator's block.",),
        "steering": (
            "One actuator per steered wheel, steer group or linkage: node_id; gear_ratio, motor "
            "turns per turn of the wheel's plane; zero_rad, the motor position (rad) with the "
            f"wheels straight ahead.  {MEASURE} zero_rad; {FILL_IN} gear_ratio and max_rpm.",
        ),
        "limits": (
            "Limits on every command, applied before anything is sent (a key left out: no "
            "limit but the motors' max_rpm).  Keep them low on a new robot.",
        ),
        "kinematics": ("How the wheel-constraint model is solved (README, Kinematics).",),
        "gateway": ("The daemon's settings (README, The daemon).",),
        "bus": (
            "The CAN bus: interface socketcan and channel can0 on Linux.  bitrate must be the "
            "controllers'; on socketcan the link sets it (ip link set can0 up type can bitrate "
            "<bitrate>) and wheelgate refuses a link at another; on any other interface "
            "wheelgate sets it.",
        ),
        "bridge": ("The Zenoh bridge to ROS 2 (README, Beyond one robot).",),
        "foxglove": ("The Foxglove live view (README, Beyond one robot).",),
    }


def not_limited(given: Mapping[str, object]) -> tuple[str, ...]:
    """The line naming the limit keys a ``limits:`` block leaves out (no limit there)."""
    missing = [k for k, spec in LIMIT_KEYS.items()
               if k not in given and spec.default == float("inf")]
    if not missing:
        return ()
    return (f"Not limited here: {', '.join(missing)}.",)


def key_note(
    block: str, key: str, protocol: Mapping[str, OptionSpec] | None = None
) -> str:
    """The end comment of the key ``key`` of the top-level block ``block`` ("": none known).

    :param protocol: the driver's protocol keys, for a key of ``motor_defaults:`` or
        ``steering_defaults:`` that is not every driver's.
    """
    if block == "geometry":
        return GEOMETRY.get(key, "")
    if block in ("motor_defaults", "steering_defaults"):
        common = STEERING_KEYS if block == "steering_defaults" else MOTOR_KEYS
        if key == "gear_ratio" and block == "steering_defaults":
            return f"motor turns per turn of the wheel's plane, {FILL_IN}"
        if key in common:
            return MOTOR_TODO.get(key, common[key].help)
        spec = (protocol or {}).get(key)
        return spec.help if spec is not None else ""
    if block == "limits" and key in LIMIT_KEYS:
        return LIMIT_KEYS[key].help or LIMITS.get(key, "")
    if block == "kinematics" and key in KINEMATICS_KEYS:
        return KINEMATICS_KEYS[key].help
    return ""


def header(example: str, drive: str, changes: tuple[str, ...], file: str,
           example_header: tuple[str, ...]) -> tuple[str, ...]:
    """The comment lines at the top of a written configuration.

    :param example: the shipped example it started from.
    :param changes: what ``init`` changed in it, one line each.
    :param file: where it is written, for the command to check it with.
    :param example_header: the example's own lines at its top.
    """
    lines = [
        f"wheelgate configuration of a robot with drive: {drive}, written by `wheelgate init` "
        f"from the shipped example {example!r}.",
        *changes,
        "",
        "Every number is the example's until you change it.  Before the robot moves:",
        f"  {MEASURE}  the geometry (wheel radius, separations) and, where steered, zero_rad;",
        f"  {FILL_IN}  gear_ratio, max_rpm, the node IDs, invert: true where a wheel turns",
        "           backwards, and the limits;",
        f"  then     wheelgate check -c {file}, and spin each wheel (wheelgate spin -c {file}",
        "           WHEEL, the wheel lifted).",
        "Units: metres, radians, seconds; max_rpm at the motor.",
    ]
    if example_header:
        lines += ["", f"The example {example!r}:", *example_header]
    return tuple(lines)
