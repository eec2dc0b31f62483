"""The frames the drivers rejected, by driver and reason.

A driver counts a frame of its motors that it cannot take (a Get_Encoder_Estimates of three
bytes, a position that is not a number) under a reason and keeps the last one's detail, what
was expected and what came (:attr:`gateway.drive.driver.MotorDriver.rejected`,
``last_rejection``), and goes on without it.  :func:`rejected_frames` gathers them for the
daemon's log (:mod:`gateway.runtime.rejections`) and the replay's summary
(:mod:`gateway.apps.replay.replay`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from collections.abc import Collection, Sequence

    from gateway.drive.driver import MotorDriver

__all__ = ["LISTENER_REJECTIONS", "RejectedFrames", "rejected_frames"]

#: Reasons that only mean a listener did not send the request the frame answers (a CiA 402
#: SDO response answers the gateway's request, which a monitor's or a replay's drivers never
#: sent): no fault of the bus or the log, for those to leave out.
LISTENER_REJECTIONS = frozenset({"unexpected SDO response"})


@dataclass(frozen=True, slots=True)
class RejectedFrames:
    """Frames one driver rejected for one reason.

    :param driver: the driver's name in the configuration (``odrive``).
    :param reason: why (``malformed``).
    :param frames: how many.
    :param last: the last one's detail (what was expected, what came), ``None`` when the
        driver gives none beyond the reason.
    """

    driver: str
    reason: str
    frames: int
    last: str | None


def rejected_frames(
    groups: Sequence[tuple[MotorDriver[Any], object]], leave_out: Collection[str] = ()
) -> tuple[RejectedFrames, ...]:
    """Every driver's rejected frames by reason, in the drivers' order (the reasons in the
    order they first came), but for the reasons in ``leave_out``.

    :param groups: the drivers (:attr:`gateway.drive.driveset.DriveSet.groups`).
    """
    return tuple(
        RejectedFrames(drv.motors[0].driver if drv.motors else type(drv).__name__, reason, n,
                       drv.last_rejection.get(reason))
        for drv, _ in groups
        for reason, n in drv.rejected.items()
        if n and reason not in leave_out
    )
