"""The odometry's samples from wheel feedback (:class:`gateway.core.odom_feed.OdomFeed`): the
rule the gateway's loop and the log replay both used to write out for themselves."""

from __future__ import annotations

import math
import random

from gateway.core.odom_feed import OdomFeed
from gateway.core.types import WheelFeedback as Fb


def loop_rule(stamp: float, feedback: list[Fb | None], driven: tuple[int, ...]
              ) -> tuple[float, tuple[float, list[float | None]] | None]:
    """The loop's own rule before the feed (``Gateway._integrate``): (new stamp, sample)."""
    newest = stamp
    for fb in feedback:
        if fb is not None and fb.timestamp_s > newest:
            newest = fb.timestamp_s
    if newest <= stamp:
        return stamp, None
    positions = [None if fb is None else fb.position_rad for fb in feedback]
    if any(positions[i] is None for i in driven):
        return newest, None
    return newest, (newest, positions)


def replay_rule(stamp: float, feedback: list[Fb | None], driven: tuple[int, ...]
                ) -> tuple[float, tuple[float, list[float | None]] | None]:
    """The replay's rule before the feed (``Replay._update``, past its own timing)."""
    if any(feedback[i] is None for i in driven):
        return stamp, None
    newest = max(fb.timestamp_s for fb in feedback if fb is not None)
    if newest <= stamp:
        return stamp, None
    return newest, (newest, [None if fb is None else fb.position_rad for fb in feedback])


def test_a_sample_needs_newer_feedback_and_every_driven_wheel() -> None:
    feed = OdomFeed((0, 2))
    assert feed.sample([None, None, None]) is None
    assert feed.stamp_s == -math.inf
    # Wheel 2 has not reported: no sample, but the time moves on.
    assert feed.sample([Fb(1.0, 0.0, 0.5), None, None]) is None
    assert feed.stamp_s == 0.5
    got = feed.sample([Fb(1.0, 0.0, 0.5), None, Fb(2.0, 0.0, 0.6)])
    assert got == (0.6, [1.0, None, 2.0])  # a passive wheel's position is None
    assert feed.sample([Fb(1.0, 0.0, 0.5), None, Fb(2.0, 0.0, 0.6)]) is None  # nothing newer
    assert feed.sample([Fb(1.5, 0.0, 0.55), None, Fb(2.0, 0.0, 0.6)]) is None  # older
    assert feed.sample([Fb(1.5, 0.0, 0.7), None, Fb(2.0, 0.0, 0.6)]) == (0.7, [1.5, None, 2.0])


def test_the_feed_is_the_loops_rule_and_the_replays() -> None:
    """Over random feedback, the feed gives the loop's samples; and, called once every driven
    wheel has reported (as the replay does), the replay's."""
    rng = random.Random(5)
    for _ in range(200):
        n = rng.randrange(1, 5)
        driven = tuple(i for i in range(n) if rng.random() < 0.7) or (0,)
        feedback: list[Fb | None] = [None] * n
        feed, loop_stamp = OdomFeed(driven), -math.inf
        replay_feed, replay_stamp = OdomFeed(driven), -math.inf
        t = 0.0
        for _ in range(60):
            t += rng.choice((0.0, 0.001, 0.01))
            for i in range(n):
                if rng.random() < 0.3:
                    # Mostly in order; now and then a late (older) sample.
                    stamp = t - rng.choice((0.0, 0.0, 0.0, 0.02))
                    feedback[i] = Fb(rng.uniform(-5, 5), 0.0, stamp)
            loop_stamp, expected = loop_rule(loop_stamp, feedback, driven)
            assert feed.sample(list(feedback)) == expected
            assert feed.stamp_s == loop_stamp
            if all(feedback[i] is not None for i in driven):
                replay_stamp, expected = replay_rule(replay_stamp, feedback, driven)
                assert replay_feed.sample(list(feedback)) == expected
                assert replay_feed.stamp_s == replay_stamp
