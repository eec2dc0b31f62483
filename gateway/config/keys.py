"""The keys a configuration file accepts, described once: one :class:`OptionSpec` table per block.

Each table gives, per key, its type, its default (``None``: required), its bounds or choices and
a line of help; :func:`gateway.core.options.validate_block` checks a block against its table and
fills in the defaults.  :mod:`gateway.config` reads the file with these tables.

Two kinds of keys are not here, because they depend on what the file chose:

* the ``geometry:`` keys of a preset drive come from the preset
  (:data:`gateway.core.kinematics.PRESETS`, ``params`` and ``choices``);
* the protocol keys of a motor block come from its driver (``OPTIONS`` of the driver class).
"""

from __future__ import annotations

import math
from types import MappingProxyType
from typing import TYPE_CHECKING

from gateway.core.kinematics import WheelType
from gateway.core.options import OptionSpec
from gateway.core.protection import WatchdogPolicy
from gateway.core.settings import (
    DEFAULT_LIMITS,
    EstopRelease,
    FaultAction,
    FeedbackRecovery,
    InfeasiblePolicy,
    Linkage,
    LoopConfig,
)

if TYPE_CHECKING:
    import enum
    from collections.abc import Mapping

_DEFAULTS = LoopConfig()


def _choices(kind: type[enum.Enum]) -> tuple[object, ...]:
    """The YAML values of a choice enum, in definition order."""
    return tuple(member.value for member in kind)


#: The top-level keys of a configuration file.
TOP_KEYS = frozenset(
    {"name", "drive", "geometry", "wheels", "motors", "motor_defaults", "steering",
     "steering_defaults", "limits", "kinematics", "bus", "gateway", "bridge", "foxglove"}
)
#: The bounds of a robot's lengths (m): a wheel radius, a track, a mounting distance.  Far
#: wider than any wheeled robot; what they catch is a typo's exponent, or a unit slip (mm for
#: m) of a length above 100 mm (a 33 mm radius written as 33 passes: no bound can tell).
MIN_LENGTH_M, MAX_LENGTH_M = 1e-3, 100.0
#: The bounds of a gear ratio (motor turns per wheel turn): a gearbox reduces at most this much
#: (or steps up at most as much).
MAX_GEAR_RATIO = 1e4
#: The highest motor speed a configuration may name (RPM at the motor).
MAX_MOTOR_RPM = 100_000.0
#: The keys of a motor block that every driver takes (``motor_defaults:`` is merged in first);
#: any other key is a protocol key of the driver.
MOTOR_KEYS: Mapping[str, OptionSpec] = MappingProxyType({
    "driver": OptionSpec(str, help="driver name, e.g. odrive"),
    "node_id": OptionSpec(int, help="the controller's node ID"),
    "gear_ratio": OptionSpec(float, 1.0, minimum=1 / MAX_GEAR_RATIO, maximum=MAX_GEAR_RATIO,
                             help="motor turns per wheel turn"),
    "invert": OptionSpec(bool, False),
    "max_rpm": OptionSpec(float, above=0.0, maximum=MAX_MOTOR_RPM,
                          help="motor speed limit in RPM at the motor"),
})
#: The keys of a steering actuator's block (``steering:``, with ``steering_defaults:`` merged
#: in first) that every driver takes; any other key is a protocol key of the driver.
STEERING_KEYS: Mapping[str, OptionSpec] = MappingProxyType({
    **MOTOR_KEYS,
    "gear_ratio": OptionSpec(float, 1.0, minimum=1 / MAX_GEAR_RATIO, maximum=MAX_GEAR_RATIO,
                             help="motor turns per turn of the wheel's plane"),
    "zero_rad": OptionSpec(float, 0.0, help="motor position (rad, the controller's frame) "
                                             "with the wheels at their neutral angle"),
})
#: The keys of a steering block that say what it turns (not merged from
#: ``steering_defaults:``): several wheels through a linkage.
LINKAGE_KEYS: Mapping[str, OptionSpec] = MappingProxyType({
    "wheels": OptionSpec(list, [], help="the wheels a linkage turns; empty: the block's name "
                                        "is the wheel or steer group"),
    "linkage": OptionSpec(str, Linkage.DIRECT.value, choices=_choices(Linkage),
                          help="ackermann: the angle is that of a virtual wheel in the middle "
                               "of the wheels' axle"),
})
#: The keys of one item of ``wheels:`` (``drive: generic``).
WHEEL_KEYS: Mapping[str, OptionSpec] = MappingProxyType({
    "name": OptionSpec(str),
    "type": OptionSpec(str, choices=tuple(t.value for t in WheelType)),
    "alpha": OptionSpec(float, help="polar angle of the mounting point, rad"),
    "l": OptionSpec(float, minimum=0.0, maximum=MAX_LENGTH_M, unit=" m",
                    help="distance from the body origin, m"),
    "beta": OptionSpec(float, help="plane angle, rad"),
    "radius": OptionSpec(float, minimum=MIN_LENGTH_M, maximum=MAX_LENGTH_M, unit=" m",
                         help="wheel radius, m"),
    "gamma": OptionSpec(float, 0.0),
    "d": OptionSpec(float, 0.0, minimum=0.0, maximum=MAX_LENGTH_M, unit=" m"),
    "steer_min": OptionSpec(float, -math.pi),
    "steer_max": OptionSpec(float, math.pi),
    "max_steer_rate": OptionSpec(float, math.inf, above=0.0),
    "steer_group": OptionSpec(str, ""),
    "motor": OptionSpec(dict, {}),
})
#: The keys of ``limits:``.
LIMIT_KEYS: Mapping[str, OptionSpec] = MappingProxyType({
    "max_wheel_accel_rad_s2": OptionSpec(float, math.inf, above=0.0,
                                         help="how fast a wheel's speed may change, rad/s^2"),
    "max_wheel_decel_rad_s2": OptionSpec(float, 0.0, minimum=0.0,
                                         help="how fast a wheel may slow down, rad/s^2; 0: "
                                              "max_wheel_accel_rad_s2"),
    "max_linear_m_s": OptionSpec(float, math.inf, minimum=0.0),
    "max_angular_rad_s": OptionSpec(float, math.inf, minimum=0.0),
})
#: The range of a calibration multiplier: a correction, not a different robot.
MIN_MULTIPLIER, MAX_MULTIPLIER = 0.5, 2.0
#: The keys of ``kinematics:``.
KINEMATICS_KEYS: Mapping[str, OptionSpec] = MappingProxyType({
    "slip_tolerance_m_s": OptionSpec(float, 1e-3, minimum=0.0),
    # Calibration as ros2_control's diff_drive_controller has it (wheel_separation_multiplier,
    # left/right_wheel_radius_multiplier): measured corrections on the nominal geometry.
    "wheel_separation_multiplier": OptionSpec(
        float, 1.0, minimum=MIN_MULTIPLIER, maximum=MAX_MULTIPLIER,
        help="factor on the geometry's track (a drive with a track)"),
    "wheel_radius_multipliers": OptionSpec(
        dict, {}, help="wheel name -> factor on its radius"),
})

#: The keys of ``gateway:``, the daemon's settings (:class:`gateway.core.settings.LoopConfig`).
GATEWAY_KEYS: Mapping[str, OptionSpec] = MappingProxyType({
    "rate_hz": OptionSpec(float, 200.0, minimum=50.0, maximum=1000.0,
                          help="control loop rate"),
    "cmd_timeout_s": OptionSpec(float, 0.5, minimum=0.0, maximum=60.0,
                                help="no valid twist for this long ramps the wheels to zero; 0 "
                                     "disables"),
    "infeasible_policy": OptionSpec(str, _DEFAULTS.infeasible_policy.value,
                                    choices=_choices(InfeasiblePolicy)),
    "feedback_recovery": OptionSpec(str, _DEFAULTS.feedback_recovery.value,
                                    choices=_choices(FeedbackRecovery)),
    "fault_action": OptionSpec(str, _DEFAULTS.fault_action.value, choices=_choices(FaultAction)),
    "enable_on_start": OptionSpec(bool, True),
    "estop_release": OptionSpec(str, _DEFAULTS.estop_release.value,
                                choices=_choices(EstopRelease),
                                help="who may release an e-stop: the control socket only, or "
                                     "also a CAN twist frame's ENABLE flag and the Zenoh "
                                     "bridge's rpc/enable"),
    "state_file": OptionSpec(str, "", help="the e-stop latch file; empty: $STATE_DIRECTORY/"
                                           "estop, else ~/.local/state/wheelgate/"),
    "controller_watchdog": OptionSpec(
        str, _DEFAULTS.controller_watchdog.value, choices=_choices(WatchdogPolicy),
        help="a controller-side watchdog the protocol can set over CAN but that is not "
             "confirmed: refuse to arm the motor (required) or arm it with a warning (warn)"),
    "enable_timeout_s": OptionSpec(float, 5.0, minimum=0.1),
    "odom_rate_hz": OptionSpec(float, 50.0, minimum=0.1, maximum=1000.0),
    "status_rate_hz": OptionSpec(float, 10.0, minimum=0.1, maximum=1000.0),
    "socket": OptionSpec(str, "", help="control socket path; empty: the default path"),
    "socket_mode": OptionSpec(int, 0o660, minimum=0, maximum=0o777),
    "socket_uids": OptionSpec(list, []),
    "can_input": OptionSpec(bool, True),
    "can_ids": OptionSpec(dict, {}),
    "rt_priority": OptionSpec(int, 0, minimum=0, maximum=99,
                              help="SCHED_FIFO priority of the loop thread; 0: normal"),
    "rt_cpu": OptionSpec(int, -1, minimum=-1, help="CPU to pin the loop to; -1: any"),
    "lock_memory": OptionSpec(bool, False),
    "spin_us": OptionSpec(float, 200.0, minimum=0.0, maximum=5000.0),
    "tracking_tolerance_rad_s": OptionSpec(
        float, DEFAULT_LIMITS.tolerance_rad_s, minimum=0.0,
        help="wheel speed error allowed at standstill (wheel rad/s)"),
    "tracking_tolerance_ratio": OptionSpec(
        float, DEFAULT_LIMITS.tolerance_ratio, minimum=0.0,
        help="added error allowed per rad/s of command"),
    "tracking_time_s": OptionSpec(
        float, DEFAULT_LIMITS.time_s, minimum=0.0,
        help="how long a wheel may stay off its command before a fault; 0 disables the check"),
    "tracking_steer_tolerance_rad": OptionSpec(
        float, DEFAULT_LIMITS.steer_tolerance_rad, minimum=0.0,
        help="steering-angle error allowed of a steering actuator (rad)"),
})
#: The keys of ``gateway.can_ids:``, the gateway's own CAN IDs (:class:`gateway.wire.can.CanIds`).
CAN_ID_KEYS: Mapping[str, OptionSpec] = MappingProxyType({
    "twist": OptionSpec(int, 0x100, minimum=0),
    "odom_pose": OptionSpec(int, 0x101, minimum=0),
    "odom_velocity": OptionSpec(int, 0x102, minimum=0),
    "status": OptionSpec(int, 0x103, minimum=0),
    "error": OptionSpec(int, 0x104, minimum=0),
    "extended": OptionSpec(bool, False),
})
#: The keys of ``bus:``; each can also come from ``GATEWAY_<KEY>`` or a ``--<key>`` flag.
BUS_KEYS: Mapping[str, OptionSpec] = MappingProxyType({
    "interface": OptionSpec(str, "virtual"),
    "channel": OptionSpec(str, "wheelgate"),
    "bitrate": OptionSpec(int, 500_000, minimum=10_000, maximum=1_000_000),
})
