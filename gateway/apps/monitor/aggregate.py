"""The monitor's aggregators: frames from a bus or a log, or the daemon's status replies.

Pure: no bus, no socket, no clock.  The caller passes every time explicitly, so a recorded log
replays on its own time stamps and tests run on simulated time.

* :class:`BusMonitor` takes frames: it counts them per ID and direction, keeps the frames of
  the last ``window_s`` seconds for rates and bus load, and gives the received ones to a
  :class:`~gateway.drive.driveset.DriveSet` of the configuration, whose drivers decode motor state,
  speed, position and faults.  It never produces a frame: it only listens.
* :class:`StatusMonitor` takes the daemon's statuses (:class:`gateway.core.status.GatewayStatus`):
  rates and bus load come from the differences between statuses up to ``window_s`` apart.

Rates are counts in the window ``(now - window_s, now]`` divided by ``window_s``, or by the
time since the start while less than a window has passed.  Bus load counts the bits of every
frame (:func:`gateway.wire.busload.frame_bits`) in the window: nominal, and with worst-case bit
stuffing.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from typing import TYPE_CHECKING

from gateway.apps.monitor.view import (
    ERROR_FRAMES,
    BusLoad,
    IdView,
    MonitorSnapshot,
    MotorView,
    error_class_counter,
)
from gateway.config.budget import bus_budget
from gateway.core.errors import DecodeError, GatewayError
from gateway.core.status import BusErrorState, fault_names, state_name
from gateway.core.types import DriveState
from gateway.drive.driveset import DriveSet
from gateway.drive.labels import FrameLabel, FrameLabeler
from gateway.drive.rejections import LISTENER_REJECTIONS  # (not counted: no bus errors)
from gateway.wire.busload import bus_load, frame_bits

if TYPE_CHECKING:
    from gateway.core.settings import GatewayConfig
    from gateway.core.status import GatewayStatus
    from gateway.core.types import Frame, MotorConfig, MotorStatus

#: Default averaging window of rates and bus load, s.
WINDOW_S = 2.0
_RPM_PER_RAD_S = 60.0 / (2.0 * math.pi)
#: Drivers whose controllers say on the bus whether they are armed (the ODrive heartbeat's axis
#: state).  For the others "armed" is the sending gateway's intent, which a listener cannot
#: see, so an answering motor shows as ``online`` rather than ``disabled``.
ARMING_ON_BUS = frozenset({"odrive"})
#: The daemon's event counters shown as errors.
_DAEMON_ERRORS = ("send_failures", "frames_unsent", "receive_failures", "bus_reopens",
                  "bad_can_twists", "fd_frames_ignored")
#: Bits per frame, nominal and worst case, by [extended][data bytes].
_BITS = tuple(
    tuple((frame_bits(n, ext), frame_bits(n, ext, worst_case=True)) for n in range(9))
    for ext in (False, True)
)


def _rpm(motor: MotorConfig | None, wheel_rad_s: float | None) -> float | None:
    if motor is None or wheel_rad_s is None:
        return None
    return motor.wheel_to_motor_rad_s(wheel_rad_s) * _RPM_PER_RAD_S


def _motors_by_name(config: GatewayConfig) -> dict[str, MotorConfig]:
    """Every motor of ``config`` by the name its status carries: the drive motors and the
    steering actuators."""
    return {m.wheel: m for m in (*config.motors, *config.steering) if m is not None}


def _budget(config: GatewayConfig, drives: DriveSet) -> tuple[float, float]:
    """The load the configuration's periodic frames need (%, nominal and worst case)."""
    budget = bus_budget(config, drives)
    return budget.load(), budget.load(worst_case=True)


#: A window at least this long (s) and a measured load this many points above the budget's
#: worst case make the note of :func:`over_budget`.
OVER_BUDGET_AFTER_S = 1.0
OVER_BUDGET_POINTS = 2.0


def over_budget(load: BusLoad, span_s: float) -> tuple[str, ...]:
    """A note when the bus carries clearly more than the configuration's budget: frames the
    configuration does not know (another node, a controller's rates other than stated)."""
    budget = load.budget_percent
    if (budget is None or span_s < OVER_BUDGET_AFTER_S
            or load.nominal_percent <= budget[1] + OVER_BUDGET_POINTS):
        return ()
    return (f"the bus carries {load.nominal_percent:.1f} %, more than the configuration's "
            f"periodic frames need ({budget[0]:.1f}-{budget[1]:.1f} %): frames it does not "
            f"know (another node on the bus, a controller's message rates other than its "
            f"block states)",)


def _check_window(window_s: float) -> float:
    if not (math.isfinite(window_s) and window_s > 0.0):
        raise ValueError(f"monitor window: expected a positive number of seconds, got {window_s}")
    return window_s


class _Row:
    """Counts of one (ID, extended, remote, direction)."""

    __slots__ = ("count", "key", "label", "window")

    def __init__(self, key: tuple[int, bool, bool, str], label: FrameLabel) -> None:
        self.key = key
        self.label = label
        self.count = 0
        self.window = 0


class BusMonitor:
    """Aggregates frames from a bus or a log.

    :param config: the robot whose drivers decode the frames.
    :param window_s: averaging window of rates and load, s (> 0).
    :param source: what :attr:`MonitorSnapshot.source` says.
    :param start_s: when watching began; the first frame's time when omitted.
    :raises ValueError: for a window that is not a positive number.
    :raises DriverNotFoundError: if a driver of the configuration cannot be loaded.
    """

    def __init__(self, config: GatewayConfig, window_s: float = WINDOW_S, source: str = "bus",
                 start_s: float | None = None) -> None:
        self.config = config
        self.window_s = _check_window(window_s)
        self.source = source
        self.drives = DriveSet(config)
        self._budget = _budget(config, self.drives)
        self.labeler = FrameLabeler(config)
        self._motors = _motors_by_name(config)
        self._rows: dict[tuple[int, bool, bool, str], _Row] = {}
        self._win: deque[tuple[float, _Row, int, int]] = deque()
        self._nominal = 0
        self._worst = 0
        self._start = start_s
        #: Frames fed since the start.
        self.frames = 0
        #: Further error counters (bus error frames, corrupt log lines, ...), by name.
        self.counters: dict[str, int] = {}

    def count(self, name: str, n: int = 1) -> None:
        """Add ``n`` to the error counter ``name`` (``n = 0`` shows it at zero)."""
        self.counters[name] = self.counters.get(name, 0) + n

    def feed(self, frame: Frame, t: float, direction: str = "rx", decode: bool = True) -> None:
        """Take one frame seen at ``t`` (s, the source's clock).

        :param direction: ``"rx"`` or ``"tx"`` as the source recorded it.
        :param decode: give the frame to the drivers (false for frames the gateway sent).
        """
        key = (frame.arbitration_id, frame.is_extended_id, frame.is_remote_frame, direction)
        row = self._rows.get(key)
        if row is None:
            row = self._rows[key] = _Row(key, self.labeler.label(frame))
        row.count += 1
        row.window += 1
        nominal, worst = _BITS[frame.is_extended_id][
            0 if frame.is_remote_frame else min(frame.dlc, 8)]
        win = self._win
        win.append((t, row, nominal, worst))
        self._nominal += nominal
        self._worst += worst
        self.frames += 1
        if self._start is None:
            self._start = t
        if win[0][0] <= t - self.window_s:
            self._expire(t)
        if decode:
            if frame.timestamp_s != t:
                frame = frame.stamped(t)
            try:
                self.drives.on_frame(frame)
            except GatewayError:  # drivers count bad frames themselves; a plugin might raise
                self.count("driver errors")

    def _expire(self, now_s: float) -> None:
        win, limit = self._win, now_s - self.window_s
        while win and win[0][0] <= limit:
            _, row, nominal, worst = win.popleft()
            row.window -= 1
            self._nominal -= nominal
            self._worst -= worst

    def snapshot(self, now_s: float) -> MonitorSnapshot:
        """The view at ``now_s`` (s, the source's clock)."""
        self._expire(now_s)
        start = now_s if self._start is None else self._start
        span = min(self.window_s, now_s - start)
        per_s = 1.0 / span if span > 0.0 else 0.0
        ids = tuple(
            IdView(*row.key[:2], row.key[2], row.key[3], row.count, row.window * per_s, row.label)
            for row in sorted(self._rows.values(), key=lambda r: r.key)
        )
        bitrate = self.config.bus.bitrate
        load = BusLoad(bitrate, len(self._win) * per_s, bus_load(self._nominal * per_s, bitrate),
                       bus_load(self._worst * per_s, bitrate), self._budget)
        motors = tuple(self._motor_view(st) for st in self.drives.status(now_s))
        errors = tuple(
            (f"rejected by {self._driver_name(drv.motors)}",
             sum(n for why, n in drv.rejected.items() if why not in LISTENER_REJECTIONS))
            for drv, _ in self.drives.groups
        ) + tuple(self.counters.items())
        return MonitorSnapshot(self.source, now_s, now_s - start, max(span, 0.0), self.frames,
                               load, motors, ids, errors, notes=over_budget(load, span))

    def _driver_name(self, motors: tuple[MotorConfig, ...]) -> str:
        return motors[0].driver if motors else "?"

    def _motor_view(self, st: MotorStatus) -> MotorView:
        motor = self._motors.get(st.name)
        driver = motor.driver if motor is not None else "?"
        state = st.state.name.lower()
        if st.state is DriveState.DISABLED and driver not in ARMING_ON_BUS:
            state = "online"
        fb = st.feedback
        velocity = None if fb is None else fb.velocity_rad_s
        return MotorView(st.name, driver, st.node_id, state, fault_names(st.faults), st.detail,
                         velocity, _rpm(motor, velocity), None if fb is None else fb.position_rad,
                         st.feedback_age_s, () if motor is None else motor.steers)


@dataclass(frozen=True, slots=True)
class _Sample:
    time_s: float
    counts: dict[tuple[int, bool, str], int]
    bits: int


class StatusMonitor:
    """Aggregates the daemon's statuses (:class:`gateway.core.status.GatewayStatus`, as
    :func:`gateway.wire.socket.status.status_from_json` reads a ``status`` reply).

    :param config: the robot's configuration (names the IDs; gives gear ratios for rpm).
    :param window_s: averaging window of rates and load, s (> 0).
    :param source: what :attr:`MonitorSnapshot.source` says.
    :raises ValueError: for a window that is not a positive number.
    """

    def __init__(self, config: GatewayConfig, window_s: float = WINDOW_S,
                 source: str = "daemon") -> None:
        self.config = config
        self.window_s = _check_window(window_s)
        self.source = source
        self.labeler = FrameLabeler(config)
        self._budget = _budget(config, DriveSet(config))
        self._motors = _motors_by_name(config)
        self._classes = {type(p).__name__: m.driver for m, p in self.labeler.probes()}
        self._samples: deque[_Sample] = deque()
        self._status: GatewayStatus | None = None
        self._start: float | None = None

    def update(self, status: GatewayStatus) -> None:
        """Take one status."""
        bus = status.bus
        t = bus.time_s
        counts = {(f.can_id, f.extended, f.direction.value): f.count for f in bus.frames}
        if self._start is None:
            self._start = t
        self._samples.append(_Sample(t, counts, bus.bits))
        while len(self._samples) > 2 and self._samples[1].time_s <= t - self.window_s:
            self._samples.popleft()
        self._status = status

    def snapshot(self) -> MonitorSnapshot:
        """The view at the last status's time (rates need two statuses).

        :raises DecodeError: before the first status.
        """
        status = self._status
        if status is None or not self._samples:
            raise DecodeError("daemon status: expected a status reply before a snapshot")
        first, last = self._samples[0], self._samples[-1]
        start = first.time_s if self._start is None else self._start
        span = last.time_s - first.time_s
        per_s = 1.0 / span if span > 0.0 else 0.0
        ids = []
        for (can_id, ext, direction), n in sorted(last.counts.items()):
            rate = (n - first.counts.get((can_id, ext, direction), 0)) * per_s
            ids.append(IdView(can_id, ext, False, direction, n, rate,
                              self.labeler.label_id(can_id, ext)))
        bitrate = status.bus.bitrate or self.config.bus.bitrate
        frames = sum(last.counts.values())
        load = BusLoad(bitrate, (frames - sum(first.counts.values())) * per_s,
                       bus_load((last.bits - first.bits) * per_s, bitrate), None,
                       self._budget if status.robot == self.config.name
                       and bitrate == self.config.bus.bitrate else None)  # (another robot's)
        return MonitorSnapshot(
            self.source, last.time_s, last.time_s - start, span, frames, load,
            self._motor_views(status), tuple(ids), self._errors(status),
            state_name(status.state), self._notes(status))

    def _motor_views(self, status: GatewayStatus) -> tuple[MotorView, ...]:
        out = []
        for m in status.motors:
            motor = self._motors.get(m.name)
            out.append(MotorView(
                m.name, motor.driver if motor is not None else "?", m.node_id,
                state_name(m.state), fault_names(m.faults), m.detail, m.velocity_rad_s,
                _rpm(motor, m.velocity_rad_s), m.position_rad, m.feedback_age_s,
                () if motor is None else motor.steers))
        return tuple(out)

    def _errors(self, status: GatewayStatus) -> tuple[tuple[str, int], ...]:
        events = status.counters.events
        drivers = sorted({m.driver for m in self._motors.values()})
        by_driver = dict.fromkeys(drivers, 0)
        for cls, reasons in status.counters.rejected_frames.items():
            name = self._classes.get(cls, cls)
            by_driver[name] = by_driver.get(name, 0) + sum(reasons.values())
        out = [(f"rejected by {name}", n) for name, n in by_driver.items()]
        out += [(name.replace("_", " "), events.get(name, 0)) for name in _DAEMON_ERRORS]
        health = status.bus.health
        bus_errors = {} if health is None else health.error_frames
        out += [(ERROR_FRAMES if name == "error_frames" else error_class_counter(name), n)
                for name, n in bus_errors.items() if n or name in ("error_frames", "bus_off")]
        return tuple(out)

    def _notes(self, status: GatewayStatus) -> tuple[str, ...]:
        notes = []
        if status.robot != self.config.name:
            notes.append(f"the daemon runs robot {status.robot!r} but names come from "
                         f"{self.config.name!r}: pass the daemon's config with -c")
        health = status.bus.health
        if health is not None and not health.healthy:
            notes.append("the daemon reports its CAN bus as unhealthy")
        if health is not None and health.error_state is not BusErrorState.ACTIVE:
            notes.append(f"CAN controller {health.error_state.value.replace('_', '-')}: "
                         f"{health.last_error_frame or 'no detail'}")
        if status.reason:
            notes.append(f"gateway: {status.reason}")
        return tuple(notes)
