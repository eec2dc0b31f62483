"""Why the drivers rejected frames, said in the log.

A driver that rejects a frame (malformed: a wrong length, a value out of its range; or a
request it does not answer) counts it under a reason and keeps the last error's text
(:meth:`gateway.drive.driver.MotorDriver.reject`); the counts reach the status as
``rejected_frames``.  The text, which names the frame, what was expected and what came, reaches
the log here, when the status is published: the first at once, then at most one line per
:data:`INTERVAL_S` for each driver and reason whose count grew, with the count since the last
line, so a flood of bad frames costs a line every few seconds, not the loop's time.
"""

from __future__ import annotations

import logging
import math
from typing import TYPE_CHECKING, Any

from gateway.drive.rejections import rejected_frames

if TYPE_CHECKING:
    from collections.abc import Sequence

    from gateway.drive.driver import MotorDriver

log = logging.getLogger("gateway.runtime.loop")

#: The shortest time between two lines of one driver and reason (s).
INTERVAL_S = 5.0


class RejectionLog:
    """The log lines of the drivers' rejected frames (see the module docstring).

    :param groups: the robot's drivers (:attr:`gateway.drive.driveset.DriveSet.groups`).
    """

    def __init__(self, groups: Sequence[tuple[MotorDriver[Any], object]]) -> None:
        self._groups = groups
        #: Per (driver, reason): the count at the last line, and when the next may come.
        self._seen: dict[tuple[str, str], tuple[int, float]] = {}

    def check(self, now_s: float) -> None:
        """Log each driver's and reason's rejections since its last line, if there are new
        ones and :data:`INTERVAL_S` has passed since that line."""
        if not any(drv.rejected for drv, _ in self._groups):
            return
        seen = self._seen
        for r in rejected_frames(self._groups):
            before, next_s = seen.get((r.driver, r.reason), (0, -math.inf))
            if r.frames == before or now_s < next_s:
                continue
            seen[r.driver, r.reason] = (r.frames, now_s + INTERVAL_S)
            new = r.frames - before if r.frames > before else r.frames  # (counts were reset)
            log.warning("%s rejected %d frame%s (%s) since the last report%s", r.driver, new,
                        "" if new == 1 else "s", r.reason,
                        f"; the last: {r.last}" if r.last else "")
