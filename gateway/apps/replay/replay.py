"""Replaying a candump log through the drivers and the odometry, as the gateway would have.

:class:`Replay` is the core of ``wheelgate odom``: every :class:`~gateway.wire.candump.LogEntry`
goes, stamped with its recorded time, to a :class:`~gateway.drive.driveset.DriveSet` built from the
configuration (drivers ignore frames that are not theirs, so a gateway ``--record`` log with
both directions is fed whole), and the odometry integrates every wheel's latest position by the
gateway's own rule (:class:`gateway.core.odom_feed.OdomFeed`): at the newest feedback time
stamp, each new position carried there by its wheel's speed, with ``None`` for wheels without
feedback; the rounds are the replay's own (below).  It reads no clock and touches no file or
bus.

When the odometry is updated
    At the end of a group of entries that share one time stamp (the gateway stamps all frames
    of a cycle alike, so a ``--record`` log replays at the gateway's cadence), on a round of
    the wheels' positions, the closest in time (:mod:`gateway.apps.replay.rounds`: ``candump``
    stamps each frame on its own and the controllers answer one after the other), and at most
    once per ``min_interval_s`` of log time (by default the configured control period, as the
    gateway); a round that comes sooner is passed over, its motion is in the next update's.  A
    wheel that falls silent delays an update by at most ``max_interval_s`` from the first new
    position after the last round (a stall of every sender silences no wheel).  Positions are
    absolute, so fewer updates lose no motion: the SE(2) step is exact while the twist is
    constant, and a twist that changes within an interval costs a second-order error
    (``tools/bench_replay.py`` measures it).  Whatever is pending is integrated at the end of
    the log: the round held, then what came after it.

When the log's time jumps
    A line out of time with the lines around it is skipped and reported; a jump the log goes
    on from (a break) is bridged: :mod:`gateway.apps.replay.timeline`.

Steering angles come from the steering actuators' feedback in the log when every steered
wheel has one.  Otherwise the wheels were steered outside the gateway and the log holds no
angles: robots with steered wheels take them from the source that
:mod:`gateway.core.steer_log` describes (:class:`SteeringSource`): the twist of the wheels
that are not steered, the gateway's own ``WG_Odom_Velocity`` frames, or the neutral angles.
"""

from __future__ import annotations

import logging
import math
from typing import TYPE_CHECKING

from gateway.apps.replay.gateway_pose import GatewayPoses
from gateway.apps.replay.results import ReplaySummary, Sample
from gateway.apps.replay.rounds import STAMP_SLACK_S, Rounds
from gateway.apps.replay.timeline import MAX_GAP_S, Timeline
from gateway.core.errors import DecodeError, KinematicsError
from gateway.core.kinematics.odometry import Odometry
from gateway.core.odom_feed import OdomFeed
from gateway.core.steer_log import SteeringSource, fixed_subset, reconstruct_steer
from gateway.drive.driveset import DriveSet
from gateway.drive.rejections import LISTENER_REJECTIONS, rejected_frames
from gateway.wire.can import WgCodec

if TYPE_CHECKING:
    from collections.abc import Iterable, Iterator, Sequence

    from gateway.core.kinematics.odometry import OdometryState
    from gateway.core.settings import GatewayConfig
    from gateway.core.types import Frame, Twist
    from gateway.wire.candump import CandumpError, LogEntry

__all__ = [
    "DEFAULT_MAX_INTERVAL_S",
    "Replay",
    "ReplaySummary",
    "Sample",
    "SteeringSource",
    "Update",
    "fixed_subset",
    "reconstruct_steer",
]

log = logging.getLogger(__name__)

#: Default log time after which a pending update waits no longer for every wheel, s.
DEFAULT_MAX_INTERVAL_S = 0.1
#: A silence of every controller longer than the longest interval and this many times the
#: usual time between two of their frames is a stall, not a wheel falling silent: a log whose
#: controllers send at 10 Hz or slower has no stalls by this rule, and a silent wheel is still
#: found there after the longest interval.
STALL_FACTOR = 4.0
#: The weight of each new time between two feedback frames in their moving average.
GAP_WEIGHT = 0.1

#: What one odometry update takes: every wheel's position, the stamp, the steering angles.
Update = tuple[tuple[float | None, ...], float, tuple[float | None, ...]]


class Replay:
    """Feeds log entries to the drivers and integrates the odometry.

    :param config: the robot (its motors decide which frames are feedback).
    :param min_interval_s: least log time between two odometry updates, s; by default the
        control period of the configuration (``gateway.rate_hz``), the gateway's own cadence.
    :param max_interval_s: log time after which the odometry is updated even though some
        driven wheel has no new sample (a wheel that fell silent), counted from the first new
        position after the last round, s; a position older than this is not carried on to an
        update's time by its speed.
    :param max_gap_s: the largest step forward of the log's time that is no jump, s
        (:mod:`gateway.apps.replay.timeline`).
    :raises DriverNotFoundError: if a driver cannot be loaded.
    :raises ValueError: if an interval is negative or not finite, or ``max_gap_s`` not positive.
    """

    def __init__(
        self,
        config: GatewayConfig,
        min_interval_s: float | None = None,
        max_interval_s: float = DEFAULT_MAX_INTERVAL_S,
        max_gap_s: float = MAX_GAP_S,
    ) -> None:
        if min_interval_s is None:
            min_interval_s = 1.0 / config.loop.rate_hz
        for name, value in (("min_interval_s", min_interval_s),
                            ("max_interval_s", max_interval_s)):
            if not 0.0 <= value < math.inf:
                raise ValueError(f"Expected {name} >= 0 s and finite, but got {value!r}")
        self.config = config
        self.model = config.model
        self.drives = DriveSet(config)
        self.min_interval_s = min_interval_s
        self.max_interval_s = max_interval_s
        #: Lines that could not be read, in order (filled by :meth:`feed_lines`).
        self.errors: list[CandumpError] = []
        #: The log's time line: lines out of time, breaks (kept by :meth:`feed_lines`).
        self.timeline = Timeline(max_gap_s)
        #: Frames no driver took, by (identifier, extended): how many, and the last.
        self.unclaimed: dict[tuple[int, bool], tuple[int, Frame]] = {}
        covered = {name for a in config.steering for name in a.steers}
        measured = bool(covered) and covered >= {w.name for w in self.model.wheels if w.steered}
        self._subset = None if measured else fixed_subset(config)
        if measured:
            self.steering = SteeringSource.ACTUATORS
        elif not any(w.steered for w in self.model.wheels):
            self.steering = SteeringSource.NONE
        elif self._subset is not None:
            self.steering = SteeringSource.FIXED_WHEELS
        else:
            self.steering = SteeringSource.NEUTRAL
        self.odometry = Odometry(self._subset[1] if self._subset else self.model)
        self._steer: tuple[float | None, ...] = self.model.neutral_steer
        # Angles from the gateway's own twist frames, when the log has them.
        self._wg = (
            WgCodec(config.loop.can_ids) if self.steering is SteeringSource.NEUTRAL else None
        )
        self._velocity_id = (config.loop.can_ids.odom_velocity, config.loop.can_ids.extended)
        self._poses = GatewayPoses(config.loop.can_ids)
        # Wheels whose feedback must be there before the first update (a later first sample
        # would leave an interval with too few wheels to solve).
        self._needed = tuple(i for i, m in enumerate(config.motors) if m is not None)
        self._n_needed = len(self._needed)
        self._feed = OdomFeed(self._needed, config.limits.max_wheel_rad_s, max_interval_s)
        #: Set to a list to keep what every odometry update takes, ``(wheel positions, stamp,
        #: steering angles)``, to integrate it again on another geometry (``wheelgate
        #: calibrate``).
        self.kept: list[Update] | None = None
        self._rounds = Rounds(self._needed)
        groups = self.drives.groups
        self._on_frame = groups[0][0].on_frame if len(groups) == 1 else self.drives.on_frame
        self._pending = False
        self._group_s: float | None = None
        self._last_update_s = float("-inf")
        self._start_s: float | None = None
        self._entries = 0
        self._received = 0
        self._motor_frames = 0
        # The last feedback frame's time and the usual time between two (a moving average):
        # a much longer silence of every controller is a stall (see feed).
        self._motor_s = -math.inf
        self._motor_gap_s = 0.0
        self._updates = 0
        self._skipped = 0

    # ----------------------------------------------------------------- input

    def feed_lines(self, lines: Iterable[str]) -> Iterator[Sample]:
        """Every update from the lines of a candump log (unreadable lines are appended to
        :attr:`errors` and skipped, the log's time is checked by :attr:`timeline`), the final
        one included."""
        feed = self.feed
        for entry in self.timeline.read(lines, self.errors):
            sample = feed(entry)
            if sample is not None:
                yield sample
        yield from self.finish()

    def feed(self, entry: LogEntry) -> Sample | None:
        """Take one entry.

        :return: the update that the start of a new time stamp group triggered, if any.
        """
        t = entry.timestamp_s
        out = None
        if t != self._group_s:
            # Cheap tests first: every driven wheel needs a frame of its own to be new.
            rounds = self._rounds
            if self._pending and (
                rounds.taken >= self._n_needed
                or rounds.held is not None
                or rounds.waited(self.drives.feedback_by_wheel, self._group_s or 0.0)
                + STAMP_SLACK_S >= self.max_interval_s
            ):
                out = self._update(final=False)
            self._group_s = t
            if self._start_s is None:
                self._start_s = t
        self._entries += 1
        if entry.is_rx:
            self._received += 1
        frame = entry.frame
        if self._on_frame(frame):
            self._motor_frames += 1
            self._rounds.taken += 1
            self._pending = True
            gap, self._motor_s = t - self._motor_s, t
            if gap < math.inf:
                if gap > self.max_interval_s and gap > STALL_FACTOR * self._motor_gap_s:
                    # Every controller was silent (a stalled bus or sender, a starved candump):
                    # no wheel fell silent then, the wait for a round starts again.
                    self._rounds.resume(t)
                self._motor_gap_s += (gap - self._motor_gap_s) * GAP_WEIGHT
        elif (
            self._wg is not None
            and frame.arbitration_id == self._velocity_id[0]
            and frame.is_extended_id == self._velocity_id[1]
        ):
            self._take_gateway_twist(self._wg, frame)
        elif (key := (frame.arbitration_id, frame.is_extended_id)) == self._poses.key:
            self._poses.take(frame, self.odometry.state.pose)
        else:  # no driver of this robot's took it: whose? (``wheelgate odom`` asks the scan)
            seen = self.unclaimed.get(key)
            self.unclaimed[key] = (1 if seen is None else seen[0] + 1, frame)
        return out

    def finish(self) -> list[Sample]:
        """Integrate whatever is still pending (at the end of the log): the round held, then
        the positions after it; the updates."""
        out = []
        while self._pending:
            sample = self._update(final=True)
            if sample is not None:
                out.append(sample)
        return out

    # ----------------------------------------------------------------- odometry

    def _update(self, final: bool) -> Sample | None:
        group = self._group_s if self._group_s is not None else 0.0
        elapsed = group - self._last_update_s
        rounds = self._rounds
        now = self.drives.feedback_by_wheel()
        # A round while no wheel is silent: the longest interval not over, or every driven
        # wheel has a new position however long it took (a stall of every sender between
        # two wheels' positions silences no wheel).
        if not final and (rounds.waited(lambda: now, group) + STAMP_SLACK_S
                          < self.max_interval_s or rounds.is_new(now)):
            found = rounds.due(now)
            if found is None:
                return None
            feedback, later = found, True
            if elapsed + STAMP_SLACK_S < self.min_interval_s:
                return None  # too soon: passed over (its positions are in the next update's)
        else:  # the longest interval is over (a wheel fell silent), or the log: the round
            # held, else what there is
            held = rounds.held
            later = held is not None
            feedback = held if held is not None else now
            rounds.take(feedback)
            if later:
                rounds.hold_if_new(now)
        self._pending = later  # (the positions that came after a held round)
        if any(feedback[i] is None for i in self._needed):
            return None  # not started: some driven wheel has not reported yet
        self._last_update_s = group
        feed, jumps = self._feed, self._feed.jumps
        got = feed.sample(feedback)
        if feed.jumps != jumps:
            log.warning("odometry at %.6f s: %s", feed.stamp_s,
                        feed.last_jump_text(self.model.names))
        if got is None:
            return None  # no feedback newer than the last update's
        stamp, positions = got
        try:
            state = self._integrate(positions, stamp)
        except KinematicsError as err:
            self._skipped += 1
            log.warning("odometry at %.6f s skipped: %s", stamp, err)
            return None
        self._updates += 1
        return Sample(
            stamp,
            state.pose,
            state.twist,
            state.slip_m_s,
            state.distance_m,
            tuple(None if fb is None else fb.velocity_rad_s for fb in feedback),
            self._steer,
        )

    def _integrate(self, positions: Sequence[float | None], stamp: float) -> OdometryState:
        if self.steering is SteeringSource.ACTUATORS:
            self._steer = self.drives.measured_steer(self._steer)
        if self.kept is not None:
            self.kept.append((tuple(positions), stamp, self._steer))
        if self._subset is None:
            return self.odometry.update(positions, stamp, self._steer)
        state = self.odometry.update([positions[i] for i in self._subset[0]], stamp)
        self._steer = self._steer_for(state.twist)
        return state

    def _steer_for(self, twist: Twist) -> tuple[float | None, ...]:
        feedback = self.drives.feedback_by_wheel()
        speeds = [None if fb is None else fb.velocity_rad_s for fb in feedback]
        return reconstruct_steer(self.model, twist, self._steer, speeds)

    def _take_gateway_twist(self, wg: WgCodec, frame: Frame) -> None:
        try:
            velocity = wg.decode_velocity(frame)
        except DecodeError as err:
            log.warning("unreadable WG_Odom_Velocity frame: %s", err)
            return
        if velocity is None:
            return
        self.steering = SteeringSource.GATEWAY_TWIST
        if velocity.twist.is_finite():
            self._steer = self._steer_for(velocity.twist)

    # ----------------------------------------------------------------- result

    def summary(self) -> ReplaySummary:
        """What was read so far and where the odometry stands."""
        st = self.odometry.state
        feedback = self.drives.feedback_by_wheel()
        return ReplaySummary(
            pose=st.pose,
            distance_m=st.distance_m,
            entries=self._entries,
            received=self._received,
            motor_frames=self._motor_frames,
            updates=self._updates,
            corrupt_lines=len(self.errors),
            start_s=self._start_s,
            end_s=self._group_s,
            steering=self.steering,
            skipped_updates=self._skipped,
            pose_check=self._poses.check(),
            out_of_time_lines=len(self.timeline.bad),
            breaks=len(self.timeline.breaks),
            gap_s=self.timeline.gap_s,
            rejections=rejected_frames(self.drives.groups, LISTENER_REJECTIONS),
            position_jumps=self._feed.jumps,
            last_jump=self._feed.last_jump_text(self.model.names),
            silent_wheels=(
                *(self.model.names[i] for i in self._needed if feedback[i] is None),
                *(a.wheel for a, fb in zip(self.config.steering, self.drives.steer_feedback(),
                                           strict=True) if fb is None),
            ),
        )
