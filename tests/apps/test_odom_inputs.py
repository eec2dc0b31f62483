"""``wheelgate odom`` on input it cannot use: a log without one readable frame is bad input
(exit 2) with the error alone; the reason plotting is unavailable is said once; the CSV writes
no negative zeros."""

from __future__ import annotations

import sys
from typing import TYPE_CHECKING

import pytest

from gateway.apps.replay.replay import Sample
from gateway.cli.commands.odom import _row, command
from gateway.core.kinematics.odometry import Pose
from gateway.core.types import Twist
from tests.apps import odom_helpers
from tests.apps.odom_helpers import DIFF, OBJ

if TYPE_CHECKING:
    from collections.abc import Callable
    from pathlib import Path

    from click.testing import CliRunner

    from tests.apps.odom_helpers import Session

sessions = odom_helpers.sessions
#: The first test that asks for a robot's session records it (seconds of simulated driving on
#: one core, several times that on a loaded machine): beyond the suite's 10 s hang guard.
pytestmark = pytest.mark.timeout(60)


def test_a_log_without_readable_frames_exits_2_with_the_error_alone(
        runner: CliRunner, tmp_path: Path) -> None:
    log = tmp_path / "notes.log"
    log.write_text("these are\nnot frames\n")
    result = runner.invoke(command, [str(log), "-q"], obj=OBJ)
    assert result.exit_code == 2, result.output
    assert result.stdout == ""  # no summary of a replay that did not happen
    assert result.stderr == (
        f"Error: {log}: no odometry: no readable frames in the log (2 unreadable lines); "
        "expected a candump log (candump -l, wheelgate run --record)\n")


def test_why_plotting_is_unavailable_is_said_once(
        sessions: Callable[[str], Session], runner: CliRunner, tmp_path: Path,
        monkeypatch: pytest.MonkeyPatch) -> None:
    s = sessions("turtlebot3_burger")
    monkeypatch.setitem(sys.modules, "matplotlib", None)
    png = tmp_path / "p.png"
    result = runner.invoke(command, ["-c", str(DIFF), str(s.log), "--plot", str(png)], obj=OBJ)
    assert result.exit_code == 2, result.output
    assert result.stderr.count("plotting needs matplotlib") == 1, result.stderr
    assert result.stderr.count("pip install") == 1
    assert f"Error: --plot {png}: not drawn (see the warning above)" in result.stderr


def test_the_csv_has_no_negative_zeros() -> None:
    sample = Sample(-0.0, Pose(-0.0, -0.0, -0.0), Twist(-0.0, -0.0, -0.0), -0.0, -0.0,
                    (-0.0, None, -1e-20), (None, None, None))
    row = _row(sample)
    assert row[0] == "0.000000"
    assert row[1:8] == ["0"] * 7
    assert row[8:] == ["0", "", "-1e-20"]  # a tiny number stays what it is
