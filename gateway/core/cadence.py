"""The next due time of something periodic (a report, a heartbeat, a simulated device's cyclic
frame), one rule for every schedule of the project."""

from __future__ import annotations

__all__ = ["next_due"]


def next_due(due_s: float | None, now_s: float, period_s: float) -> float:
    """When the next one is due, after the one due at ``due_s`` went out at ``now_s``: one
    period after ``due_s``, on its grid, so that a cycle a little late (or a hair early: the
    next) does not lengthen every period; one period from now when none was due yet (``None``)
    or the caller fell behind by a whole period (no burst to catch up)."""
    nxt = (now_s if due_s is None else due_s) + period_s
    return nxt if nxt > now_s else now_s + period_s
