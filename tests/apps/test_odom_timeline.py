""":mod:`gateway.apps.replay.timeline` in a replay and in ``wheelgate odom``: a line whose time
stamp is out of time with the lines around it is skipped and reported like an unreadable line,
a jump of the log's time that the log goes on from (a break) is bridged, and neither stops the
odometry.

The logs are built in the test: a recorded session (:mod:`tests.apps.odom_helpers`) with one
line's time stamp changed, and short logs of ODrive encoder frames.
"""

from __future__ import annotations

import json
import math
from typing import TYPE_CHECKING

import pytest

from gateway.apps.replay.candump_report import MAX_REPORTED
from gateway.apps.replay.replay import Replay
from gateway.apps.replay.timeline import MAX_GAP_S, StampError, Timeline
from gateway.cli.commands.odom import command
from gateway.config import load_config
from tests.apps import odom_helpers
from tests.apps.odom_helpers import DIFF, OBJ, Session, line, replay_file

if TYPE_CHECKING:
    from collections.abc import Callable
    from pathlib import Path

    from click.testing import CliRunner

sessions = odom_helpers.sessions
#: The first test that asks for a robot's session records it (seconds of simulated driving on
#: one core, several times that on a loaded machine): beyond the suite's 10 s hang guard.
pytestmark = pytest.mark.timeout(60)


def restamp(text: str, t: float) -> str:
    """A log line with another time stamp."""
    return f"({t:.6f})" + text[text.index(")") + 1:]


def stamp(text: str) -> float:
    return float(text[1:text.index(")")])


def encoder_line(lines: list[str], after: int) -> int:
    """The index of the first Get_Encoder_Estimates of node 1 received at or after ``after``."""
    return next(i for i in range(after, len(lines)) if " 029#" in lines[i]
                and lines[i].rstrip().endswith(" R"))


def with_stamp(session: Session, folder: Path, name: str,
               change: Callable[[list[str]], list[str]]) -> Path:
    lines = session.log.read_text(encoding="ascii").splitlines(keepends=True)
    path = folder / name
    path.write_text("".join(change(lines)), encoding="ascii")
    return path


def close(a: Replay, b: Replay, metres: float) -> None:
    pa, pb = a.summary().pose, b.summary().pose
    assert math.hypot(pa.x_m - pb.x_m, pa.y_m - pb.y_m) <= metres, (pa, pb)
    assert abs(pa.theta_rad - pb.theta_rad) <= metres


# ----------------------------------------------------------------- a recorded session


@pytest.mark.parametrize("shift", [3600.0, -5.0])
def test_one_line_out_of_time_is_skipped_and_the_replay_goes_on(
    sessions: Callable[[str], Session], tmp_path: Path, shift: float,
) -> None:
    # The reviewer's log: one encoder frame an hour ahead (or 5 s behind) in a recorded
    # session.  Without the check every later interval was negative: 185 updates of 429 and a
    # path cut short, blamed on the configuration.
    s = sessions("turtlebot3_burger")
    clean = replay_file(s.config, s.log)
    original = s.log.read_text(encoding="ascii").splitlines()
    k = encoder_line(original, 1000)

    def change(lines: list[str]) -> list[str]:
        lines[k] = restamp(lines[k], stamp(lines[k]) + shift)
        return lines

    log = with_stamp(s, tmp_path, "jump.log", change)
    got = replay_file(s.config, log)
    summary = got.summary()
    assert summary.out_of_time_lines == 1 and summary.breaks == 0
    assert summary.corrupt_lines == 0
    (bad,) = got.timeline.bad
    assert bad.line_number == k + 1
    assert bad.time_s == pytest.approx(stamp(original[k]) + shift)
    assert bad.previous_s == stamp(original[k - 1])
    assert summary.entries == clean.summary().entries - 1
    # One encoder sample fewer: the same updates within one, the same pose (positions are
    # absolute), and the gateway's own pose frames agree as they do with the clean log.
    assert abs(summary.updates - clean.summary().updates) <= 1
    assert summary.duration_s == clean.summary().duration_s
    close(got, clean, 1e-4)
    assert summary.pose_check is not None
    assert summary.pose_check.max_position_error_m < 0.01


@pytest.mark.parametrize("shift", [3600.0, -100.0])
def test_a_clock_set_while_recording_is_a_break_the_replay_goes_across(
    sessions: Callable[[str], Session], tmp_path: Path, shift: float,
) -> None:
    # From line 1001 on, every stamp is an hour later (NTP set the clock of a robot without a
    # real-time clock) or 100 s earlier: one break, the same odometry as the clean log.
    s = sessions("turtlebot3_burger")
    clean = replay_file(s.config, s.log)
    log = with_stamp(s, tmp_path, "step.log", lambda lines: lines[:1000] + [
        restamp(text, stamp(text) + shift) for text in lines[1000:]])
    got = replay_file(s.config, log)
    summary, want = got.summary(), clean.summary()
    assert (summary.breaks, summary.out_of_time_lines) == (1, 0)
    (jump,) = got.timeline.breaks
    assert jump.line_number == 1001
    assert jump.time_s - jump.previous_s == pytest.approx(shift, abs=0.02)
    assert summary.gap_s == (pytest.approx(jump.time_s - jump.previous_s) if shift > 0 else 0.0)
    assert summary.updates == want.updates and summary.entries == want.entries
    assert summary.pose == want.pose and summary.distance_m == want.distance_m
    assert summary.duration_s == pytest.approx(want.duration_s, abs=0.02)


def test_cli_reports_the_line_out_of_time_and_no_wrong_config(
    sessions: Callable[[str], Session], runner: CliRunner, tmp_path: Path,
) -> None:
    s = sessions("turtlebot3_burger")
    clean = replay_file(s.config, s.log).summary()

    def change(lines: list[str]) -> list[str]:
        lines[1000] = restamp(lines[1000], stamp(lines[1000]) + 3600.0)
        return lines

    log = with_stamp(s, tmp_path, "jump.log", change)
    before = stamp(s.log.read_text(encoding="ascii").splitlines()[999])
    after = stamp(s.log.read_text(encoding="ascii").splitlines()[1000]) + 3600.0
    result = runner.invoke(command, ["-c", str(DIFF), str(log)], obj=OBJ)
    assert result.exit_code == 0, result.output
    assert (f"warning: skipped line 1001: expected a time stamp at most {MAX_GAP_S:g} s after "
            f"the log's time before it ({before:.6f}), got ({after:.6f}), "
            f"{after - before:.3f} s later") in result.stderr
    assert "0 unreadable lines skipped, 1 line out of time skipped" in result.stdout
    # One encoder sample fewer (the controllers' feedback at their own phases): the same
    # updates within one, as the replay of the file counts them, the same distance.
    got = replay_file(s.config, log).summary()
    assert abs(got.updates - clean.updates) <= 1
    assert f"{got.updates:,} updates" in result.stdout
    assert f"distance: {clean.distance_m:.3f} m" in result.stdout
    assert "configuration is probably not" not in result.stderr
    doc = json.loads(runner.invoke(command, ["-c", str(DIFF), str(log), "--json"],
                                   obj=OBJ).stdout)
    assert doc["out_of_time_lines"] == 1 and doc["time_breaks"] == 0
    assert doc["out_of_time"][0]["line"] == 1001
    assert doc["out_of_time"][0]["time_s"] == pytest.approx(after)
    assert doc["out_of_time"][0]["previous_s"] == pytest.approx(before)
    assert doc["updates"] == got.updates
    quiet = runner.invoke(command, ["-c", str(DIFF), str(log), "-q"], obj=OBJ)
    assert "skipped line" not in quiet.stderr
    assert "1 line out of time skipped" in quiet.stdout


# ----------------------------------------------------------------- short logs


def times(replay: Replay, lines: list[str]) -> list[float]:
    return [round(s.time_s, 6) for s in replay.feed_lines(lines)]


def steady(n: int, start: float = 0.0) -> list[str]:
    """Both wheels of the TurtleBot forward, 0.1 turn every 10 ms from ``start``."""
    return [line(start + k * 0.01, node, k * 0.1 * (1 if node == 1 else -1))
            for k in range(n) for node in (1, 2)]


def test_a_line_out_of_time_is_skipped_whichever_way_it_goes() -> None:
    cfg = load_config(DIFF)
    clean = Replay(cfg, 0.0)
    want = times(clean, steady(10))
    for bad in ("(3600.050000) can0 7FF#00 R\n", "(0.000100) can0 7FF#00 R\n",
                "(-0.5) can0 7FF#00 R\n"):
        log = steady(10)
        log.insert(11, bad)  # after the frames at 0.05 s
        replay = Replay(cfg, 0.0)
        assert times(replay, log) == want, bad
        assert replay.summary().pose == clean.summary().pose
        (err,) = replay.timeline.bad
        assert isinstance(err, StampError)
        assert (err.line_number, err.previous_s) == (12, 0.05)
        assert replay.timeline.breaks == []


def test_first_and_last_lines_out_of_time() -> None:
    cfg = load_config(DIFF)
    log = ["(3600.000000) can0 7FF#00 R\n", *steady(5), "(-7.0) can0 7FF#00 R\n"]
    replay = Replay(cfg, 0.0)
    assert times(replay, log) == [0.0, 0.01, 0.02, 0.03, 0.04]
    first, last = replay.timeline.bad
    assert str(first) == ("line 1: expected a time stamp no later than the next line's "
                          "(0.000000), got (3600.000000), 3600.000 s later")
    assert str(last) == ("line 12: expected a time stamp no earlier than the log's time before "
                         "it (0.040000), got (-7.000000), 7.040 s earlier")
    assert replay.summary().start_s == 0.0


def test_a_step_back_goes_on_from_the_time_before_it() -> None:
    cfg = load_config(DIFF)
    r = cfg.model.wheels[0].radius
    # 0 .. 0.09 s, then the clock set back 100 s: the wheels go on turning.
    log = steady(10) + [line(-100.0 + k * 0.01, node, k * 0.1 * (1 if node == 1 else -1))
                        for k in range(10, 20) for node in (1, 2)]
    replay = Replay(cfg, 0.0)
    got = times(replay, log)
    # In order, every group an update (the first after the step may join the last before
    # it: no time passed).
    assert got == sorted(got) and len(got) >= 19
    summary = replay.summary()
    assert summary.breaks == 1 and summary.out_of_time_lines == 0
    assert str(replay.timeline.breaks[0]).startswith(
        "line 21: the log's time goes 99.990 s back, from (0.090000) to (-99.900000)")
    assert summary.pose.x_m == pytest.approx(2 * math.pi * 1.9 * r, rel=1e-6)
    assert summary.duration_s == pytest.approx(0.18)


def test_a_gap_forward_is_integrated_across_and_left_out_of_the_duration() -> None:
    cfg = load_config(DIFF)
    r = cfg.model.wheels[0].radius
    log = steady(10) + [line(60.0 + k * 0.01, node, k * 0.1 * (1 if node == 1 else -1))
                        for k in range(10, 20) for node in (1, 2)]
    replay = Replay(cfg, 0.0)
    assert len(times(replay, log)) == 20
    summary = replay.summary()
    assert summary.breaks == 1 and summary.gap_s == pytest.approx(60.0 + 0.1 - 0.09)
    assert summary.pose.x_m == pytest.approx(2 * math.pi * 1.9 * r, rel=1e-6)
    assert summary.duration_s == pytest.approx(0.18)


def test_small_steps_back_and_pauses_are_no_jumps() -> None:
    cfg = load_config(DIFF)
    # A frame 5 ms behind the one before it (two interfaces merged), and a pause of 0.9 s.
    log = [*steady(3), line(0.015, 1, 0.15), *steady(3, start=0.9)]
    replay = Replay(cfg, 0.0)
    for _ in replay.feed_lines(log):
        pass
    assert replay.timeline.bad == [] and replay.timeline.breaks == []
    assert replay.summary().entries == len(log)


def test_cli_lists_breaks_and_caps_the_list(runner: CliRunner, tmp_path: Path) -> None:
    # The clock stepped forward and back again and again: every step a break, the first few
    # named, the rest counted.
    log: list[str] = []
    for k in range(MAX_REPORTED + 5):
        log += steady(3, start=(k % 2) * 3600.0 + k * 0.1)
    path = tmp_path / "steps.log"
    path.write_text("".join(log), encoding="ascii")
    result = runner.invoke(command, ["-c", str(DIFF), str(path)], obj=OBJ)
    assert result.exit_code == 0, result.output
    assert result.stderr.count("the log's time jumps") + result.stderr.count(
        "the log's time goes") == MAX_REPORTED
    assert "... and 4 more breaks in the log's time" in result.stderr
    assert f"{MAX_REPORTED + 4} breaks in the log's time" in result.stdout
    assert "skipped line" not in result.stderr


def test_bad_gaps_are_refused() -> None:
    with pytest.raises(ValueError, match="max_gap_s > 0 s"):
        Timeline(0.0)
    with pytest.raises(ValueError, match="max_step_back_s >= 0 s"):
        Timeline(1.0, math.nan)
    with pytest.raises(ValueError, match="max_gap_s"):
        Replay(load_config(DIFF), max_gap_s=math.inf)
