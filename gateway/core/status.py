"""The gateway's status as typed data: what a ``status`` request on the control socket returns.

Pure data -- frozen dataclasses and enums, no I/O, no clock, no format.  The daemon builds a
:class:`GatewayStatus` (:mod:`gateway.runtime.report`); ``wheelgate status``, ``jog`` and
``monitor`` read its fields.  Its JSON form, the ``status`` reply, is
:mod:`gateway.wire.socket.status`: the model is kept apart from its format, as cantools keeps
its database model (``cantools.database.can.Database``, ``Message``, ``Signal``) apart from the
formats it reads and writes (``cantools.database.can.formats.dbc``, ``kcd``, ``sym``;
https://github.com/cantools/cantools).

Counters whose set grows with the gateway (its event counters, the bus's error frames by class,
the frames each driver rejected by reason) are read-only mappings in the order the daemon
keeps them.  A field that a daemon older than its introduction did not report is ``None`` (see
the format for which ones).
"""

from __future__ import annotations

import enum
from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from collections.abc import Mapping

    from gateway.core.kinematics.odometry import OdometryState
    from gateway.core.protection import Guard, ProtectionState
    from gateway.core.settings import TrackingLimits
    from gateway.core.types import DriveFault, DriveState, ErrorCode, GatewayState, Twist

__all__ = [
    "BusErrorState",
    "BusHealth",
    "BusReport",
    "CommandReport",
    "ConfigReport",
    "ControllerStop",
    "Counters",
    "Direction",
    "FrameCount",
    "GatewayStatus",
    "LastError",
    "MotorReport",
    "ServerCounters",
    "SocketReport",
    "TimingReport",
    "TrackingReport",
    "fault_names",
    "state_name",
]


def state_name(state: enum.Enum) -> str:
    """How a state is written and shown: its lower-case name (``GatewayState.RUNNING`` ->
    ``"running"``)."""
    return state.name.lower() if state.name else str(state.value)


def fault_names(faults: DriveFault) -> tuple[str, ...]:
    """The lower-case names of the single flags set in ``faults``, in definition order (as
    :func:`gateway.wire.socket.to_json` writes a flag enum)."""
    return tuple(
        f.name.lower() for f in type(faults)
        if f.name and f.value and f.value & (f.value - 1) == 0 and f in faults
    )


class Direction(str, enum.Enum):
    """Which way a frame went, as the gateway saw it."""

    RX = "rx"
    TX = "tx"


class BusErrorState(str, enum.Enum):
    """The CAN controller's fault confinement state (ISO 11898-1, clause 12), as its error
    frames report it (:mod:`gateway.bus.health`) and ``status`` shows it."""

    ACTIVE = "active"
    WARNING = "warning"
    PASSIVE = "passive"
    BUS_OFF = "bus_off"


@dataclass(frozen=True, slots=True)
class ControllerStop:
    """A motor's controller-side stop (:mod:`gateway.core.protection`).

    :param guard: how it is known.
    :param timeout_s: the controller stops this long after wheelgate falls silent (``None``:
        unknown or never).
    :param state: where the configuring of a configured one stands.
    """

    guard: Guard
    timeout_s: float | None
    state: ProtectionState


@dataclass(frozen=True, slots=True)
class MotorReport:
    """One motor controller (a driven wheel's or a steering actuator's).

    :param name: the wheel's name (an actuator's block name + ``" steering"``).
    :param node_id: the controller's node ID.
    :param state: what the driver believes.
    :param faults: protocol-independent fault flags.
    :param detail: protocol-specific fault text, empty when healthy.
    :param feedback_age_s: time since the last feedback, s; ``None`` before the first.
    :param position_rad: wheel (or steering) angle, rad; ``None`` before the first feedback.
    :param velocity_rad_s: wheel (or steering) speed, rad/s; ``None`` before the first feedback.
    :param controller_stop: its controller-side stop; ``None`` when not known.
    """

    name: str
    node_id: int
    state: DriveState
    faults: DriveFault
    detail: str
    feedback_age_s: float | None
    position_rad: float | None
    velocity_rad_s: float | None
    controller_stop: ControllerStop | None = None


@dataclass(frozen=True, slots=True)
class CommandReport:
    """What the gateway is told and what it commands.

    :param target: the twist the supervisor follows.
    :param applied: the twist of the last command, after the limits.
    :param cmd_timeout_active: whether the command timeout holds the target at zero.
    :param speed_scale: the speed limits' factor on the last command (1: none).
    :param accel_scale: the acceleration limits' factor on the last command (1: none).
    """

    target: Twist
    applied: Twist
    cmd_timeout_active: bool
    speed_scale: float
    accel_scale: float


@dataclass(frozen=True, slots=True)
class TrackingReport:
    """The tracking-error check (:mod:`gateway.core.tracking`).

    :param limits: its window and time.
    :param worst_ratio: the worst wheel's error count as a share of ``limits.time_s``.
    :param steer_worst_ratio: the same for the steering actuators.
    """

    limits: TrackingLimits
    worst_ratio: float
    steer_worst_ratio: float


@dataclass(frozen=True, slots=True)
class Counters:
    """What happened since start.

    :param events: the event counters of the control cycle, the bus edge and the supervisor
        by name (``cycles``, ``frames_sent``, ``infeasible``, ``faults``, ...: the fields of
        their records, in the order of :func:`gateway.runtime.report.event_counts`).
    :param rejected_frames: per driver class, frames its driver rejected, by reason.
    :param commands_not_followed: per driver class, commands its controllers did not follow,
        by kind.
    """

    events: Mapping[str, int]
    rejected_frames: Mapping[str, Mapping[str, int]]
    commands_not_followed: Mapping[str, Mapping[str, int]]


@dataclass(frozen=True, slots=True)
class ServerCounters:
    """A snapshot of the control server's counters (all since start except ``clients``).

    :param clients: clients connected now.
    :param accepted: connections admitted as clients.
    :param refused: connections closed without being served: uid not allowed, or displaced by
        a newer connection while ``max_clients`` were connected before any of their lines was
        taken.
    :param evicted: clients closed for a newer connection while ``max_clients`` were connected,
        after they had been served (the one idle longest each time).
    :param too_long: lines longer than ``max_message_bytes``.
    :param malformed: lines that failed to parse (not counting ``too_long``).
    :param dropped_partial: clients that disconnected in the middle of a line.
    :param slow_disconnects: subscribers disconnected for not reading their events.
    :param idle_timeouts: clients closed after ``idle_timeout_s`` without a line.
    :param partial_timeouts: clients closed after ``partial_timeout_s`` in the middle of a line.
    :param deferred: times a client's input was left for a later poll because the budget of
        the poll or of the cycle was spent.
    """

    clients: int = 0
    accepted: int = 0
    refused: int = 0
    evicted: int = 0
    too_long: int = 0
    malformed: int = 0
    dropped_partial: int = 0
    slow_disconnects: int = 0
    idle_timeouts: int = 0
    partial_timeouts: int = 0
    deferred: int = 0


@dataclass(frozen=True, slots=True)
class ConfigReport:
    """The configuration the daemon runs.

    :param path: its file (or the embedded default's name).
    :param fingerprint: the CRC-32 of the file's bytes when the daemon read it
        (:attr:`gateway.core.settings.GatewayConfig.fingerprint`).
    """

    path: str
    fingerprint: str


@dataclass(frozen=True, slots=True)
class SocketReport:
    """The control socket.

    :param path: its file.
    :param counters: the server's counters.
    """

    path: str
    counters: ServerCounters


@dataclass(frozen=True, slots=True)
class TimingReport:
    """The control loop's timing over the last ring-buffer window
    (:class:`gateway.runtime.timing.LoopTimer` summarises it).

    Percentiles are nearest-rank over the window; all times are in microseconds.  Every
    figure is 0.0 when there are no samples.

    :param cycles: cycles started since start-up (not limited to the window).
    :param missed: deadlines skipped after overruns since start-up.
    :param rate_hz: the configured loop rate (0.0 if the timer was not told).
    :param achieved_hz: the cycle rate achieved over the window (0.0 with fewer than 2 cycles).
    :param lateness_p50_us: median of cycle start minus deadline.
    :param lateness_p99_us: 99th percentile of the lateness.
    :param lateness_max_us: largest lateness in the window.
    :param cost_p50_us: median of the work duration of a cycle.
    :param cost_p99_us: 99th percentile of the cost.
    :param cost_max_us: largest cost in the window.
    :param latency_samples: twist-to-frame latency samples in the window.
    :param latency_p50_us: median twist-to-frame latency.
    :param latency_p99_us: 99th percentile of the latency.
    :param latency_max_us: largest latency in the window.
    :param late_on_cpu: late starts (each skipping one or more deadlines) since start-up for
        which the loop thread was on a CPU for more than a period
        (:class:`~gateway.runtime.timing.cause.MissCause`; all three stay 0 where the kernel's
        per-thread statistics cannot be read).
    :param late_runnable: late starts for which it was runnable but not running.
    :param late_asleep: late starts for which it was woken late.
    :param burst_gap_max_ms: the longest time between two cycles' bursts of wheel frames, ms
        (``None``: not reported; the daemon adds it).
    """

    cycles: int
    missed: int
    rate_hz: float
    achieved_hz: float
    lateness_p50_us: float
    lateness_p99_us: float
    lateness_max_us: float
    cost_p50_us: float
    cost_p99_us: float
    cost_max_us: float
    latency_samples: int
    latency_p50_us: float
    latency_p99_us: float
    latency_max_us: float
    late_on_cpu: int = 0
    late_runnable: int = 0
    late_asleep: int = 0
    burst_gap_max_ms: float | None = None

    def summary(self) -> str:
        """One line for ``STATUS=`` and logs."""
        return (
            f"{self.achieved_hz:.1f}/{self.rate_hz:g} Hz, {self.cycles} cycles, "
            f"{self.missed} missed; "
            f"late p99 {self.lateness_p99_us:.0f} us max {self.lateness_max_us:.0f} us; "
            f"cost p99 {self.cost_p99_us:.0f} us max {self.cost_max_us:.0f} us"
        )


@dataclass(frozen=True, slots=True)
class LastError:
    """The last error the gateway reported (on CAN and to the socket's subscribers).

    :param code: its class.
    :param message: a sentence for people.
    """

    code: ErrorCode
    message: str


@dataclass(frozen=True, slots=True)
class FrameCount:
    """Frames seen on one identifier in one direction since start.

    :param can_id: the arbitration ID.
    :param extended: whether it is a 29-bit ID.
    :param direction: received or sent.
    :param count: how many.
    """

    can_id: int
    extended: bool
    direction: Direction
    count: int


@dataclass(frozen=True, slots=True)
class BusHealth:
    """What the CAN bus itself reported (:mod:`gateway.bus.health`).

    :param healthy: whether frames go out.
    :param error_state: the controller's error state.
    :param error_frames: error frames in all (``error_frames``) and by class.
    :param last_error_frame: the description of the last error frame (empty: none).
    """

    healthy: bool
    error_state: BusErrorState
    error_frames: Mapping[str, int]
    last_error_frame: str


@dataclass(frozen=True, slots=True)
class BusReport:
    """The CAN bus the motor controllers are on.

    :param interface: python-can interface name.
    :param channel: channel name.
    :param bitrate: nominal bitrate, bit/s.
    :param health: what the bus reported; ``None``: not reported.
    :param bits: nominal bits of every frame sent and received since start.
    :param time_s: the daemon's monotonic clock when the status was taken, s.
    :param frames: frames per identifier and direction, by ID, extended, then direction.
    """

    interface: str
    channel: str
    bitrate: int
    health: BusHealth | None
    bits: int
    time_s: float
    frames: tuple[FrameCount, ...]


@dataclass(frozen=True, slots=True)
class GatewayStatus:
    """Everything a ``status`` request returns.

    :param robot: the robot's name.
    :param state: what the gateway as a whole is doing.
    :param reason: why it is in FAULT or ESTOP (empty otherwise).
    :param command: the target and the last command.
    :param motors: every motor controller: the drive motors in the order of their wheels, then
        the steering actuators.
    :param tracking: the tracking-error check; ``None``: not reported.
    :param odometry: the odometry.
    :param counters: what happened since start.
    :param socket: the control socket.
    :param timing: the control loop's timing.
    :param last_error: the last error reported; ``None``: none yet.
    :param realtime: what the real-time set-up did, a line each.
    :param bus: the CAN bus.
    :param config: the configuration it runs (``None``: a daemon that does not say).
    """

    robot: str
    state: GatewayState
    reason: str
    command: CommandReport
    motors: tuple[MotorReport, ...]
    tracking: TrackingReport | None
    odometry: OdometryState
    counters: Counters
    socket: SocketReport
    timing: TimingReport
    last_error: LastError | None
    realtime: tuple[str, ...]
    bus: BusReport
    config: ConfigReport | None = None
