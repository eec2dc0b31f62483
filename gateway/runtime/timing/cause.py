"""The causes of a late start of the control loop: :class:`MissCause`.

Its own module, below both :mod:`gateway.runtime.timing.stats` (which counts late starts by
cause) and :mod:`gateway.runtime.timing.misses` (which classifies them with the scheduler's
help), so that neither imports the other.
"""

from __future__ import annotations

import enum


class MissCause(enum.Enum):
    """What kept the loop from its deadline (see :mod:`gateway.runtime.timing.misses`)."""

    ON_CPU = "on_cpu"
    RUNNABLE = "runnable"
    ASLEEP = "asleep"
