"""From wheel feedback to odometry samples: :class:`OdomFeed`, the one rule for the gateway's
loop (:mod:`gateway.runtime.loop`) and the log replay (:mod:`gateway.apps.replay.replay`).

The odometry integrates every wheel's position at one time, the newest feedback's:

* a sample is due when some wheel's feedback is newer than the last sample's time (the
  newest time stamp among the wheels with feedback moves on);
* that time becomes the feed's, even when the sample is not taken because a driven wheel has
  not reported yet (the odometry starts once every driven wheel has);
* with *whole rounds* (the gateway's loop) a sample is due only once every driven wheel has a
  position newer than the last sample's, or is silent (none for ``silent_s``; then it is held
  where it was): controllers send at their own phases (an ODrive's estimates at its own
  10 ms timer, a VESC's STATUS at its own rate), so a sample at every new position of any
  wheel moved one wheel at a time.  On a mecanum robot that is a zig-zag: each single
  wheel's step solves to a diagonal with a turn, four of them add up to the straight line
  again, but the distance grows by up to sqrt(2) (41 %) and the odometry's twist is each
  wheel's alone (at 0.5 m/s straight: 0.42 m/s forward, 0.42 m/s sideways and 1.1 rad/s of
  turn).  After a stall of every wheel (no feedback at all for longer than ``silent_s``: a
  bus unplugged, a stalled sender) every driven wheel is waited for again, up to ``silent_s``:
  the first wheel back would otherwise find the others silent, and its position, the motion
  of the whole stall, against their old ones is a turn the robot did not make.  The replay
  chooses its rounds itself (:mod:`gateway.apps.replay.rounds`);
* every position newer than the last sample's is carried to the sample's time with its own
  wheel's speed (``position + velocity * (time - its time)``): the wheels of one round were
  measured up to a feedback period apart.  A wheel whose position is not newer, or older than
  ``silent_s``, is held (its speed is no longer known: a silent wheel, or a log whose clock
  stepped), and so is one whose speed is not finite;
* wheels without feedback (passive, or not reported yet) get ``None``.

**Position jumps.**  A wheel's position may move between two of its samples by at most
:data:`JUMP_SPEED_FACTOR` times the wheel's top speed (its motor's ``max_rpm`` at the wheel)
over the time between them plus :data:`JUMP_SLACK_S`.  A step beyond that is no motion the
wheel can have made: a controller that restarted its position count (a VESC's tachometer
starts again at 0 after a power cycle, an ODrive's estimate after a reboot, a CiA 402 drive's
after homing) or a corrupt value (a finite but absurd float from a firmware fault).  The feed
does not pass it on: from that sample on the wheel's position is offset so that it goes on
from where it was, the step is counted in :attr:`OdomFeed.jumps` and described by
:attr:`OdomFeed.last_jump` for the caller to report.  What the wheel really turned during
such a step is lost (at most one sample's motion, or the motion during the silence of a
restarting controller).  A restart after less travel than the bound is not recognised: the
odometry then takes the step as motion (at most the bound).  A position that is not finite
passes unchanged, and the step after it is not checked: the odometry names it and skips both
steps.

Every step is taken from the wheel's position at the previous sample: the feed tests all wheels
at once (the sum of the steps' sizes within the smallest wheel's :data:`JUMP_SLACK_S` of
motion, one pass in C), and wheel by wheel only when that fails.

Pure: no clock, no I/O.  What to integrate it with (the steering angles, a subset of the
wheels) is the caller's: :meth:`OdomFeed.sample` returns the sample, which the caller passes to
:meth:`gateway.core.kinematics.odometry.Odometry.update`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from operator import itemgetter, sub
from typing import TYPE_CHECKING, cast

if TYPE_CHECKING:
    from collections.abc import Sequence

    from gateway.core.types import WheelFeedback

__all__ = ["JUMP_SLACK_S", "JUMP_SPEED_FACTOR", "OdomFeed", "PositionJump", "jumps_warning"]

#: How many times its top speed a wheel may seem to turn before a step of its position is a
#: jump: a wheel can be back-driven beyond its motor's ``max_rpm`` (pushed, down a slope, a
#: limit set below what the motor can do), but not by this much for long.
JUMP_SPEED_FACTOR = 3.0
#: Time added to the interval between two positions of a wheel before the bound is taken
#: (s): receive times jitter (a bursty bus, a loaded host), and two positions received
#: together may have been measured a feedback period apart.
JUMP_SLACK_S = 0.1

#: A feedback's time (``WheelFeedback.timestamp_s``), in C.
_TIME = itemgetter(2)


@dataclass(frozen=True, slots=True)
class PositionJump:
    """A step of one wheel's position that the feed took for a jump, not motion.

    :param wheel: the wheel's index (model order).
    :param step_rad: the step (new position minus the one before), rad.
    :param elapsed_s: the time between the two positions, s.
    :param bound_rad: the largest step the wheel could have made in that time, rad.
    :param timestamp_s: the new position's time, s.
    """

    wheel: int
    step_rad: float
    elapsed_s: float
    bound_rad: float
    timestamp_s: float

    def describe(self, name: str) -> str:
        """What happened, for the log: ``name`` is the wheel's."""
        return (f"wheel {name!r}: its position stepped {self.step_rad:+.6g} rad in "
                f"{self.elapsed_s:.3f} s, more than it can turn ({self.bound_rad:.4g} rad: "
                f"{JUMP_SPEED_FACTOR:g} x its max_rpm at the wheel over the interval plus "
                f"{JUMP_SLACK_S:g} s): taken for a restart of its controller's position count "
                f"or a corrupt value, not for motion; the odometry goes on from where the "
                f"wheel was")


def jumps_warning(count: int, last: str) -> str:
    """A replay's warning for ``count`` jumps, the last described by ``last``."""
    return (f"{count:,} step{'' if count == 1 else 's'} of a wheel's position went beyond what "
            f"the wheel can turn and {'was' if count == 1 else 'were'} not taken for motion (a "
            f"controller that restarted its count, or a corrupt value); the last: {last}")


class OdomFeed:
    """The odometry's samples from the wheels' latest feedback (see the module docstring).

    :param driven: the model indices of the driven wheels, whose feedback a sample needs.
    :param max_wheel_rad_s: every wheel's top speed (rad/s, model order; ``inf`` for a wheel
        without a motor): the jump bound's.  Without it no step is a jump.
    :param silent_s: how much older than the newest a position is when its wheel counts as
        silent: held, not carried on by its speed, and not waited for (the gateway: the
        longest ``liveness_s``; the replay: its longest interval).
    :param whole_rounds: a sample only once every driven wheel has a new position or is
        silent (the gateway's loop; the replay chooses its rounds itself).
    """

    def __init__(self, driven: Sequence[int],
                 max_wheel_rad_s: Sequence[float] | None = None,
                 silent_s: float = math.inf, whole_rounds: bool = False) -> None:
        self.driven = tuple(driven)
        #: The newest feedback time seen by :meth:`sample` (s; ``-inf`` before any).
        self.stamp_s = -math.inf
        #: The time of the last sample :meth:`sample` returned (s; ``-inf`` before any).
        self.sampled_s = -math.inf
        #: When a wheel counts as silent (s; see the parameter).
        self.silent_s = silent_s
        #: Whether a sample waits for a whole round.
        self.whole_rounds = whole_rounds
        #: Steps taken for jumps so far (see the module docstring).
        self.jumps = 0
        #: The last of them, ``None`` before any.
        self.last_jump: PositionJump | None = None
        tops = () if max_wheel_rad_s is None else tuple(max_wheel_rad_s)
        self._rate = [JUMP_SPEED_FACTOR * w for w in tops]
        # The largest step of a wheel that is never a jump, whatever the interval; and the
        # smallest of them, for the test of every wheel at once (the fast path).
        self._free = [r * JUMP_SLACK_S for r in self._rate]
        self._calm = min(self._free, default=math.inf)
        # The previous call's feedback and raw positions: what each step is taken from.
        self._before: Sequence[WheelFeedback | None] = ()
        self._raw: list[float | None] | None = None
        # Per wheel, since its last jump: its raw position then, and the position passed on
        # for it (a difference, not an offset: exact whatever the raw values).  Empty until
        # the first jump.
        self._from_raw: list[float] = []
        self._from_out: list[float] = []
        # When every wheel's feedback came back after a silence of all of them longer than
        # silent_s (a stall; -inf: none yet): a round waits for every driven wheel again.
        self._resumed_s = -math.inf

    def last_jump_text(self, names: Sequence[str]) -> str:
        """:attr:`last_jump` described with its wheel's name (``names``: model order); empty
        without a jump."""
        j = self.last_jump
        return "" if j is None else j.describe(names[j.wheel])

    def sample(
        self, feedback: Sequence[WheelFeedback | None]
    ) -> tuple[float, list[float | None]] | None:
        """The sample due for this feedback, if any.

        :param feedback: every wheel's latest feedback, model order (``None``: none); a new
            sequence on every call (the feed keeps it to take the next steps from).
        :return: ``(time, positions)``: the newest feedback time and every wheel's position
            (rad, model order, ``None`` for wheels without feedback; a wheel that jumped, as
            it goes on from where it was), each new one carried to that time; ``None`` when no
            feedback is newer than the last sample's, a driven wheel has none, or (whole
            rounds) a driven wheel has no new position yet.
        """
        last = newest = self.stamp_s
        for fb in feedback:
            if fb is not None and fb.timestamp_s > newest:
                newest = fb.timestamp_s
        if newest <= last:
            return None
        self.stamp_s = newest
        if newest - last > self.silent_s:
            self._resumed_s = newest  # every wheel was silent (or none reported before): a
            # stall, see _round_over
        sampled = self.sampled_s
        if None in feedback:  # (else every wheel has reported: the oldest in C)
            for i in self.driven:
                if feedback[i] is None:
                    return None  # integrate once every driven wheel has reported
            oldest = min(cast("WheelFeedback", feedback[i]).timestamp_s for i in self.driven)
        else:
            oldest = min(map(_TIME, cast("Sequence[WheelFeedback]", feedback)))
        silent = self.silent_s
        if (oldest <= sampled and self.whole_rounds
                and not self._round_over(feedback, newest, sampled, silent)):
            return None  # a driven wheel has not sent a new position yet
        positions = self.positions(feedback)
        self.sampled_s = newest
        if oldest == newest:
            return newest, positions  # measured at one time (a cycle's stamp): as they are
        # Each new position carried to the sample's time with its wheel's speed.
        since = max(sampled, newest - silent)
        shifts = [0.0 if fb is None or fb.timestamp_s <= since
                  else fb.velocity_rad_s * (newest - fb.timestamp_s) for fb in feedback]
        if not math.isfinite(sum(shifts)):  # (a speed that is not finite: that wheel held)
            shifts = [x if math.isfinite(x) else 0.0 for x in shifts]
        return newest, [None if p is None else p + x
                        for p, x in zip(positions, shifts, strict=True)]

    def _round_over(self, feedback: Sequence[WheelFeedback | None], newest: float,
                    sampled: float, silent: float) -> bool:
        """Whether every driven wheel has a position newer than ``sampled`` or has sent none
        for ``silent`` up to ``newest`` (whole rounds) while others did: within ``silent`` of
        the end of a stall of every wheel, every one is waited for.  Otherwise the first wheel
        back would count the others as silent, and its new position, the motion of the whole
        stall, integrated against their old ones would be a turn the robot did not make,
        undone by the next sample, the translation between them going the wrong way."""
        stalled = newest - self._resumed_s < silent
        for i in self.driven:
            t = cast("WheelFeedback", feedback[i]).timestamp_s
            if sampled >= t and (stalled or t > newest - silent):
                return False
        return True

    def positions(self, feedback: Sequence[WheelFeedback | None]) -> list[float | None]:
        """Every wheel's position, jumps taken out (see the module docstring): what
        :meth:`sample` passes on, for a caller with a rule of its own for when to sample
        (``feedback`` as there)."""
        raw = [None if fb is None else fb.position_rad for fb in feedback]
        if not self._rate:
            return raw
        before, then = self._raw, self._before
        self._raw, self._before = raw, feedback
        # Every wheel at once, in C: the sum of the steps' sizes within the smallest wheel's
        # slack (NaN, inf, a wheel without a position: the wheel-by-wheel test).
        if before is not None and (None in raw or None in before or not sum(
                map(abs, map(sub, raw, before))) <= self._calm):
            self._check(feedback, then)
        if not self._from_raw:
            return raw
        return [None if p is None else o + (p - r)
                for p, o, r in zip(raw, self._from_out, self._from_raw, strict=True)]

    def _check(self, now: Sequence[WheelFeedback | None],
               then: Sequence[WheelFeedback | None]) -> None:
        """Each wheel's step from its feedback ``then`` to ``now``: a step beyond what the
        wheel turns in the slack and beyond its bound for the interval is a jump (the slow
        path)."""
        free = self._free
        for i, (fb, fb0) in enumerate(zip(now, then, strict=True)):
            if fb is None or fb0 is None:
                continue
            p, q = fb.position_rad, fb0.position_rad
            step = p - q
            if not (step > free[i] or step < -free[i]) or not math.isfinite(p + q):
                continue  # within the slack; or NaN, inf (passed on: the odometry names it)
            elapsed = fb.timestamp_s - fb0.timestamp_s
            bound = self._rate[i] * (elapsed + JUMP_SLACK_S)  # (elapsed <= 0: the slack's)
            if -bound <= step <= bound:
                continue
            if not self._from_raw:
                self._from_raw = [0.0] * len(now)
                self._from_out = [0.0] * len(now)
            self._from_out[i] += q - self._from_raw[i]
            self._from_raw[i] = p
            self.jumps += 1
            self.last_jump = PositionJump(i, step, elapsed, bound, fb.timestamp_s)
