"""The replay's rounds (:mod:`gateway.apps.replay.rounds`) when positions do not come in step: a
wheel that falls silent is waited for at most the longest interval, and a stall of every
controller (a stalled bus or sender, a ``candump`` starved of CPU) silences no wheel."""

from __future__ import annotations

import itertools
import math

import pytest

from gateway.apps.replay.replay import Replay
from gateway.config import load_config
from tests.apps.odom_helpers import DIFF, line


def times(replay: Replay, lines: list[str]) -> list[float]:
    return [round(s.time_s, 6) for s in replay.feed_lines(lines)]


def test_a_wheel_that_falls_silent_delays_updates_by_the_longest_interval() -> None:
    cfg = load_config(DIFF)
    log = [line(0.0, 1, 0.0), line(0.0, 2, 0.0)]
    log += [line(k * 0.01, 1, k * 0.01) for k in range(1, 51)]   # right falls silent
    got = times(Replay(cfg, 0.0, max_interval_s=0.1), log)
    # Counted from the first new position after the last round (0.01, 0.12, ...).
    assert got == [0.0, 0.11, 0.22, 0.33, 0.44, 0.5]


def _straight(t: float, node: int) -> str:
    """Node ``node``'s position at ``t`` of a turtlebot driving straight at 1 turn/s."""
    return line(t, node, t if node == 1 else -t)


@pytest.mark.parametrize("before", ["", "left", "right"])
def test_a_stall_of_every_sender_makes_no_wheel_silent(before: str) -> None:
    """Both wheels every 10 ms, then nothing for 0.3 s (a stalled bus or sender, a starved
    candump) while the robot drives on; the first wheel back does not count the other as
    silent, without or with a new position of one wheel (``before``) just before the stall:
    the right's (the left's new one makes the round whole) or the left's own (a round needs
    the right's, and the wait for it counts from the end of the stall).  Integrated against
    the other's old position, the first wheel's new one would be a turn the robot did not
    make (CI: 0.9 m off over a 4 m square recorded in an emulated VM)."""
    cfg = load_config(DIFF)
    log = [_straight(k * 0.01 + 0.0005 * (node - 1), node)
           for k in range(51) for node in (1, 2)]
    # (... and after the stall the left wheel comes back first, as before it)
    if before == "right":
        log.append(_straight(0.5105, 2))
    elif before == "left":  # twice: the wait for the right wheel has begun before the stall
        log += [_straight(0.51, 1), _straight(0.52, 1)]
    log += [_straight(k * 0.01 + 0.0005 * (node - 1), node)
            for k in range(80, 101) for node in (1, 2)]
    replay = Replay(cfg, 0.0, max_interval_s=0.1)
    samples = list(replay.feed_lines(log))
    assert len(samples) > 40
    assert max(abs(s.pose.theta_rad) for s in samples) < 1e-6  # (a false turn: 0.4 rad)
    pose = replay.summary().pose
    r = cfg.model.wheels[0].radius
    assert pose.x_m == pytest.approx(2 * math.pi * r, rel=1e-3)
    assert abs(pose.y_m) < 1e-6


def test_a_whole_round_is_never_a_silent_wheel() -> None:
    """The right wheel reports once more, then the left's next position comes the longest
    interval later (no stall: not that much longer than the usual time between frames); it
    makes the round whole, which is taken as such, not as a left wheel fallen silent."""
    cfg = load_config(DIFF)
    log = [_straight(0.03 * k + 0.015 * (node - 1), node) for k in range(17) for node in (1, 2)]
    log += [_straight(0.5, 2), _straight(0.6, 1), _straight(0.615, 2)]
    log += [_straight(0.03 * k + 0.015 * (node - 1), node) for k in range(21, 34)
            for node in (1, 2)]
    samples = list(Replay(cfg, 0.0, max_interval_s=0.1).feed_lines(log))
    assert len(samples) > 25
    assert max(abs(s.pose.theta_rad) for s in samples) < 1e-6  # (a false turn: 0.15 rad)

def test_a_silent_wheel_is_found_among_slow_controllers() -> None:
    """The left wheel reports at 5 Hz, the right falls silent: every gap between frames is
    longer than the longest interval, but it is the usual one, no stall, so the right wheel
    is found silent and the odometry goes on (it would wait for the end of the log if every
    such gap ended a stall)."""
    cfg = load_config(DIFF)
    log = [line(0.0, 1, 0.0), line(0.0, 2, 0.0)]
    log += [line(k * 0.2, 1, k * 0.2) for k in range(1, 21)]
    got = times(Replay(cfg, 0.0, max_interval_s=0.1), log)
    assert len(got) > 5 and got[-1] == 4.0
    assert all(b - a <= 0.4 + 1e-9 for a, b in itertools.pairwise(got[1:]))
