"""Which sets of the wheels' positions a log replay integrates: :class:`Rounds`.

A *round* is every driven wheel's position newer than at the last round, the closest in time
of those that follow one another.  ``candump`` stamps each frame on its own and the
controllers answer one after the other (the TPDOs of one CiA 402 SYNC, an ODrive's estimates
at its own phase), so the sets that a new position makes come and go: the first complete one
is held, and replaced by the next one while that spreads over less time.  The TPDOs of one SYNC
spread over a millisecond or so, the first wheel of the next SYNC with the last of this one
over nearly a period; a ``--record`` log stamps a cycle's frames alike, a spread of none.

An update as soon as every wheel had a newer position paired the first wheel of one round with
the last of the one before, and once out of step it stayed so, every update mixing positions a
period apart: on a CiA 402 log recorded under load (``candump`` in an emulated VM), 4 % of false
distance and 0.19 rad of heading off on the way.  Controllers that send at their own phases, as
ODrives do, pair with their neighbours closest in time.

Pure: the caller passes every wheel's latest feedback (stamped with its position's time,
:class:`~gateway.core.types.WheelFeedback`) and the count of frames the drivers took.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, cast

if TYPE_CHECKING:
    from collections.abc import Sequence

    from gateway.core.types import WheelFeedback

__all__ = ["Rounds"]

#: Spreads closer than this are alike (microseconds in the log; float64 epoch times resolve
#: 0.24 us), s.
_SLACK_S = 1e-6


def _times(feedback: Sequence[WheelFeedback | None], wheels: Sequence[int]) -> list[float]:
    """The position times of ``wheels`` (which all have feedback)."""
    return [cast("WheelFeedback", feedback[i]).timestamp_s for i in wheels]


class Rounds:
    """The rounds of a replay (see the module docstring).

    :param needed: the model indices of the driven wheels.
    """

    __slots__ = ("held", "held_spread", "held_taken", "held_times", "last", "needed")

    def __init__(self, needed: Sequence[int]) -> None:
        self.needed = tuple(needed)
        #: The driven wheels' feedback at the last round.
        self.last: list[WheelFeedback | None] = [None] * len(self.needed)
        #: A set held until the next position tells whether it is the closest in time: every
        #: wheel's feedback; the driven wheels' times and their spread (s); the frames the
        #: drivers had taken since the last round when it was held.
        self.held: list[WheelFeedback | None] | None = None
        self.held_times: list[float] = []
        self.held_spread = 0.0
        self.held_taken = 0

    def due(self, feedback: list[WheelFeedback | None],
            taken: int) -> list[WheelFeedback | None] | None:
        """The round due at this ``feedback`` (``taken`` frames since the last round), if
        any: the one held, when this one spreads over no less time (this one is held in turn
        when every driven wheel has a newer position in it)."""
        needed = self.needed
        held = self.held
        if held is None:
            self.hold_if_new(feedback, taken)
            return None
        times = _times(feedback, needed)
        if times == self.held_times:
            return None  # no new position since
        if max(times) - min(times) + _SLACK_S < self.held_spread:
            self._hold(feedback, times, taken)  # closer in time
            return None
        self.take(held)
        self.hold_if_new(feedback, taken - self.held_taken)
        return held

    def take(self, feedback: list[WheelFeedback | None]) -> None:
        """``feedback`` is a round: from here on, every driven wheel needs a position newer
        than in it (nothing is held)."""
        self.held = None
        self.last = [feedback[i] for i in self.needed]

    def hold_if_new(self, feedback: list[WheelFeedback | None], taken: int) -> None:
        """Hold ``feedback`` if every driven wheel has a newer position in it than at the last
        round."""
        for i, before in zip(self.needed, self.last, strict=True):
            fb = feedback[i]
            if fb is None or (before is not None and fb.timestamp_s <= before.timestamp_s):
                return  # wait until every driven wheel has a new position
        self._hold(feedback, _times(feedback, self.needed), taken)

    def _hold(self, feedback: list[WheelFeedback | None], times: list[float],
              taken: int) -> None:
        self.held, self.held_times, self.held_spread = feedback, times, max(times) - min(times)
        self.held_taken = taken
