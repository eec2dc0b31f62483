"""The validated configuration: frozen dataclasses that :mod:`gateway.config` fills in.

* :class:`GatewayConfig`: the whole file: the robot (its wheel-constraint model, one
  :class:`~gateway.core.types.MotorConfig` per driven wheel, the limits) and the settings below.
* :class:`BusConfig`: the ``bus:`` block, where the motor controllers are.
* :class:`LoopConfig`: the ``gateway:`` block, the daemon's settings, with the tracking-error
  check's :class:`TrackingLimits` (the check itself is :mod:`gateway.core.tracking`).

The choices of the ``gateway:`` block (:class:`InfeasiblePolicy`, :class:`FeedbackRecovery`,
:class:`FaultAction`, :class:`EstopRelease`) and of a steering block (:class:`Linkage`) are
:class:`Choice` enums: each member is equal to, hashes as and prints as its YAML value, as
Python 3.11's ``enum.StrEnum`` does (https://docs.python.org/3/library/enum.html#enum.StrEnum),
so messages and comparisons with the YAML text stay as they were.

Their defaults equal those of the keys in :mod:`gateway.config.keys`, so that a
``LoopConfig()`` made in code is what an empty ``gateway:`` block gives.  Code that receives a
configuration imports them from :mod:`gateway.config`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from gateway.core.can_ids import CanIds
from gateway.core.choice import Choice, choice
from gateway.core.protection import WatchdogPolicy

if TYPE_CHECKING:
    import enum
    from collections.abc import Mapping

    from gateway.core.bridge_settings import BridgeSettings, FoxgloveSettings
    from gateway.core.kinematics import Limits, RobotModel, Wheel
    from gateway.core.types import MotorConfig

class InfeasiblePolicy(Choice):
    """``gateway.infeasible_policy``: what an infeasible twist gets."""

    #: An error to the sender; the wheels ramp to zero.
    REJECT = "reject"
    #: The nearest feasible twist is followed, with a warning counted.
    PROJECT = "project"


class FeedbackRecovery(Choice):
    """``gateway.feedback_recovery``: how the gateway leaves a motor fault or lost feedback."""

    #: Enabled again once every motor is healthy (a few tries).
    AUTO = "auto"
    #: Only an explicit enable.
    MANUAL = "manual"


class FaultAction(Choice):
    """``gateway.fault_action``: what the motors get on a fault."""

    #: Zero speed, drives stay armed.
    ZERO = "zero"
    #: Zero speed, then disarm.
    DISARM = "disarm"


class EstopRelease(Choice):
    """``gateway.estop_release``: who may release an e-stop."""

    #: The control socket's ``enable`` only.
    SOCKET = "socket"
    #: Also a CAN twist frame's ENABLE flag and a Zenoh peer's ``rpc/enable``.
    ANY = "any"


class Linkage(Choice):
    """A steering block's ``linkage``: how one actuator's angle turns its wheels."""

    #: Every wheel at the actuator's angle.
    DIRECT = "direct"
    #: An Ackermann linkage: the angle is a virtual middle wheel's (:mod:`gateway.core.linkage`).
    ACKERMANN = "ackermann"


#: The ``gateway:`` keys whose values are choices, with their enums.
LOOP_CHOICES: dict[str, type[enum.Enum]] = {
    "infeasible_policy": InfeasiblePolicy,
    "feedback_recovery": FeedbackRecovery,
    "fault_action": FaultAction,
    "estop_release": EstopRelease,
    "controller_watchdog": WatchdogPolicy,
}


@dataclass(frozen=True, slots=True)
class BusConfig:
    """Where the motor controllers are.

    :param interface: python-can interface name (``socketcan``, ``virtual``, ...).
    :param channel: channel name (``can0``, ...).
    :param bitrate: nominal bitrate in bit/s (for bus-load figures; set the link outside).
    """

    interface: str = "virtual"
    channel: str = "wheelgate"
    bitrate: int = 500_000


@dataclass(frozen=True, slots=True)
class TrackingLimits:
    """How far and how long a wheel may be off its command (the rule is
    :mod:`gateway.core.tracking`'s).

    :param tolerance_rad_s: the window's half-width at standstill (wheel rad/s).
    :param tolerance_ratio: how much the window widens per rad/s of command.
    :param time_s: how long a wheel may stay outside the window; 0 disables the check.
    :param steer_tolerance_rad: the largest steering-angle error of a steering actuator (rad).
    """

    tolerance_rad_s: float = 1.0
    tolerance_ratio: float = 0.2
    time_s: float = 0.5
    steer_tolerance_rad: float = 0.2

    @property
    def enabled(self) -> bool:
        """Whether the check runs at all."""
        return self.time_s > 0.0

    def window(self, command_rad_s: float) -> float:
        """The largest allowed error for this command (rad/s)."""
        return self.tolerance_rad_s + self.tolerance_ratio * abs(command_rad_s)


#: The defaults, which the ``gateway:`` block's ``tracking_*`` keys take from here.
DEFAULT_LIMITS = TrackingLimits()


@dataclass(frozen=True, slots=True)
class LoopConfig:
    """The daemon's settings (``gateway:`` block).

    :param rate_hz: control loop rate, 50 to 1000 Hz.
    :param cmd_timeout_s: no valid twist for this long ramps the wheels to zero (0: never).
    :param infeasible_policy: ``reject`` (error to the sender, wheels ramp to zero) or
        ``project`` (follow the nearest feasible twist, count a warning).
    :param feedback_recovery: after a motor fault or lost feedback, ``auto`` re-enables when
        every motor is healthy again, ``manual`` waits for an explicit enable.
    :param fault_action: on a fault, ``zero`` commands zero speed, ``disarm`` also disarms.
    :param enable_on_start: enable the drives when the daemon starts (never out of a latched
        e-stop).
    :param estop_release: who may release an e-stop: ``socket`` (the control socket's
        ``enable`` only) or ``any`` (also a CAN twist frame's ENABLE flag and the Zenoh
        bridge's ``rpc/enable``).
    :param state_file: the e-stop latch file (empty: see :mod:`gateway.runtime.latch`).
    :param controller_watchdog: what happens when a controller-side watchdog the protocol can
        set over CAN is not confirmed (:class:`gateway.core.protection.WatchdogPolicy`).
    :param enable_timeout_s: how long the drives may take to enable.
    :param odom_rate_hz: odometry publishing rate (CAN and socket).
    :param status_rate_hz: status publishing rate.
    :param socket: control socket path (empty: the default path).
    :param socket_mode: file mode of the control socket.
    :param socket_uids: user IDs allowed besides the daemon's own (empty: file mode decides).
    :param can_input: accept twist frames from the CAN bus.
    :param can_ids: the gateway's own CAN IDs (``twist``, ``odom_pose``, ``odom_velocity``,
        ``status``, ``error``, ``extended``; defaults in ``config/wheelgate.dbc``).
    :param rt_priority: SCHED_FIFO priority of the loop thread (0: normal scheduling).
    :param rt_cpu: CPU to pin the loop thread to (-1: any).
    :param lock_memory: ``mlockall`` after start-up.
    :param spin_us: how long before each deadline the loop spins instead of sleeping.
    :param tracking_tolerance_rad_s: tracking-error window at standstill (wheel rad/s).
    :param tracking_tolerance_ratio: how much the window widens per rad/s of command.
    :param tracking_time_s: how long a wheel may stay outside its window before a FAULT
        (0: no tracking-error check); see :mod:`gateway.core.tracking`.
    :param tracking_steer_tolerance_rad: the steering-angle window of steering actuators (rad).

    The choices may also be given as their values (``fault_action="disarm"``): they are turned
    into their enums (:data:`LOOP_CHOICES`), and any other value raises :class:`ConfigError`.
    """

    rate_hz: float = 200.0
    cmd_timeout_s: float = 0.5
    infeasible_policy: InfeasiblePolicy = InfeasiblePolicy.REJECT
    feedback_recovery: FeedbackRecovery = FeedbackRecovery.AUTO
    fault_action: FaultAction = FaultAction.ZERO
    enable_on_start: bool = True
    estop_release: EstopRelease = EstopRelease.SOCKET
    state_file: str = ""
    controller_watchdog: WatchdogPolicy = WatchdogPolicy.REQUIRED
    enable_timeout_s: float = 5.0
    odom_rate_hz: float = 50.0
    status_rate_hz: float = 10.0
    socket: str = ""
    socket_mode: int = 0o660
    socket_uids: tuple[int, ...] = ()
    can_input: bool = True
    can_ids: CanIds = field(default_factory=CanIds)
    rt_priority: int = 0
    rt_cpu: int = -1
    lock_memory: bool = False
    spin_us: float = 200.0
    tracking_tolerance_rad_s: float = DEFAULT_LIMITS.tolerance_rad_s
    tracking_tolerance_ratio: float = DEFAULT_LIMITS.tolerance_ratio
    tracking_time_s: float = DEFAULT_LIMITS.time_s
    tracking_steer_tolerance_rad: float = DEFAULT_LIMITS.steer_tolerance_rad

    def __post_init__(self) -> None:
        for name, kind in LOOP_CHOICES.items():
            value = getattr(self, name)
            if type(value) is not kind:
                object.__setattr__(self, name, choice(kind, value, f"gateway.{name}"))

    @property
    def tracking(self) -> TrackingLimits:
        """The tracking-error check's limits."""
        return TrackingLimits(self.tracking_tolerance_rad_s, self.tracking_tolerance_ratio,
                              self.tracking_time_s, self.tracking_steer_tolerance_rad)


@dataclass(frozen=True, slots=True)
class GatewayConfig:
    """A validated configuration.

    :param source: the file it came from (or :data:`gateway.config.DEFAULT_NAME`).
    :param name: robot name.
    :param drive: preset name or ``"generic"``.
    :param geometry: the preset's geometry keys with defaults filled in (empty for generic).
    :param model: the wheel-constraint model.
    :param motors: per wheel (model order), its motor, ``None`` for passive wheels.
    :param limits: speed and acceleration limits.
    :param bus: bus settings.
    :param loop: the daemon's settings.
    :param steering: the steering actuators (``steering:`` blocks), each naming the wheels it
        turns; steered wheels without one are steered outside the gateway.
    :param warnings: what is allowed but probably wrong (``check`` prints them, ``run`` logs
        them at start).
    :param bridge: the ``bridge:`` block (Zenoh, ROS 2), ``None`` when absent.
    :param foxglove: the ``foxglove:`` block (live view), ``None`` when absent.
    :param calibration: the calibration multipliers that are not 1 (``kinematics:``:
        ``wheel_separation_multiplier``, and ``radius NAME`` per wheel); the model's geometry
        has them applied, ``geometry`` is as written.
    :param fingerprint: the CRC-32 of the file's bytes as 8 hex digits (``""``: not read from
        a file), so that a daemon's robot can be told from an edited copy of its file.
    :param path: the file as an absolute path (``""``: the embedded default or no file), for
        other processes (``source`` is as given, for messages).
    """

    source: str
    name: str
    drive: str
    geometry: Mapping[str, object]
    model: RobotModel
    motors: tuple[MotorConfig | None, ...]
    limits: Limits
    bus: BusConfig
    loop: LoopConfig = field(default_factory=LoopConfig)
    steering: tuple[MotorConfig, ...] = ()
    warnings: tuple[str, ...] = ()
    bridge: BridgeSettings | None = None
    foxglove: FoxgloveSettings | None = None
    calibration: Mapping[str, float] = field(default_factory=dict)
    fingerprint: str = ""
    path: str = ""

    @property
    def wheels(self) -> tuple[Wheel, ...]:
        """The wheels, in model order."""
        return self.model.wheels
