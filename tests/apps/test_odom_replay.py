""":mod:`gateway.apps.replay.replay`: a candump log replayed through the drivers and the odometry
-- against the gateway and the ground truth, the update rule, and reconstructed steering.

The logs are recorded in the test by the gateway itself (``Gateway(record=...)``, as ``wheelgate
run --record`` does) driving simulated controllers on simulated time, so the replay can be held
against the gateway's own odometry of the same session and against the ground truth (the
simulators' exact wheel angles).
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import random
from typing import TYPE_CHECKING

import pytest
import yaml

from gateway.apps.replay import candump_report
from gateway.apps.replay.replay import Replay, SteeringSource, fixed_subset, reconstruct_steer
from gateway.cli.commands.odom import command
from gateway.config import load_config
from gateway.core.kinematics import RobotModel
from gateway.core.kinematics.odometry import se2_exp
from gateway.core.types import Twist
from gateway.wire.candump import parse_line
from tests.apps import odom_helpers
from tests.apps.odom_helpers import (
    DIFF,
    OBJ,
    Session,
    line,
    replay_file,
)
from tests.conftest import CONFIG_DIR
from tests.e2e_helpers import virtual_config

if TYPE_CHECKING:
    from collections.abc import Callable
    from pathlib import Path

    from click.testing import CliRunner


# The shared fixtures (odom_helpers.py), bound here so that pytest finds them.
sessions = odom_helpers.sessions
#: The first test that asks for a robot's session records it (seconds of simulated driving on
#: one core, several times that on a loaded machine): beyond the suite's 10 s hang guard.
pytestmark = pytest.mark.timeout(60)


def wrap(angle: float) -> float:
    return (angle + math.pi) % (2 * math.pi) - math.pi


def test_replay_matches_the_gateway_and_the_ground_truth(
    sessions: Callable[[str], Session],
) -> None:
    s = sessions("turtlebot3_burger")
    replay = replay_file(s.config, s.log)
    got = replay.summary()
    # The same encoder data through the same odometry, at the same cadence: the same pose.
    assert math.hypot(got.pose.x_m - s.gateway.pose.x_m,
                      got.pose.y_m - s.gateway.pose.y_m) < 1e-6
    assert abs(wrap(got.pose.theta_rad - s.gateway.pose.theta_rad)) < 1e-6
    # And the ground truth within 1 % of the distance.
    assert s.truth.distance_m > 3.0
    err = math.hypot(got.pose.x_m - s.truth.pose.x_m, got.pose.y_m - s.truth.pose.y_m)
    assert err <= 0.01 * s.truth.distance_m
    assert abs(got.distance_m - s.truth.distance_m) <= 0.01 * s.truth.distance_m
    with open(s.log, encoding="ascii") as f:
        lines = f.read().splitlines()
    assert got.entries == len(lines)
    assert got.entries - got.received == sum(line.endswith(" T") for line in lines) > 0
    assert got.corrupt_lines == 0
    assert got.steering is SteeringSource.NONE
    assert got.updates > 100
    assert got.start_s == 0.0
    assert got.duration_s == pytest.approx(s.truth.timestamp_s, abs=0.02)


@pytest.mark.parametrize(("name", "source"), [
    ("ackermann_external", SteeringSource.FIXED_WHEELS),
    ("ackermann", SteeringSource.ACTUATORS),
    ("tricycle_external", SteeringSource.GATEWAY_TWIST),
    ("tricycle", SteeringSource.ACTUATORS),
    ("swerve", SteeringSource.ACTUATORS),
])
def test_steered_robots_replay_within_one_percent(
    sessions: Callable[[str], Session], name: str, source: SteeringSource
) -> None:
    s = sessions(name)
    got = replay_file(s.config, s.log).summary()
    assert got.steering is source
    assert s.truth.distance_m > 2.0
    for want in (s.truth, s.gateway):
        err = math.hypot(got.pose.x_m - want.pose.x_m, got.pose.y_m - want.pose.y_m)
        assert err <= 0.01 * s.truth.distance_m, (name, got.pose, want.pose)
        assert abs(wrap(got.pose.theta_rad - want.pose.theta_rad)) <= 0.02
    assert abs(got.distance_m - s.truth.distance_m) <= 0.01 * s.truth.distance_m


def test_without_gateway_frames_steering_is_neutral_and_wrong(
    sessions: Callable[[str], Session], tmp_path: Path, runner: CliRunner
) -> None:
    # The documented limitation: a tricycle log without WG_Odom_Velocity frames has no
    # steering information; the turns of the steered wheel are missed and the summary says so.
    s = sessions("tricycle_external")
    stripped = tmp_path / "no_wg.log"
    with open(s.log, encoding="ascii") as f:
        stripped.write_text("".join(line for line in f if " 102#" not in line))
    got = replay_file(s.config, stripped).summary()
    assert got.steering is SteeringSource.NEUTRAL
    err = math.hypot(got.pose.x_m - s.truth.pose.x_m, got.pose.y_m - s.truth.pose.y_m)
    assert err > 0.2 * s.truth.distance_m
    doc = yaml.safe_load((CONFIG_DIR / "tricycle.yaml").read_text())
    external = tmp_path / "tricycle.yaml"
    external.write_text(yaml.safe_dump({k: v for k, v in doc.items() if k != "steering"}))
    result = runner.invoke(command, ["-c", str(external), str(stripped)], obj=OBJ)
    assert result.exit_code == 0, result.output
    assert "replayed at their neutral angles" in result.stderr
    assert "steering: neutral angles" in result.stdout
    # With the actuator configured but absent from the log, the summary names it.
    result = runner.invoke(command, ["-c", str(CONFIG_DIR / "tricycle.yaml"), str(stripped)],
                           obj=OBJ)
    assert result.exit_code == 0, result.output
    assert "steering: measured by the steering actuators" in result.stdout
    assert "warning: no feedback from front steering" in result.stderr


# ----------------------------------------------------------------- the update rule


def times(replay: Replay, lines: list[str]) -> list[float]:
    return [round(s.time_s, 6) for s in replay.feed_lines(lines)]


def test_updates_wait_until_every_wheel_has_a_new_sample() -> None:
    cfg = load_config(DIFF)
    log = [line(0.0, 1, 0.0), line(0.0005, 2, 0.0),   # both: the first update (baseline)
           line(0.001, 1, 0.1), line(0.002, 1, 0.2),  # left only: wait
           line(0.0025, 2, -0.2),                     # right too: update at 0.0025
           line(0.003, 1, 0.3)]                       # pending at the end: last update
    assert times(Replay(cfg, 0.0), log) == [0.0005, 0.0025, 0.003]


def test_rounds_stay_in_step_when_the_wheels_answer_one_after_the_other() -> None:
    # Driving straight: per round the left wheel answers, the right one 0.2 to 2 ms later,
    # rounds 4 to 40 ms apart (a loaded host), sometimes a round with the right wheel first.
    # An update as soon as both have a newer position takes the left of one round with the
    # right of the round before: out of step, and it stays so (a heading off by a period's
    # travel over the track, a path off to the side).
    cfg = load_config(DIFF)
    r, track = cfg.model.wheels[0].radius, 0.16
    speed = 12.0  # rad/s at the wheels
    rng = random.Random(7)
    rounds = list(itertools.accumulate(rng.uniform(0.004, 0.04) for _ in range(400)))
    log = []
    for k, t in enumerate(rounds):
        lag = rng.uniform(0.0002, 0.002)
        first, second = (1, 2) if k % 37 else (2, 1)
        turns = speed * t / (2 * math.pi)
        log += [line(t, first, turns * (1 if first == 1 else -1)),
                line(t + lag, second, turns * (1 if second == 1 else -1))]
    replay = Replay(cfg)
    headings = [s.pose.theta_rad for s in replay.feed_lines(log)]
    true_distance = speed * (rounds[-1] - rounds[0]) * r  # (positions count from the first)
    off = speed * 0.004 * r / track  # the heading of a round out of step, at least
    assert max(abs(h) for h in headings) < off / 10
    pose = replay.summary().pose
    assert pose.x_m == pytest.approx(true_distance, rel=1e-6)  # (float32 turns)
    assert abs(pose.y_m) < 1e-6
    assert replay.summary().distance_m == pytest.approx(true_distance, rel=1e-6)


def test_frames_with_one_time_stamp_make_one_update() -> None:
    cfg = load_config(DIFF)
    log = [line(k * 0.01, node, k * 0.1 * (1 if node == 1 else -1))
           for k in range(5) for node in (1, 2)]
    assert times(Replay(cfg, 0.0), log) == [0.0, 0.01, 0.02, 0.03, 0.04]


def test_a_cycle_of_one_stamp_is_a_round_at_once() -> None:
    # A --record log stamps a cycle's frames alike: nothing closer in time can follow, so its
    # update comes at the start of the next cycle, not one later (the replay's pose where the
    # gateway's own pose frames stand would lag a cycle behind them).
    cfg = load_config(DIFF)
    replay = Replay(cfg, 0.0)
    got = []
    for n, text in enumerate(line(k * 0.01, node, k * 0.1 * (1 if node == 1 else -1))
                             for k in range(5) for node in (1, 2)):
        sample = replay.feed(parse_line(text, n + 1))
        got.append(None if sample is None else round(sample.time_s, 6))
    assert got == [None, None, 0.0, None, 0.01, None, 0.02, None, 0.03, None]


def test_least_interval_throttles_updates_without_losing_motion() -> None:
    cfg = load_config(DIFF)
    r = cfg.model.wheels[0].radius
    log = [line(k * 0.001 + 0.0002 * (node - 1), node,
                0.02 * k * (1 if node == 1 else -1)) for k in range(101) for node in (1, 2)]
    every = Replay(cfg, 0.0)
    assert len(times(every, log)) == 101
    sparse = Replay(cfg, 0.01)
    assert len(times(sparse, log)) == 11
    for replay in (every, sparse):
        pose = replay.summary().pose
        assert pose.x_m == pytest.approx(2 * math.pi * 2.0 * r, rel=1e-6)
        assert abs(pose.y_m) < 1e-9
        assert abs(pose.theta_rad) < 1e-9


def test_arc_is_exact_whatever_the_rate() -> None:
    cfg = load_config(DIFF)
    model = cfg.model
    twist = Twist(0.2, 0.0, 1.0)
    speeds = model.ik(twist).wheel_rad_s
    log = [line(k * 0.001, node, speeds[node - 1] * k * 0.001 / (2 * math.pi)
                * (1 if node == 1 else -1)) for k in range(2001) for node in (1, 2)]
    want = se2_exp(0.2 * 2.0, 0.0, 1.0 * 2.0)
    for interval in (0.0, 0.05):
        replay = Replay(cfg, interval)
        assert times(replay, log)[-1] == 2.0
        pose = replay.summary().pose
        assert pose.x_m == pytest.approx(want.x_m, abs=1e-5)
        assert pose.y_m == pytest.approx(want.y_m, abs=1e-5)
        assert pose.theta_rad == pytest.approx(want.theta_rad, abs=1e-5)


def test_a_wheel_never_heard_from_is_named() -> None:
    cfg = load_config(DIFF)
    replay = Replay(cfg, 0.0)
    assert times(replay, [line(k * 0.01, 1, k * 0.1) for k in range(20)]) == []
    s = replay.summary()
    assert s.updates == 0
    assert s.silent_wheels == ("right",)
    assert s.motor_frames == 20


def test_other_frames_and_own_commands_change_nothing() -> None:
    cfg = load_config(DIFF)
    clean = [line(k * 0.01, node, k * 0.05) for k in range(10) for node in (1, 2)]
    noisy: list[str] = []
    for text in clean:
        stamp = text[:text.index(")") + 1]
        noisy += [text, f"{stamp} can0 7FF#DEADBEEF R\n",
                  f"{stamp} can0 02D#0000204100000000 T\n"]  # Set_Input_Vel of node 1
    a, b = Replay(cfg, 0.0), Replay(cfg, 0.0)
    assert times(a, clean) == times(b, noisy)
    assert a.summary().pose == b.summary().pose
    assert b.summary().entries == 3 * len(clean)
    assert b.summary().received == 2 * len(clean)


def test_bad_intervals_are_refused() -> None:
    cfg = load_config(DIFF)
    with pytest.raises(ValueError, match="min_interval_s >= 0 s"):
        Replay(cfg, -1.0)
    with pytest.raises(ValueError, match="max_interval_s"):
        Replay(cfg, 0.0, max_interval_s=math.inf)
    assert Replay(cfg).min_interval_s == pytest.approx(1.0 / cfg.loop.rate_hz)


# ----------------------------------------------------------------- steering


def test_fixed_subset_finds_wheels_that_fix_the_twist() -> None:
    ack = load_config(CONFIG_DIR / "ackermann.yaml")
    got = fixed_subset(ack)
    assert got is not None
    assert [ack.model.names[i] for i in got[0]] == ["rear_left", "rear_right"]
    castor = load_config(CONFIG_DIR / "differential_castor.yaml")
    assert fixed_subset(castor) is not None
    for name in ("tricycle", "swerve", "synchro", "turtlebot3_burger"):
        assert fixed_subset(load_config(CONFIG_DIR / f"{name}.yaml")) is None, name


def test_reconstructed_steering_follows_the_measured_wheel_direction() -> None:
    model = load_config(CONFIG_DIR / "swerve.yaml").model
    n = model.n
    ahead = Twist(0.5, 0.0, 0.0)
    # Forward motion: angle 0 with the wheel turning forward, or pi with it turning back.
    assert reconstruct_steer(model, ahead, [0.0] * n, [10.0] * n) == (0.0,) * n
    back = reconstruct_steer(model, ahead, [0.0] * n, [-10.0] * n)
    assert all(abs(abs(a or 0.0) - math.pi) < 1e-9 for a in back)
    # Without a measured direction: the angle nearest the previous one.
    assert reconstruct_steer(model, ahead, [3.0] * n, [None] * n) == back
    # Standing still: angles kept.
    assert reconstruct_steer(model, Twist(), [0.3] * n, [0.0] * n) == (0.3,) * n
    # Turning in place: every wheel tangent to its circle.
    spin = reconstruct_steer(model, Twist(0.0, 0.0, 1.0), [0.0] * n, [None] * n)
    for w, a in zip(model.wheels, spin, strict=True):
        direction = w.heading(a or 0.0)
        assert abs(math.cos(direction) * w.x + math.sin(direction) * w.y) < 1e-9


def test_reconstructed_steering_respects_limits() -> None:
    model = load_config(CONFIG_DIR / "ackermann.yaml").model
    prev = model.neutral_steer
    # Sideways motion needs 90 degrees, beyond max_steer: the angles stay.
    assert reconstruct_steer(model, Twist(0.0, 0.5, 0.0), prev, [None] * model.n) == prev


def test_the_replay_is_judged_by_the_gateways_own_pose_frames(
    sessions: Callable[[str], Session],
) -> None:
    # A --record log holds the gateway's WG_Odom_Pose frames: the replay of the same encoder
    # frames agrees with them to the frames' millimetre and an update's lag, and a replay with
    # a wrong wheel radius (5 % too big) is told apart by as much.
    s = sessions("turtlebot3_burger")
    check = replay_file(s.config, s.log).summary().pose_check
    assert check is not None
    assert check.frames > 50
    assert check.position_error_m < 0.005 and abs(check.heading_error_rad) < 0.005, check
    assert check.max_position_error_m < 0.01 and check.max_heading_error_rad < 0.01, check
    wheels = tuple(dataclasses.replace(w, radius=w.radius * 1.05) for w in s.config.model.wheels)
    wrong = dataclasses.replace(s.config, model=RobotModel(wheels))
    bad = replay_file(wrong, s.log).summary().pose_check
    assert bad is not None
    # A square of 1 m sides: 5 % too far on a side is 5 cm off on the way.
    assert bad.max_position_error_m > 0.04, bad
    assert bad.gateway == check.gateway  # the log's frames are the log's


def test_a_log_without_pose_frames_has_no_check() -> None:
    cfg = virtual_config(CONFIG_DIR / "turtlebot3_burger.yaml", "wg-odom-nopose")
    replay = Replay(cfg)
    for _ in replay.feed_lines([line(0.0, 1, 0.0), line(0.0, 2, 0.0), line(0.1, 1, 1.0),
                                line(0.1, 2, 1.0)]):
        pass
    assert replay.summary().pose_check is None


def test_a_count_that_restarts_or_a_corrupt_value_is_no_motion_of_the_replay() -> None:
    """Driving straight at 5 rad/s, rounds 10 ms apart: the left ODrive's count restarts at 0
    after 1 s (a reboot), the right one sends 1e30 turns once.  The replay goes on from where
    each wheel was: three jumps, the distance short by at most three rounds' travel."""
    cfg = load_config(DIFF)
    r = cfg.model.wheels[0].radius
    speed, period = 5.0, 0.01
    log = []
    for k in range(300):
        t = k * period
        turns = speed * t / (2 * math.pi)
        left = turns if k < 100 else speed * (t - 1.0) / (2 * math.pi)
        right = 1e30 if k == 150 else turns
        log += [line(t, 1, left), line(t + 0.0005, 2, -right)]
    replay = Replay(cfg)
    for _ in replay.feed_lines(log):
        pass
    s = replay.summary()
    assert s.position_jumps == 3
    true_distance = speed * 299 * period * r
    assert true_distance - 3 * speed * period * r < s.distance_m < true_distance
    assert s.pose.x_m == pytest.approx(s.distance_m, rel=1e-3)
    assert s.last_jump.startswith("wheel 'right': its position stepped ")
    text = candump_report.warnings(cfg, s)
    assert ("3 steps of a wheel's position went beyond what the wheel can turn and were not "
            "taken for motion (a controller that restarted its count, or a corrupt value); "
            f"the last: {s.last_jump}") in text
