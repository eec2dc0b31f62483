"""The gateway's own odometry in a log, to judge a replay by: its ``WG_Odom_Pose`` frames.

A ``wheelgate run --record`` log holds the pose the gateway integrated while it ran
(``WG_Odom_Pose``, at ``gateway.odom_rate_hz``; x and y in millimetres wrapping at
+-8388.608 m, theta in 0.1 mrad).  :class:`GatewayPoses` follows those frames during a replay
and at each one compares the gateway's motion since its first frame (``first^-1 * now``) with
the replay's over the same stretch, so a log that starts mid-run, away from the origin,
compares as well; :meth:`GatewayPoses.check` gives the difference at the end and the largest
on the way (a path that closes, a square, ends right even with a wrong radius, not on the
way).  Both come from the same encoder frames, so they agree to the frames' resolution and
an update's lag (the replay updates at the next time stamp); a large difference means
the configuration is not the one the gateway ran (a wheel radius, a gear ratio, an inverted
motor), or the gateway's odometry was reset during the log.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

from gateway.core.errors import DecodeError
from gateway.core.kinematics import wrap_angle
from gateway.core.kinematics.odometry import Pose
from gateway.wire.can import WgCodec, unwrap_position_m

if TYPE_CHECKING:
    from gateway.core.can_ids import CanIds
    from gateway.core.types import Frame

log = logging.getLogger(__name__)


def relative(start: Pose, end: Pose) -> Pose:
    """``start^-1 * end``: where ``end`` lies seen from ``start`` (heading wrapped)."""
    c, s = math.cos(start.theta_rad), math.sin(start.theta_rad)
    dx, dy = end.x_m - start.x_m, end.y_m - start.y_m
    return Pose(c * dx + s * dy, -s * dx + c * dy, wrap_angle(end.theta_rad - start.theta_rad))


@dataclass(frozen=True, slots=True)
class PoseCheck:
    """The replay against the gateway's own odometry, over the same stretch of the log.

    :param frames: ``WG_Odom_Pose`` frames read.
    :param gateway: the gateway's motion from its first pose frame to its last (in the frame
        of the first).
    :param replay: the replay's motion over the same stretch.
    :param position_error_m: the distance between the two end points, m.
    :param heading_error_rad: the difference of the two headings at the end, rad (wrapped).
    :param max_position_error_m: the largest distance between the two on the way, m.
    :param max_heading_error_rad: the largest difference of the headings on the way, rad.
    """

    frames: int
    gateway: Pose
    replay: Pose
    position_error_m: float
    heading_error_rad: float
    max_position_error_m: float
    max_heading_error_rad: float


class GatewayPoses:
    """Follows the ``WG_Odom_Pose`` frames of a log (see the module).

    :param ids: the gateway's identifiers (the configuration's ``gateway.can_ids``).
    """

    def __init__(self, ids: CanIds) -> None:
        self._codec = WgCodec(ids)
        self.key = (ids.odom_pose, ids.extended)
        self.frames = 0
        self._first: tuple[Pose, Pose] | None = None
        self._last: tuple[Pose, Pose] | None = None
        self._worst = (0.0, 0.0)

    def take(self, frame: Frame, replay_pose: Pose) -> None:
        """One ``WG_Odom_Pose`` frame, read when the replay stood at ``replay_pose``."""
        try:
            pose = self._codec.decode_pose(frame)
        except DecodeError as err:
            log.warning("unreadable WG_Odom_Pose frame: %s", err)
            return
        if pose is None:
            return
        if self._last is not None:  # x and y wrap: take the turn nearest the last pose
            before = self._last[0]
            pose = Pose(unwrap_position_m(before.x_m, pose.x_m),
                        unwrap_position_m(before.y_m, pose.y_m), pose.theta_rad)
        self.frames += 1
        if self._first is None:
            self._first = (pose, replay_pose)
        self._last = (pose, replay_pose)
        _, _, error, heading = self._difference()
        self._worst = (max(self._worst[0], error), max(self._worst[1], abs(heading)))

    def _difference(self) -> tuple[Pose, Pose, float, float]:
        assert self._first is not None and self._last is not None
        (g0, r0), (g1, r1) = self._first, self._last
        gateway, replay = relative(g0, g1), relative(r0, r1)
        error = math.hypot(gateway.x_m - replay.x_m, gateway.y_m - replay.y_m)
        heading = wrap_angle(gateway.theta_rad - replay.theta_rad)
        return gateway, replay, error, heading

    def check(self) -> PoseCheck | None:
        """The comparison, or ``None`` with fewer than two pose frames."""
        if self.frames < 2:
            return None
        gateway, replay, error, heading = self._difference()
        return PoseCheck(self.frames, gateway, replay, error, heading, *self._worst)
