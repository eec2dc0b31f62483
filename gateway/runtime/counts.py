"""The control cycle's event counters: what :class:`~gateway.runtime.loop.Gateway` and its CAN
command input (:class:`~gateway.runtime.can_twist.CanTwists`) count since start.

A mutable record with one ``int`` per event, incremented by attribute in the cycle; the bus
edge (:class:`gateway.bus.edge.EdgeCounts`) and the supervisor
(:class:`gateway.core.counts.SupervisorCounts`) keep their own.  The status report
(:mod:`gateway.runtime.report`) reads all three into its ``counters``.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["LoopCounts"]


@dataclass(slots=True)
class LoopCounts:
    """What the control cycle counted since start (in the status's ``counters``)."""

    #: Control cycles run.
    cycles: int = 0
    #: WG_Twist_Cmd frames taken (duplicates not included).
    can_twists: int = 0
    #: WG_Twist_Cmd frames that repeated the previous frame's counter.
    can_duplicates: int = 0
    #: WG_Twist_Cmd frames missing from the counter's sequence.
    can_lost: int = 0
    #: WG_Twist_Cmd frames that could not be decoded.
    bad_can_twists: int = 0
    #: Errors reported (WG_Error frames, and error events for subscribers).
    errors_reported: int = 0
    #: Errors whose WG_Error frame was not sent: newer errors took the cycle's frame
    #: (:data:`gateway.runtime.publish.ERRORS_PER_CYCLE`); each is in the outbox all the same.
    errors_not_sent: int = 0
    #: Odometry updates skipped: the kinematics refused the wheels' feedback.
    odometry_errors: int = 0
    #: Steps of a wheel's position the odometry took for jumps, not motion (a controller
    #: that restarted its count, a corrupt value: :mod:`gateway.core.odom_feed`).
    position_jumps: int = 0
