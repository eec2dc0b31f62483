"""From wheel feedback to odometry samples: :class:`OdomFeed`, the one rule for the gateway's
loop (:mod:`gateway.runtime.loop`) and the log replay (:mod:`gateway.apps.replay.replay`).

The odometry integrates every wheel's latest position at the time of the newest feedback:

* a sample is due when some wheel's feedback is newer than the last sample's time (the
  newest time stamp among the wheels with feedback moves on);
* that time becomes the feed's, even when the sample is not taken because a driven wheel has
  not reported yet (the odometry starts once every driven wheel has);
* wheels without feedback (passive, or not reported yet) get ``None``.

Pure: no clock, no I/O.  What to integrate it with (the steering angles, a subset of the
wheels) is the caller's: :meth:`OdomFeed.sample` returns the sample, which the caller passes to
:meth:`gateway.core.kinematics.Odometry.update`.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from collections.abc import Sequence

    from gateway.core.types import WheelFeedback

__all__ = ["OdomFeed"]


class OdomFeed:
    """The odometry's samples from the wheels' latest feedback (see the module docstring).

    :param driven: the model indices of the driven wheels, whose feedback a sample needs.
    """

    def __init__(self, driven: Sequence[int]) -> None:
        self.driven = tuple(driven)
        #: The newest feedback time seen by :meth:`sample` (s; ``-inf`` before any).
        self.stamp_s = -math.inf

    def sample(
        self, feedback: Sequence[WheelFeedback | None]
    ) -> tuple[float, list[float | None]] | None:
        """The sample due for this feedback, if any.

        :param feedback: every wheel's latest feedback, model order (``None``: none).
        :return: ``(time, positions)``: the newest feedback time and every wheel's position
            (rad, model order, ``None`` for wheels without feedback); ``None`` when no
            feedback is newer than the last sample's, or a driven wheel has none.
        """
        last = newest = self.stamp_s
        for fb in feedback:
            if fb is not None and fb.timestamp_s > newest:
                newest = fb.timestamp_s
        if newest <= last:
            return None
        self.stamp_s = newest
        positions = [None if fb is None else fb.position_rad for fb in feedback]
        for i in self.driven:
            if positions[i] is None:
                return None  # integrate once every driven wheel has reported
        return newest, positions
