"""The odometry's samples from wheel feedback (:class:`gateway.core.odom_feed.OdomFeed`): the
rule the gateway's loop and the log replay both used to write out for themselves."""

from __future__ import annotations

import math
import random

import pytest

from gateway.core.odom_feed import JUMP_SLACK_S, JUMP_SPEED_FACTOR, OdomFeed, PositionJump
from gateway.core.types import WheelFeedback as Fb


def loop_rule(stamp: float, feedback: list[Fb | None], driven: tuple[int, ...]
              ) -> tuple[float, tuple[float, list[float | None]] | None]:
    """The loop's own rule before the feed (``Gateway._integrate``), the feed's without whole
    rounds: (new stamp, sample)."""
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
    """Over random feedback at rest (speeds 0: nothing to carry to the sample's time), the
    feed without whole rounds gives the loop's samples of before them; and, called once every
    driven wheel has reported (as the replay does), the replay's."""
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


# ----------------------------------------------------------------- one time for every wheel

def test_new_positions_are_carried_to_the_samples_time_with_their_speeds() -> None:
    """Each wheel's position newer than the last sample's moves on by its speed to the newest
    time; one no newer (a silent wheel) is held, and so is one whose speed is not finite."""
    feed = OdomFeed((0, 1, 2))
    assert feed.sample([Fb(1.0, 2.0, 0.5), Fb(3.0, -4.0, 0.25), Fb(5.0, 8.0, 0.5)]) == (
        0.5, [1.0, 3.0 - 4.0 * 0.25, 5.0])
    assert feed.sampled_s == 0.5
    # Wheel 1 not newer than the sample at 0.5: held (where it was measured).
    assert feed.sample([Fb(2.0, 2.0, 0.75), Fb(3.0, -4.0, 0.25), Fb(7.0, 8.0, 1.0)]) == (
        1.0, [2.0 + 2.0 * 0.25, 3.0, 7.0])
    for bad in (math.nan, math.inf):
        got = feed.sample([Fb(4.0, bad, 1.25), Fb(1.0, -4.0, 1.5), Fb(9.0, 8.0, 1.75)])
        assert got == (1.75, [4.0, 1.0 - 4.0 * 0.25, 9.0])
        feed = OdomFeed((0, 1, 2))
        feed.sample([Fb(0.0, 0.0, 1.0)] * 3)
    # Measured at one time (a cycle's stamp): as they are, whatever the speeds.
    assert feed.sample([Fb(1.0, 9.0, 2.0), Fb(2.0, 9.0, 2.0), Fb(3.0, math.nan, 2.0)]) == (
        2.0, [1.0, 2.0, 3.0])


def test_a_position_older_than_silent_s_is_held() -> None:
    """A new position more than ``silent_s`` older than the newest is not carried: its wheel
    fell silent, or the log's clock stepped between them (an hour at 2 rad/s is not motion)."""
    feed = OdomFeed((0, 1), silent_s=0.1)
    feed.sample([Fb(0.0, 2.0, 0.0), Fb(0.0, 2.0, 0.0)])
    assert feed.sample([Fb(1.0, 2.0, 0.15), Fb(1.0, 2.0, 3600.2)]) == (3600.2, [1.0, 1.0])
    assert feed.sample([Fb(1.0, 2.0, 3600.21), Fb(2.0, 2.0, 3600.25)]) == (
        3600.25, [pytest.approx(1.08), 2.0])


def test_whole_rounds_wait_for_every_driven_wheel() -> None:
    """With whole rounds a sample waits until every driven wheel has a newer position than
    the last sample's: controllers at their own phases, one sample per round, at the newest
    time, every wheel carried there."""
    feed = OdomFeed((0, 2), silent_s=0.25, whole_rounds=True)
    assert feed.sample([Fb(0.0, 1.0, 0.000), None, Fb(0.0, 1.0, 0.005)]) == (
        0.005, [0.005, None, 0.0])
    # Wheel 0's next position (at its 10 ms phase), wheel 2's not yet: no sample.
    assert feed.sample([Fb(0.01, 1.0, 0.010), None, Fb(0.0, 1.0, 0.005)]) is None
    assert (feed.stamp_s, feed.sampled_s) == (0.010, 0.005)
    got = feed.sample([Fb(0.01, 1.0, 0.010), None, Fb(0.01, 1.0, 0.015)])
    assert got is not None and got[0] == 0.015
    assert got[1] == pytest.approx([0.015, None, 0.01], abs=1e-15)
    # Without whole rounds, the same wheel's position alone is a sample.
    plain = OdomFeed((0, 2))
    plain.sample([Fb(0.0, 1.0, 0.000), None, Fb(0.0, 1.0, 0.005)])
    assert plain.sample([Fb(0.01, 1.0, 0.010), None, Fb(0.0, 1.0, 0.005)]) == (
        0.010, [0.01, None, 0.0])


def test_a_silent_wheel_holds_whole_rounds_back_for_the_wait_only() -> None:
    feed = OdomFeed((0, 1), silent_s=0.25, whole_rounds=True)
    feed.sample([Fb(0.0, 1.0, 0.0), Fb(0.0, 1.0, 0.0)])
    for k in range(1, 25):  # wheel 1 silent from 0.0 on
        assert feed.sample([Fb(0.01 * k, 1.0, 0.01 * k), Fb(0.0, 1.0, 0.0)]) is None
    # 0.25 s after wheel 1's last position: on without it (held, not carried on by its speed).
    assert feed.sample([Fb(0.25, 1.0, 0.25), Fb(0.0, 1.0, 0.0)]) == (0.25, [0.25, 0.0])
    assert feed.sample([Fb(0.26, 1.0, 0.26), Fb(0.0, 1.0, 0.0)]) == (0.26, [0.26, 0.0])
    # Back: the next round needs it again.
    assert feed.sample([Fb(0.27, 1.0, 0.27), Fb(0.3, 1.0, 0.265)]) == (
        0.27, [0.27, pytest.approx(0.305)])
    assert feed.sample([Fb(0.28, 1.0, 0.28), Fb(0.3, 1.0, 0.265)]) is None


def test_after_a_stall_of_every_wheel_whole_rounds_wait_for_every_one() -> None:
    """Both wheels silent for 0.5 s (a bus unplugged while the robot rolls on), then wheel 0
    comes back first: not a round yet, though wheel 1's last position is older than
    ``silent_s``; a round once wheel 1 is back, or ``silent_s`` after the stall without it."""
    feed = OdomFeed((0, 1), silent_s=0.25, whole_rounds=True)
    for k in range(3):
        assert feed.sample([Fb(0.1 * k, 1.0, 0.01 * k), Fb(0.1 * k, 1.0, 0.01 * k)]) is not None
    assert feed.sample([Fb(0.6, 1.0, 0.52), Fb(0.02, 1.0, 0.02)]) is None
    assert feed.sample([Fb(0.61, 1.0, 0.53), Fb(0.62, 1.0, 0.525)]) == (
        0.53, [0.61, pytest.approx(0.625)])
    # Another stall, after which wheel 1 does not come back: on without it (held where it
    # was) silent_s after the stall's end.
    for t in (1.2, 1.3, 1.44):
        assert feed.sample([Fb(t, 1.0, t), Fb(0.62, 1.0, 0.525)]) is None
    assert feed.sample([Fb(1.45, 1.0, 1.45), Fb(0.62, 1.0, 0.525)]) == (1.45, [1.45, 0.62])


# ----------------------------------------------------------------- position jumps

#: Top speeds of three wheels (rad/s): the jump bound is JUMP_SPEED_FACTOR times these.
TOP = (10.0, 10.0, math.inf)


def test_a_step_beyond_what_the_wheel_can_turn_is_a_jump() -> None:
    rate = JUMP_SPEED_FACTOR * TOP[0]
    bound = rate * (0.01 + JUMP_SLACK_S)
    for step, jump in ((0.999 * bound, False), (-0.999 * bound, False),
                       (1.001 * bound, True), (-1.001 * bound, True)):
        feed = OdomFeed((0, 1), TOP)
        assert feed.sample([Fb(1.0, 0.0, 0.0), Fb(2.0, 0.0, 0.0), None]) == (
            0.0, [1.0, 2.0, None])
        got = feed.sample([Fb(1.0 + step, 0.0, 0.01), Fb(2.5, 0.0, 0.01), None])
        assert got == (0.01, [1.0 if jump else 1.0 + step, 2.5, None])
        assert feed.jumps == jump
        if jump:
            assert feed.last_jump == PositionJump(0, step, 0.01, rate * (0.01 + JUMP_SLACK_S),
                                                  0.01)
        # A wheel without a top speed never jumps.
        assert feed.sample([Fb(1.0 + step, 0.0, 0.02), Fb(2.5, 0.0, 0.01),
                            Fb(1e300, 0.0, 0.02)]) == (0.02, [1.0 if jump else 1.0 + step,
                                                              2.5, 1e300])
        assert feed.jumps == jump


def test_the_bound_grows_with_the_time_between_two_positions() -> None:
    """A wheel silent for 2 s may have turned 2.1 s at three times its top speed."""
    feed = OdomFeed((0,), TOP[:1])
    feed.sample([Fb(0.0, 0.0, 0.0)])
    assert feed.sample([Fb(60.0, 0.0, 2.0)]) == (2.0, [60.0])  # bound 63
    assert feed.jumps == 0
    assert feed.sample([Fb(124.0, 0.0, 4.0)]) == (4.0, [60.0])  # 64 in 2 s: a jump
    assert feed.jumps == 1
    assert feed.sample([Fb(126.0, 0.0, 4.1)]) == (4.1, [62.0])  # 2 < 30 * 0.2: motion


def test_a_corrupt_value_and_back_leave_the_position_where_it_was() -> None:
    """1e30 then true values again: neither step is motion; the positions after it go on
    from where the wheel was, exactly, and move as the wheel does."""
    feed = OdomFeed((0, 1), TOP[:2])
    out = []
    for k, p in enumerate((5.0, 5.01, 1e30, 1e30, 5.04, 5.05, 4.0e30, 5.07)):
        got = feed.sample([Fb(p, 0.0, 0.01 * k), Fb(-3.0, 0.0, 0.01 * k)])
        assert got is not None
        out.append(got[1][0])
    assert out == [5.0, 5.01, 5.01, 5.01, 5.01, 5.01 + (5.05 - 5.04), 5.01 + (5.05 - 5.04),
                   5.01 + (5.05 - 5.04)]
    assert feed.jumps == 4
    last = feed.last_jump
    assert last is not None and (last.wheel, last.step_rad) == (0, 5.07 - 4.0e30)


def test_a_count_that_restarts_at_zero_goes_on_from_where_it_was() -> None:
    feed = OdomFeed((0,), TOP[:1])
    feed.sample([Fb(5000.0, 0.0, 0.0)])
    feed.sample([Fb(5001.0, 0.0, 0.1)])
    assert feed.sample([Fb(0.0, 0.0, 0.6)]) == (0.6, [5001.0])  # the controller restarted
    assert feed.sample([Fb(2.0, 0.0, 0.7)]) == (0.7, [5003.0])  # and the wheel turns on
    assert feed.jumps == 1


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_a_position_that_is_not_finite_passes_for_the_odometry_to_name(bad: float) -> None:
    feed = OdomFeed((0,), TOP[:1])
    feed.sample([Fb(1.0, 0.0, 0.0)])
    got = feed.sample([Fb(bad, 0.0, 0.01)])
    assert got is not None
    p = got[1][0]
    assert p is not None and (p == bad or (math.isnan(bad) and math.isnan(p)))
    # The step after it is not checked (the odometry skips it too): no jump, no poison.
    assert feed.sample([Fb(1.2, 0.0, 0.02)]) == (0.02, [1.2])
    assert feed.jumps == 0


def test_steps_inside_the_bound_pass_bit_for_bit() -> None:
    """Over random feedback (as above) whose steps stay inside the bound, the feed with top
    speeds gives the very samples of the feed without: steps beyond what the wheel turns in
    the slack (the slow path) included."""
    rng = random.Random(7)
    for _ in range(100):
        n = rng.randrange(1, 5)
        driven = tuple(range(n))
        plain, bounded = OdomFeed(driven), OdomFeed(driven, [rng.uniform(60.0, 100.0)] * n)
        feedback: list[Fb | None] = [None] * n
        t = 0.0
        for _ in range(60):
            dt = rng.choice((0.001, 0.01, 1.0))
            t += dt
            for i in range(n):
                if rng.random() < 0.5:
                    # Steps of at most 9 rad (two before a sample stay inside the 18 rad
                    # of the slack at 180 rad/s), or 98 rad after 1 s (the bound is then
                    # 198 rad: the slow path).
                    before = feedback[i]
                    p = rng.uniform(-5, 5) if before is None else (
                        before.position_rad + rng.uniform(-1, 1) * (9.0 + 89.0 * (dt == 1.0)))
                    feedback[i] = Fb(p, 0.0, t)
            assert bounded.sample(list(feedback)) == plain.sample(list(feedback))
        assert bounded.jumps == 0
