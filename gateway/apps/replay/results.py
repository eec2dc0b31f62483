"""What a log replay gives (:mod:`gateway.apps.replay.replay`): each odometry update
(:class:`Sample`) and the summary of the whole (:class:`ReplaySummary`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from gateway.apps.replay.gateway_pose import PoseCheck
    from gateway.core.kinematics.odometry import Pose
    from gateway.core.steer_log import SteeringSource
    from gateway.core.types import Twist
    from gateway.drive.rejections import RejectedFrames

__all__ = ["ReplaySummary", "Sample"]


@dataclass(frozen=True, slots=True)
class Sample:
    """The odometry after one update.

    :param time_s: log time of the newest feedback, s (the replay's clock after a step back).
    :param pose: integrated pose.
    :param twist: body twist over the last interval.
    :param slip_m_s: RMS residual of the forward kinematics over the last interval, m/s.
    :param distance_m: path length so far, m.
    :param wheel_rad_s: every wheel's latest reported speed (model order), rad/s, ``None``
        for wheels without feedback.
    :param steer_rad: the steering angles used (``None`` for wheels not steered).
    """

    time_s: float
    pose: Pose
    twist: Twist
    slip_m_s: float
    distance_m: float
    wheel_rad_s: tuple[float | None, ...]
    steer_rad: tuple[float | None, ...]


@dataclass(frozen=True, slots=True)
class ReplaySummary:
    """What a replay read and where it ended.

    :param pose: final pose.
    :param distance_m: path length, m.
    :param entries: log entries read.
    :param received: entries marked received (``R`` or no direction).
    :param motor_frames: entries one of the drivers claimed (its motors' frames, in either
        direction: a ``--record`` log holds the commands too).
    :param updates: odometry updates.
    :param corrupt_lines: lines that could not be read (skipped).
    :param start_s: time stamp of the first entry, s (``None`` for an empty log).
    :param end_s: time stamp of the last entry, s (after a step back of the log's time, on
        the replay's clock: :mod:`gateway.apps.replay.timeline`).
    :param steering: where the steering angles came from.
    :param skipped_updates: intervals the forward kinematics could not solve (too few wheels
        with feedback); their motion is lost.
    :param silent_wheels: driven wheels with no feedback in the log (the odometry starts once
        every driven wheel has reported, so one silent wheel leaves it at the origin), and
        steering actuators with none (their wheels are then replayed at the neutral angle).
    :param pose_check: the replay against the log's own ``WG_Odom_Pose`` frames (a
        ``wheelgate run --record`` log has them), ``None`` without two of them.
    :param out_of_time_lines: lines whose time stamp does not follow the lines around them
        (skipped).
    :param breaks: jumps of the log's time that the log goes on from (bridged).
    :param gap_s: log time the breaks forward jump over, s (not in :attr:`duration_s`).
    :param rejections: the motors' frames their drivers rejected, by driver and reason.
    :param position_jumps: steps of a wheel's position taken for jumps of its count, not
        motion (:mod:`gateway.core.odom_feed`).
    :param last_jump: the last of them, described (empty without any).
    """

    pose: Pose
    distance_m: float
    entries: int
    received: int
    motor_frames: int
    updates: int
    corrupt_lines: int
    start_s: float | None
    end_s: float | None
    steering: SteeringSource
    skipped_updates: int = 0
    silent_wheels: tuple[str, ...] = ()
    pose_check: PoseCheck | None = None
    out_of_time_lines: int = 0
    breaks: int = 0
    gap_s: float = 0.0
    rejections: tuple[RejectedFrames, ...] = ()
    position_jumps: int = 0
    last_jump: str = ""

    @property
    def duration_s(self) -> float:
        """Log time covered (the breaks' gaps left out), s."""
        if self.start_s is None or self.end_s is None:
            return 0.0
        return self.end_s - self.start_s - self.gap_s

    @property
    def rejected_frames(self) -> int:
        """The motors' frames their drivers rejected."""
        return sum(r.frames for r in self.rejections)
