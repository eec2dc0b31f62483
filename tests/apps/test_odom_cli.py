"""``wheelgate odom``: the command replaying a recorded candump log -- its pose, JSON and CSV
output, corrupt lines, the progress bar, plots, and its usage errors.

The logs are recorded by the gateway itself on simulated time (:mod:`tests.apps.odom_helpers`).
"""

from __future__ import annotations

import csv
import json
import sys
from typing import TYPE_CHECKING

import pytest

from gateway.apps.replay.candump_report import MAX_REPORTED
from gateway.cli import COMMANDS, main
from gateway.cli.commands.odom import CSV_COLUMNS, command, install_hint
from gateway.config import load_config
from tests.apps import odom_helpers
from tests.apps.odom_helpers import (
    DIFF,
    OBJ,
    Session,
    replay_file,
)
from tests.conftest import CONFIG_DIR

if TYPE_CHECKING:
    from collections.abc import Callable
    from pathlib import Path

    from click.testing import CliRunner, Result


# The shared fixtures (odom_helpers.py), bound here so that pytest finds them.
sessions = odom_helpers.sessions
#: The first test that asks for a robot's session records it (seconds of simulated driving on
#: one core, several times that on a loaded machine): beyond the suite's 10 s hang guard.
pytestmark = pytest.mark.timeout(60)


# ----------------------------------------------------------------- the command


def run(runner: CliRunner, *args: str) -> Result:
    return runner.invoke(command, list(args), obj=OBJ)


def test_cli_prints_the_replayed_pose(sessions: Callable[[str], Session],
                                      runner: CliRunner) -> None:
    s = sessions("turtlebot3_burger")
    want = replay_file(load_config(DIFF), s.log).summary()
    result = run(runner, "-c", str(DIFF), str(s.log))
    assert result.exit_code == 0, result.output
    out = result.stdout
    p = want.pose
    assert (f"final pose: x {p.x_m:+.4f} m, y {p.y_m:+.4f} m, theta {p.theta_rad:+.4f} rad"
            in out)
    assert f"distance: {want.distance_m:.3f} m" in out
    assert f"frames: {want.entries:,} read" in out
    assert f"{want.updates:,} updates" in out
    assert "x real time" in out
    assert "steering: none" in out
    assert result.stderr == ""


def test_cli_json(sessions: Callable[[str], Session], runner: CliRunner) -> None:
    s = sessions("turtlebot3_burger")
    result = run(runner, "-c", str(DIFF), str(s.log), "--json")
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    assert data["pose"]["x"] == pytest.approx(s.gateway.pose.x_m, abs=1e-6)
    assert data["unreadable_lines"] == 0
    assert data["steering"] == "none"
    assert data["frames"]["motors"] > 0
    assert data["csv"] is None
    assert data["min_interval_s"] == pytest.approx(0.005)   # the config's 200 Hz
    sparse = json.loads(run(runner, "-c", str(DIFF), str(s.log), "--json",
                            "--min-interval-ms", "50").stdout)
    assert sparse["min_interval_s"] == pytest.approx(0.05)
    assert sparse["updates"] < data["updates"] / 4
    assert sparse["pose"]["x"] == pytest.approx(data["pose"]["x"], abs=1e-3)


@pytest.mark.parametrize("every", [1, 7])
def test_cli_csv_columns_and_rows(sessions: Callable[[str], Session], runner: CliRunner,
                                  tmp_path: Path, every: int) -> None:
    s = sessions("turtlebot3_burger")
    updates = replay_file(load_config(DIFF), s.log).summary().updates
    out = tmp_path / "traj.csv"
    result = run(runner, "-c", str(DIFF), str(s.log), "--csv", str(out), "--every", str(every))
    assert result.exit_code == 0, result.output
    with open(out, newline="", encoding="utf-8") as f:
        rows = list(csv.reader(f))
    assert rows[0] == [*CSV_COLUMNS, "left_rad_s", "right_rad_s"]
    kept = -(-updates // every) + (0 if (updates - 1) % every == 0 else 1)
    assert len(rows) - 1 == kept
    assert f"({kept:,} rows)" in result.stdout
    stamps = [float(r[0]) for r in rows[1:]]
    assert stamps == sorted(stamps)
    last = [float(v) for v in rows[-1][1:4]]
    assert last == pytest.approx([s.gateway.pose.x_m, s.gateway.pose.y_m,
                                  s.gateway.pose.theta_rad], abs=1e-6)


def test_cli_reports_corrupt_lines_and_goes_on(sessions: Callable[[str], Session],
                                               runner: CliRunner, tmp_path: Path) -> None:
    s = sessions("turtlebot3_burger")
    lines = s.log.read_text(encoding="ascii").splitlines(keepends=True)
    lines.insert(2, "this is not a frame\n")
    lines.insert(9, "(1.0) can0 12G#00 R\n")
    bad = tmp_path / "bad.log"
    bad.write_text("".join(lines), encoding="ascii")
    result = run(runner, "-c", str(DIFF), str(bad))
    assert result.exit_code == 0, result.output
    assert "warning: skipped line 3: expected '(time) interface ID#DATA [R|T]'" in result.stderr
    assert "warning: skipped line 10: expected a hexadecimal ID, got '12G'" in result.stderr
    assert "2 unreadable lines skipped" in result.stdout
    p = s.gateway.pose
    assert f"final pose: x {p.x_m:+.4f} m, y {p.y_m:+.4f} m" in result.stdout


def test_cli_caps_the_list_of_corrupt_lines(sessions: Callable[[str], Session],
                                            runner: CliRunner, tmp_path: Path) -> None:
    s = sessions("turtlebot3_burger")
    bad = tmp_path / "bad.log"
    bad.write_text("garbage\n" * 30 + s.log.read_text(encoding="ascii"), encoding="ascii")
    result = run(runner, "-c", str(DIFF), str(bad))
    assert result.exit_code == 0, result.output
    assert result.stderr.count("warning: skipped line") == MAX_REPORTED
    assert f"... and {30 - MAX_REPORTED} more unreadable lines" in result.stderr
    quiet = run(runner, "-c", str(DIFF), str(bad), "-q")
    assert quiet.exit_code == 0
    assert "skipped line" not in quiet.stderr
    assert "30 unreadable lines skipped" in quiet.stdout


def test_cli_progress_bar_only_when_asked_or_on_a_terminal(
    sessions: Callable[[str], Session], runner: CliRunner
) -> None:
    s = sessions("turtlebot3_burger")
    assert "replaying" not in run(runner, "-c", str(DIFF), str(s.log)).stderr
    shown = run(runner, "-c", str(DIFF), str(s.log), "--progress")
    assert shown.exit_code == 0
    assert "replaying" in shown.stderr
    assert "100%" in shown.stderr
    assert "replaying" not in run(runner, "-c", str(DIFF), str(s.log), "--progress",
                                  "-q").stderr


def test_cli_usage_errors_exit_2(sessions: Callable[[str], Session], runner: CliRunner,
                                 tmp_path: Path) -> None:
    s = sessions("turtlebot3_burger")
    missing = run(runner, "-c", str(DIFF), str(tmp_path / "nope.log"))
    assert missing.exit_code == 2
    assert "nope.log' does not exist" in missing.stderr
    every = run(runner, "-c", str(DIFF), str(s.log), "--every", "0")
    assert every.exit_code == 2
    assert "Invalid value for '--every'" in every.stderr
    folder = run(runner, "-c", str(DIFF), str(s.log), "--csv", str(tmp_path / "no" / "t.csv"))
    assert folder.exit_code == 2
    assert "expected a file in an existing directory" in folder.stderr


def test_cli_missing_config_exits_2(sessions: Callable[[str], Session], runner: CliRunner,
                                    tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(COMMANDS, "odom", "odom")
    s = sessions("turtlebot3_burger")
    result = runner.invoke(main, ["odom", "-c", str(tmp_path / "robot.yaml"), str(s.log)])
    assert result.exit_code == 2
    assert "robot.yaml: cannot read the file" in result.stderr


def test_cli_plot_without_matplotlib_still_writes_the_csv_then_exits_2(
    sessions: Callable[[str], Session], runner: CliRunner, tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    s = sessions("turtlebot3_burger")
    monkeypatch.setitem(sys.modules, "matplotlib", None)
    out = tmp_path / "traj.csv"
    result = run(runner, "-c", str(DIFF), str(s.log), "--plot", str(tmp_path / "p.png"),
                 "--csv", str(out))
    assert result.exit_code == 2
    assert "warning: --plot: plotting needs matplotlib" in result.stderr
    assert f"--plot {tmp_path / 'p.png'}: not drawn" in result.stderr
    # Said at once, before the replay; the CSV and the summary are there all the same.
    assert result.stderr.index("warning: --plot") < result.stderr.index("not drawn")
    rows = out.read_text().splitlines()
    assert rows[0].startswith(",".join(CSV_COLUMNS)) and len(rows) > 100
    assert f"csv: {out}" in result.stdout and "final pose:" in result.stdout
    assert not (tmp_path / "p.png").exists()


def test_the_install_hint_names_this_python_and_the_clone_of_an_editable_install(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path,
) -> None:
    import importlib.metadata
    import json

    class Dist:
        def __init__(self, text: str | None) -> None:
            self.text = text

        def read_text(self, name: str) -> str | None:
            assert name == "direct_url.json"
            return self.text

    clone = {"url": f"file://{tmp_path}/wheelgate", "dir_info": {"editable": True}}
    for origin, expected in (
        (clone, f"{sys.executable} -m pip install -e '{tmp_path}/wheelgate[plot]'"),
        ({"url": "https://example.org/w.whl", "archive_info": {}},
         f"{sys.executable} -m pip install 'wheelgate[plot]'"),
        (None, f"{sys.executable} -m pip install 'wheelgate[plot]'"),
    ):
        text = None if origin is None else json.dumps(origin)
        monkeypatch.setattr(importlib.metadata, "distribution", lambda _n, t=text: Dist(t))
        assert install_hint("plot") == expected


def test_cli_plot_writes_a_png(sessions: Callable[[str], Session], runner: CliRunner,
                               tmp_path: Path) -> None:
    pytest.importorskip("matplotlib")
    s = sessions("turtlebot3_burger")
    png = tmp_path / "p.png"
    result = run(runner, "-c", str(DIFF), str(s.log), "--plot", str(png), "--every", "5")
    assert result.exit_code == 0, result.output
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert f"plot: {png}" in result.stdout


def test_cli_wrong_config_exits_2_with_the_error_alone(sessions: Callable[[str], Session],
                                                      runner: CliRunner) -> None:
    """A log that does not fit the configuration is bad input: the error, and no summary of
    a replay that did not happen (no zero pose, no warning about it) before it."""
    s = sessions("turtlebot3_burger")
    result = run(runner, "-c", str(CONFIG_DIR / "mecanum.yaml"), str(s.log))
    assert result.exit_code == 2
    assert "no odometry: 0 of" in result.stderr
    assert "is it the right config?" in result.stderr
    assert result.stdout == ""
    assert "warning:" not in result.stderr and "Usage:" not in result.stderr
    doc = json.loads(run(runner, "-c", str(CONFIG_DIR / "mecanum.yaml"), str(s.log),
                         "--json").stdout)
    assert doc["ok"] is False and doc["error"]["code"] == "no_odometry"
    assert "no odometry: 0 of" in doc["error"]["message"]


def test_a_log_of_another_robot_is_warned_about(
    sessions: Callable[[str], Session], runner: CliRunner,
) -> None:
    # The demo's mecanum log (ODrive nodes 1 to 4) replayed with the TurtleBot's configuration
    # (ODrive nodes 1 and 2): two of the four wheels make a path that never was; the frames of
    # nodes 3 and 4 give it away.
    s = sessions("default")
    result = run(runner, "-c", str(DIFF), str(s.log))
    warned = [line for line in result.stderr.splitlines() if "does not name" in line]
    assert len(warned) == 1, result.stderr
    assert "ODrive node 3, ODrive node 4" in warned[0] and "another robot's log" in warned[0]
    share = float(warned[0].split("warning: ")[1].split("%")[0])
    assert 45 <= share <= 55  # half the controllers' frames are of the two unnamed nodes
    report = json.loads(run(runner, "-c", str(DIFF), str(s.log), "--json").stdout)
    assert [(d["protocol"], d["node_id"]) for d in report["foreign_controllers"]["devices"]] \
        == [("ODrive", 3), ("ODrive", 4)]
    # The right configuration: nothing foreign, and the gateway's own pose frames agree.
    mine = run(runner, str(s.log))
    assert "does not name" not in mine.stderr and mine.exit_code == 0, mine.stderr
    assert "gateway: " in mine.stdout and "from the gateway's own odometry" in mine.stdout
    assert json.loads(run(runner, str(s.log), "--json").stdout)["foreign_controllers"] is None


def test_a_robots_own_commands_are_not_taken_for_another_robots_controllers(
    sessions: Callable[[str], Session], runner: CliRunner,
) -> None:
    """The DBC robot commands its wheels on 0x201 and 0x202, where DJI ESCs send their
    feedback: its own log, replayed with its own configuration, was said to be 64 % another
    robot's (DJI nodes 1 and 2).  Frames a driver of the robot sends are the robot's."""
    s = sessions("example_dbc")
    result = run(runner, "-c", str(CONFIG_DIR / "example_dbc.yaml"), str(s.log))
    assert result.exit_code == 0, result.stderr
    assert "does not name" not in result.stderr, result.stderr
    report = json.loads(run(runner, "-c", str(CONFIG_DIR / "example_dbc.yaml"), str(s.log),
                            "--json").stdout)
    assert report["foreign_controllers"] is None


def test_a_replay_that_departs_from_the_gateways_pose_is_warned_about(
    sessions: Callable[[str], Session], runner: CliRunner, tmp_path: Path,
) -> None:
    s = sessions("turtlebot3_burger")
    wrong = tmp_path / "tb3.yaml"
    wrong.write_text(DIFF.read_text().replace("wheel_radius: 0.033", "wheel_radius: 0.036"))
    assert wrong.read_text() != DIFF.read_text()
    result = run(runner, "-c", str(wrong), str(s.log))
    assert "departs from the gateway's own odometry" in result.stderr, result.stderr
    assert "departs" not in run(runner, "-c", str(DIFF), str(s.log)).stderr
