"""The validated configuration: frozen dataclasses that :mod:`gateway.config` fills in.

* :class:`GatewayConfig`: the whole file: the robot (its wheel-constraint model, one
  :class:`~gateway.core.types.MotorConfig` per driven wheel, the limits) and the settings below.
* :class:`BusConfig`: the ``bus:`` block, where the motor controllers are.
* :class:`LoopConfig`: the ``gateway:`` block, the daemon's settings.

Their defaults equal those of the keys in :mod:`gateway.config.keys`, so that a
``LoopConfig()`` made in code is what an empty ``gateway:`` block gives.  Code that receives a
configuration imports them from :mod:`gateway.config`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from gateway.core.protection import WatchdogPolicy
from gateway.core.tracking import DEFAULT_LIMITS, TrackingLimits
from gateway.wire.can import CanIds

if TYPE_CHECKING:
    from collections.abc import Mapping

    from gateway.core.kinematics import Limits, RobotModel, Wheel
    from gateway.core.types import MotorConfig


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
class LoopConfig:
    """The daemon's settings (``gateway:`` block).

    :param rate_hz: control loop rate, 50 to 1000 Hz.
    :param cmd_timeout_s: no valid twist for this long ramps the wheels to zero (0: never).
    :param infeasible_policy: ``"reject"`` (error to the sender, wheels ramp to zero) or
        ``"project"`` (follow the nearest feasible twist, count a warning).
    :param feedback_recovery: after a motor fault or lost feedback, ``"auto"`` re-enables when
        every motor is healthy again, ``"manual"`` waits for an explicit enable.
    :param fault_action: on a fault, ``"zero"`` commands zero speed, ``"disarm"`` also disarms.
    :param enable_on_start: enable the drives when the daemon starts (never out of a latched
        e-stop).
    :param estop_release: who may release an e-stop: ``"socket"`` (the control socket's
        ``enable`` only) or ``"any"`` (also a CAN twist frame's ENABLE flag).
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
    """

    rate_hz: float = 200.0
    cmd_timeout_s: float = 0.5
    infeasible_policy: str = "reject"
    feedback_recovery: str = "auto"
    fault_action: str = "zero"
    enable_on_start: bool = True
    estop_release: str = "socket"
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

    @property
    def wheels(self) -> tuple[Wheel, ...]:
        """The wheels, in model order."""
        return self.model.wheels
