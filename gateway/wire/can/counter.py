"""The rolling counter of ``WG_Twist_Cmd``: new, duplicate or jump, and frames lost.

Pure, no clock: the control loop feeds each received counter to a :class:`CounterTracker`
and decides what a duplicate or a jump means for the command timeout.
"""

from __future__ import annotations

import enum

from gateway.core.errors import DecodeError
from gateway.wire.can.messages import TWIST_CMD, U8_MAX


class CounterKind(enum.Enum):
    """How a ``WG_Twist_Cmd`` counter relates to the previous one."""

    #: The previous counter + 1 (mod 256), or the first counter seen.
    NEW = "new"
    #: Equal to the previous counter: a repeated frame; it must not refresh the timeout.
    DUPLICATE = "duplicate"
    #: Anything else: accepted, the frames in between are counted as lost.
    JUMP = "jump"


def classify_counter(last: int | None, counter: int) -> tuple[CounterKind, int]:
    """The kind of ``counter`` after ``last`` (``None``: none yet) and the frames lost.

    >>> classify_counter(254, 1)
    (<CounterKind.JUMP: 'jump'>, 2)
    """
    if last is None or counter == (last + 1) & U8_MAX:
        return CounterKind.NEW, 0
    if counter == last:
        return CounterKind.DUPLICATE, 0
    return CounterKind.JUMP, (counter - last - 1) & U8_MAX


class CounterTracker:
    """Classifies the counters of successive ``WG_Twist_Cmd`` frames (pure, no clock).

    Call :meth:`reset` when the sender is considered gone (e.g. on a command timeout), so
    that its next frame counts as the first one.
    """

    def __init__(self) -> None:
        #: The last counter fed, ``None`` before the first or after :meth:`reset`.
        self.last: int | None = None
        #: Frames counted as lost by jumps so far.
        self.lost_frames = 0
        #: Duplicates seen so far.
        self.duplicates = 0

    def feed(self, counter: int) -> tuple[CounterKind, int]:
        """Classify the next counter and remember it.

        :param counter: 0..255.
        :return: the kind and the frames lost before this one (non-zero for a jump only).
        :raises DecodeError: for a counter outside 0..255.
        """
        if not 0 <= counter <= U8_MAX:
            raise DecodeError(
                f'Expected "Counter" in {TWIST_CMD} between 0 and 255, but got {counter!r}.'
            )
        kind, lost = classify_counter(self.last, counter)
        self.lost_frames += lost
        if kind is CounterKind.DUPLICATE:
            self.duplicates += 1
        self.last = counter
        return kind, lost

    def reset(self) -> None:
        """Forget the last counter (the totals stay)."""
        self.last = None
