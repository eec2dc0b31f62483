"""Replaying a live-view recording (MCAP) through the odometry, as the daemon integrated it.

``wheelgate run --record-mcap FILE`` (or a ``foxglove:`` block's ``mcap``) records the live
view's channels (:mod:`gateway.runtime.liveview_channels`).  :class:`McapReplay` reads one back:

* every ``/wheels`` message gives each driven wheel's measured angle (``position_rad``, by the
  wheel's name) and :meth:`gateway.core.kinematics.odometry.Odometry.update` integrates them
  in model order, stamped with the message's log time, as the daemon's loop does with its feedback;
  wheels the recording does not name (passive ones) are ``None``, and the odometry starts once
  every driven wheel has an angle (:class:`gateway.core.odom_feed.OdomFeed`'s rule);
* steered wheels take the angles of their actuators from ``/steering`` -- measured, else
  commanded, as the loop's ``DriveSet.measured_steer`` -- through the actuator's linkage
  (:meth:`gateway.drive.driveset.DriveSet.wheel_angles`); a robot whose steered wheels have no
  actuators is replayed on the wheels that are not steered when they fix the twist
  (:func:`gateway.core.steer_log.fixed_subset`), else at the neutral angles;
* the replay starts at the recording's own ``/odom`` pose and distance where it starts, so its
  end compares with the recording's last ``/odom`` (:attr:`McapSummary.recorded`): the
  difference is what a lower rate (the snapshots' instead of every cycle's) and lost
  snapshots cost.

The messages of one snapshot share a log time and are taken together (``/steering`` with the
``/wheels`` it belongs to, whatever their order in the file).  The file is read as a stream, in
file order (https://mcap.dev/spec), so a recording whose writer died (no summary, a cut chunk)
replays up to the damage: :attr:`McapSummary.damage` says where it stopped.  LZ4 chunks, the
live view's, need only the ``mcap`` package's own dependencies.
"""

from __future__ import annotations

import json
import logging
import math
import os
from dataclasses import dataclass
from typing import IO, TYPE_CHECKING, Any

from gateway.apps.replay.replay import Sample
from gateway.core.errors import GatewayError, KinematicsError
from gateway.core.kinematics.odometry import Odometry, OdometryState, Pose
from gateway.core.odom_feed import OdomFeed
from gateway.core.steer_log import SteeringSource, fixed_subset
from gateway.core.types import Twist, WheelFeedback
from gateway.runtime.liveview_channels import (
    ODOM_TOPIC,
    STEERING_TOPIC,
    WHEELS_TOPIC,
    num,
)

if TYPE_CHECKING:
    from collections.abc import Iterator

    from gateway.core.settings import GatewayConfig

__all__ = [
    "INSTALL_HINT",
    "MCAP_MAGIC",
    "McapMissingError",
    "McapReplay",
    "McapSummary",
    "RecordingError",
    "is_mcap",
    "pose_difference",
]

log = logging.getLogger(__name__)

#: The first bytes of every MCAP file (https://mcap.dev/spec#magic).
MCAP_MAGIC = b"\x89MCAP0\r\n"
INSTALL_HINT = "install the extra: pip install 'wheelgate[foxglove]'"
_TOPICS = (WHEELS_TOPIC, STEERING_TOPIC, ODOM_TOPIC)


class RecordingError(GatewayError):
    """A file that is not a readable MCAP recording."""


class McapMissingError(GatewayError):
    """The ``mcap`` package is not installed."""


def is_mcap(path: str) -> bool:
    """Whether ``path`` names an MCAP file: its suffix is ``.mcap`` or it starts with the
    magic bytes."""
    if path.lower().endswith(".mcap"):
        return True
    try:
        with open(path, "rb") as f:
            return f.read(len(MCAP_MAGIC)) == MCAP_MAGIC
    except OSError:
        return False


@dataclass(frozen=True, slots=True)
class McapSummary:
    """What a replay of a recording read and where it ended.

    :param pose: final pose (the replay starts at ``start``).
    :param distance_m: path length, m (from the recording's distance at the start).
    :param start: the pose the replay started at (the recording's, else the origin).
    :param messages: messages read, by topic (every topic, the others too).
    :param updates: odometry updates.
    :param skipped_updates: intervals the forward kinematics could not solve.
    :param start_s: log time of the first message, s (``None``: none).
    :param end_s: log time of the last message, s.
    :param steering: where the steering angles came from.
    :param silent_wheels: driven wheels with no angle in the recording.
    :param recorded: the recording's last ``/odom`` pose (``None``: no ``/odom``).
    :param recorded_distance_m: its distance, m.
    :param robot: the robot named in the recording's metadata ('' when none).
    :param damage: why reading stopped before the end of the file ('' when it did not).
    :param unreadable: messages on the replayed topics that were not JSON objects (skipped).
    :param from_recording: whether ``start`` is the recording's pose (else the origin).
    :param position_jumps: steps of a wheel's angle taken for jumps of its count, not motion
        (:mod:`gateway.core.odom_feed`, as the daemon's loop).
    :param last_jump: the last of them, described (empty without any).
    """

    pose: Pose
    distance_m: float
    start: Pose
    messages: dict[str, int]
    updates: int
    skipped_updates: int
    start_s: float | None
    end_s: float | None
    steering: SteeringSource
    silent_wheels: tuple[str, ...]
    recorded: Pose | None
    recorded_distance_m: float | None
    robot: str
    damage: str
    unreadable: int = 0
    from_recording: bool = False
    position_jumps: int = 0
    last_jump: str = ""

    @property
    def duration_s(self) -> float:
        """Log time covered, s."""
        if self.start_s is None or self.end_s is None:
            return 0.0
        return self.end_s - self.start_s


class McapReplay:
    """Integrates a recording's wheel angles (see the module's doc).

    :param config: the robot (its model, its driven wheels, its steering actuators).
    """

    def __init__(self, config: GatewayConfig) -> None:
        self.config = config
        model = self.model = config.model
        self._driven = tuple(i for i, m in enumerate(config.motors) if m is not None)
        self._feed = OdomFeed(self._driven, config.limits.max_wheel_rad_s)
        self._drives: Any = None
        covered = {name for a in config.steering for name in a.steers}
        steered = {w.name for w in model.wheels if w.steered}
        self._subset = None
        if not steered:
            self.steering = SteeringSource.NONE
        elif covered >= steered:
            self.steering = SteeringSource.ACTUATORS
            from gateway.drive.driveset import DriveSet  # noqa: PLC0415 - steered robots only

            self._drives = DriveSet(config)
        else:
            self._subset = fixed_subset(config)
            self.steering = (SteeringSource.NEUTRAL if self._subset is None
                             else SteeringSource.FIXED_WHEELS)
        self.odometry = Odometry(self._subset[1] if self._subset else model)
        self._steer: tuple[float | None, ...] = model.neutral_steer
        self._messages: dict[str, int] = {}
        self._seen: set[str] = set()
        self._started = False
        self._start = Pose()
        self._recorded: tuple[Pose, float] | None = None
        self._start_s: float | None = None
        self._end_s: float | None = None
        self._updates = self._skipped = 0
        self._robot = ""
        self._damage = ""
        self._unreadable = 0
        self._from_recording = False

    # ----------------------------------------------------------------- input

    def feed_file(self, path: str) -> Iterator[Sample]:
        """Every odometry update of the recording at ``path``, in file order.

        :raises McapMissingError: without the ``mcap`` package.
        :raises RecordingError: when the file is not an MCAP file at all (its magic bytes).
        """
        with open(path, "rb") as f:
            head = f.read(len(MCAP_MAGIC))
            if head != MCAP_MAGIC:
                raise RecordingError(f"{path}: not an MCAP file: expected the magic bytes "
                                     f"{MCAP_MAGIC!r} at its start, got {head!r}")
            f.seek(0)
            group: list[tuple[str, dict[str, Any]]] = []
            group_ns: int | None = None
            for topic, log_ns, data in self._records(f, os.path.getsize(path)):
                if log_ns != group_ns and group:
                    sample = self._take(group, group_ns or 0)
                    group = []
                    if sample is not None:
                        yield sample
                group_ns = log_ns
                try:
                    message = json.loads(data)
                except ValueError as err:
                    self._unreadable += 1
                    if self._unreadable == 1:   # the first says why; the summary counts them
                        log.warning("%s: an unreadable %s message skipped: %s", path, topic, err)
                    continue
                if isinstance(message, dict):
                    group.append((topic, message))
                else:
                    self._unreadable += 1
            if group:
                sample = self._take(group, group_ns or 0)
                if sample is not None:
                    yield sample

    def _records(self, stream: IO[bytes], size: int) -> Iterator[tuple[str, int, bytes]]:
        """``(topic, log time, data)`` of the messages on the replayed topics, counting every
        message; reading stops at the first damage (noted in :attr:`McapSummary.damage`)."""
        try:
            from mcap import records  # noqa: PLC0415 - optional, wheelgate[foxglove]
            from mcap.stream_reader import StreamReader  # noqa: PLC0415
        except ImportError as err:
            raise McapMissingError(f"reading an MCAP file needs the mcap package ({err}): "
                                   f"{INSTALL_HINT}") from err
        topics: dict[int, str] = {}
        counts = self._messages
        reader = StreamReader(stream, validate_crcs=True, record_size_limit=max(size, 1))
        try:
            for record in reader.records:
                if isinstance(record, records.Message):
                    topic = topics.get(record.channel_id, f"channel {record.channel_id}")
                    counts[topic] = counts.get(topic, 0) + 1
                    t = record.log_time * 1e-9
                    if self._start_s is None:
                        self._start_s = t
                    self._end_s = t
                    if topic in _TOPICS:
                        yield topic, record.log_time, record.data
                elif isinstance(record, records.Channel):
                    topics[record.id] = record.topic
                elif isinstance(record, records.Metadata) and record.name == "wheelgate":
                    self._robot = record.metadata.get("robot", "")
        except Exception as err:  # the reader's errors: McapError, struct.error, lz4's...
            self._damage = (f"truncated or damaged after {sum(counts.values()):,} messages "
                            f"of a file of {size:,} bytes ({type(err).__name__}: {err})")

    # ----------------------------------------------------------------- odometry

    def _take(self, group: list[tuple[str, dict[str, Any]]], log_ns: int) -> Sample | None:
        """One snapshot's messages: the steering first, then the wheels, then ``/odom``."""
        wheels = None
        for topic, message in group:
            if topic == STEERING_TOPIC:
                self._take_steering(message)
            elif topic == WHEELS_TOPIC:
                wheels = message
            elif topic == ODOM_TOPIC:
                self._take_odom(message)
        return None if wheels is None else self._integrate(wheels, log_ns * 1e-9)

    def _take_steering(self, message: dict[str, Any]) -> None:
        drives = self._drives
        if drives is None:
            return
        steer = list(self._steer)
        for k, actuator in enumerate(self.config.steering):
            angles = message.get(actuator.wheel)
            if not isinstance(angles, dict):
                continue
            angle = num(angles.get("measured_rad"))
            if angle is None:
                angle = num(angles.get("commanded_rad"))
            if angle is not None:
                for i, wheel_angle in drives.wheel_angles(k, angle):
                    steer[i] = wheel_angle
        self._steer = tuple(steer)

    def _take_odom(self, message: dict[str, Any]) -> None:
        pose = message.get("pose")
        if not isinstance(pose, dict):
            return
        x, y, theta = num(pose.get("x_m")), num(pose.get("y_m")), num(pose.get("theta_rad"))
        if x is not None and y is not None and theta is not None:
            self._recorded = (Pose(x, y, theta), num(message.get("distance_m")) or 0.0)

    def _integrate(self, wheels: dict[str, Any], t: float) -> Sample | None:
        positions: list[float | None] = []
        speeds: list[float | None] = []
        for name in self.model.names:
            w = wheels.get(name)
            if not isinstance(w, dict):
                w = {}
            positions.append(num(w.get("position_rad")))
            speeds.append(num(w.get("measured_rad_s")))
        feed, jumps = self._feed, self._feed.jumps
        positions = feed.positions([None if p is None else WheelFeedback(p, 0.0, t)
                                    for p in positions])
        if feed.jumps != jumps:
            log.warning("odometry at %.6f s: %s", t, feed.last_jump_text(self.model.names))
        self._seen.update(self.model.names[i] for i, p in enumerate(positions) if p is not None)
        if not self._started:
            if any(positions[i] is None for i in self._driven):
                return None  # the odometry starts once every driven wheel has an angle
            self._started = True
            if self._recorded is not None:
                self._start, distance = self._recorded
                self._from_recording = True
            else:
                distance = 0.0
            self.odometry.state = OdometryState(self._start, Twist(), 0.0, distance, t)
        try:
            if self._subset is None:
                state = self.odometry.update(positions, t, self._steer)
            else:
                state = self.odometry.update([positions[i] for i in self._subset[0]], t)
        except KinematicsError as err:
            self._skipped += 1
            log.warning("odometry at %.6f s skipped: %s", t, err)
            return None
        self._updates += 1
        return Sample(t, state.pose, state.twist, state.slip_m_s, state.distance_m,
                      tuple(speeds), self._steer)

    # ----------------------------------------------------------------- result

    def summary(self) -> McapSummary:
        """What was read so far and where the odometry stands."""
        st = self.odometry.state
        recorded = self._recorded
        return McapSummary(
            pose=st.pose,
            distance_m=st.distance_m,
            start=self._start,
            messages=dict(self._messages),
            updates=self._updates,
            skipped_updates=self._skipped,
            start_s=self._start_s,
            end_s=self._end_s,
            steering=self.steering,
            silent_wheels=tuple(self.model.names[i] for i in self._driven
                                if self.model.names[i] not in self._seen),
            recorded=None if recorded is None else recorded[0],
            recorded_distance_m=None if recorded is None else recorded[1],
            robot=self._robot,
            damage=self._damage,
            unreadable=self._unreadable,
            from_recording=self._from_recording,
            position_jumps=self._feed.jumps,
            last_jump=self._feed.last_jump_text(self.model.names),
        )


def pose_difference(a: Pose, b: Pose) -> tuple[float, float, float]:
    """``a - b``: x and y (m) and the heading (rad, wrapped to [-pi, pi))."""
    dtheta = (a.theta_rad - b.theta_rad + math.pi) % (2 * math.pi) - math.pi
    return a.x_m - b.x_m, a.y_m - b.y_m, dtheta
