"""The supervisor's event counters: what :class:`gateway.core.control.Supervisor` counts since
start.

A mutable record with one ``int`` per event, incremented by attribute; the control cycle
(:class:`gateway.runtime.counts.LoopCounts`) and the bus edge
(:class:`gateway.bus.edge.EdgeCounts`) keep their own.  The status report
(:mod:`gateway.runtime.report`) reads all three into its ``counters``.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["SupervisorCounts"]


@dataclass(slots=True)
class SupervisorCounts:
    """What the supervisor counted since start (in the status's ``counters``)."""

    #: Twists that no wheel speeds can follow (rejected or projected).
    infeasible: int = 0
    #: Infeasible twists followed as their nearest feasible twist (``infeasible_policy``).
    projected: int = 0
    #: Twists refused because the gateway was not RUNNING.
    rejected: int = 0
    #: Faults: a motor, an enable timed out or refused, the tracking check, the bus.
    faults: int = 0
    #: Times the command timeout set the target to zero.
    cmd_timeouts: int = 0
    #: E-stops taken (one that is already latched is not counted again).
    estops: int = 0
