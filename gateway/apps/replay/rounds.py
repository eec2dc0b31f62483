"""Which sets of the wheels' positions a log replay integrates: :class:`Rounds`.

A *round* is every driven wheel's position newer than at the last round, the closest in time
of those that follow one another.  ``candump`` stamps each frame on its own and the
controllers answer one after the other (the TPDOs of one CiA 402 SYNC, an ODrive's estimates
at its own phase), so the sets that a new position makes come and go: the first complete one
is held, and replaced by the next one while that spreads over less time.  The TPDOs of one SYNC
spread over a millisecond or so, the first wheel of the next SYNC with the last of this one
over nearly a period; a ``--record`` log stamps a cycle's frames alike, a spread of none.

A wheel that falls silent is waited for at most the replay's longest interval, counted from the
first position newer than at the last round, or from the end of a stall of every controller
(:meth:`Rounds.waited`, :meth:`Rounds.resume`), not from the last round; and a set in which
every wheel's position is new is a round, however long it took.  Otherwise, after a stretch
in which no controller sent (a stalled bus or sender, a ``candump`` starved of CPU), the first
wheel back would count every other wheel as silent, and its new position integrated against
their old ones is a turn the robot did not make, undone by the next update, the translation
between them going the wrong way (a CI run: 0.9 m off over a 4 m square recorded in an
emulated VM).

An update as soon as every wheel had a newer position paired the first wheel of one round with
the last of the one before, and once out of step it stayed so, every update mixing positions a
period apart: on a CiA 402 log recorded under load (``candump`` in an emulated VM), 4 % of false
distance and 0.19 rad of heading off on the way.  Controllers that send at their own phases, as
ODrives do, pair with their neighbours closest in time.

Pure: the caller passes every wheel's latest feedback (stamped with its position's time,
:class:`~gateway.core.types.WheelFeedback`) and counts the frames the drivers take.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, cast

if TYPE_CHECKING:
    from collections.abc import Callable, Sequence

    from gateway.core.types import WheelFeedback

__all__ = ["STAMP_SLACK_S", "Rounds"]

#: Slack for float rounding of time stamps (microseconds in the log; float64 epoch times
#: resolve 0.24 us), s: spreads closer than this are alike.
STAMP_SLACK_S = 1e-6


def _times(feedback: Sequence[WheelFeedback | None], wheels: Sequence[int]) -> list[float]:
    """The position times of ``wheels`` (which all have feedback)."""
    return [cast("WheelFeedback", feedback[i]).timestamp_s for i in wheels]


class Rounds:
    """The rounds of a replay (see the module docstring).

    :param needed: the model indices of the driven wheels.
    """

    __slots__ = ("first_new_s", "held", "held_spread", "held_taken", "held_times", "last",
                 "needed", "resumed_s", "taken")

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
        #: The frames the drivers took since the last round (the caller counts them): every
        #: driven wheel having a new position needs one each, so fewer spare the look.
        self.taken = 0
        #: The time of the first position newer than at the last round, once :meth:`waited`
        #: saw one (``None``: not yet).
        self.first_new_s: float | None = None
        #: When every controller last came back from a stall (:meth:`resume`).
        self.resumed_s = -math.inf

    def due(self, feedback: list[WheelFeedback | None]) -> list[WheelFeedback | None] | None:
        """The round due at this ``feedback``, if any: the one held, when this one spreads
        over no less time (this one is held in turn when every driven wheel has a newer
        position in it)."""
        held = self.held
        if held is None:
            self.hold_if_new(feedback)
            held = self.held
            if held is None or self.held_spread > STAMP_SLACK_S:
                return None
            # In step already (a cycle's frames of a ``--record`` log share one stamp):
            # nothing closer can come, so it is not held for the next position.
            self.take(held)
            return held
        times = _times(feedback, self.needed)
        if times == self.held_times:
            return None  # no new position since
        if max(times) - min(times) + STAMP_SLACK_S < self.held_spread:
            self._hold(feedback, times)  # closer in time
            return None
        self.take(held, self.taken - self.held_taken)
        self.hold_if_new(feedback)
        return held

    def take(self, feedback: list[WheelFeedback | None], taken_since: int = 0) -> None:
        """``feedback`` is a round, ``taken_since`` frames ago: from here on, every driven
        wheel needs a position newer than in it (nothing is held)."""
        self.held = None
        self.last = [feedback[i] for i in self.needed]
        self.taken = taken_since
        self.first_new_s = None

    def waited(self, feedback: Callable[[], Sequence[WheelFeedback | None]],
               now_s: float) -> float:
        """How long new positions have waited for a round at ``now_s`` (s): since the first
        driven wheel's position newer than at the last round; 0 while there is none (frames
        without a position, such as heartbeats, wait for nothing).  ``feedback`` gives every
        wheel's latest feedback; it is asked only until a new position is seen, so the caller
        asks at every new time stamp and the first new position's time is its own."""
        since = self.first_new_s
        if since is None:
            latest = feedback()
            since = self.first_new_s = min(
                (fb.timestamp_s for i, before in zip(self.needed, self.last, strict=True)
                 if (fb := latest[i]) is not None
                 and (before is None or fb.timestamp_s > before.timestamp_s)), default=None)
            if since is None:
                return 0.0
        return now_s - max(since, self.resumed_s)

    def resume(self, t: float) -> None:
        """Every controller was silent until ``t`` (a stall): from then on a wheel is waited
        for as if the first new position came at ``t``, also when one came before the stall
        (the same wheel may then come back first again)."""
        self.resumed_s = t

    def is_new(self, feedback: Sequence[WheelFeedback | None]) -> bool:
        """Whether every driven wheel has a newer position in ``feedback`` than at the last
        round."""
        for i, before in zip(self.needed, self.last, strict=True):
            fb = feedback[i]
            if fb is None or (before is not None and fb.timestamp_s <= before.timestamp_s):
                return False
        return True

    def hold_if_new(self, feedback: list[WheelFeedback | None]) -> None:
        """Hold ``feedback`` if every driven wheel has a newer position in it than at the last
        round (:meth:`is_new`; else wait until every one has)."""
        if self.is_new(feedback):
            self._hold(feedback, _times(feedback, self.needed))

    def _hold(self, feedback: list[WheelFeedback | None], times: list[float]) -> None:
        self.held, self.held_times, self.held_spread = feedback, times, max(times) - min(times)
        self.held_taken = self.taken
