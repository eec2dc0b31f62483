"""``wheelgate calibrate``: the kinematics: block's factors fitted to runs whose end pose was
measured.

The runs are recorded by the gateway itself on simulated time (as in the odom tests: the
TurtleBot's two ODrives), driving with the nominal geometry.  The floor's truth is that of a
robot whose wheels and track differ from the file: the same logs integrated on the geometry
of the true factors (what the simulated wheels' angles would have done on that robot).  The
fit must find those factors from the end poses alone, and leave a combination that the runs
cannot tell as it was.
"""

from __future__ import annotations

import json
import math
import re
from typing import TYPE_CHECKING

import pytest
import yaml

from gateway.apps.calibrate.fit import fit
from gateway.apps.calibrate.runs import end_poses, factors_of, read_run
from gateway.cli import main
from gateway.config import parse_config
from gateway.core.kinematics.odometry import Pose
from gateway.core.types import Twist
from tests.apps.odom_helpers import DIFF, drive, record, replay_file
from tests.conftest import CONFIG_DIR
from tests.e2e_helpers import virtual_config

if TYPE_CHECKING:
    from pathlib import Path

    from click.testing import CliRunner

#: The robot's true factors: the left wheel 2 % larger, the right 1.5 % smaller, the track
#: 4 % wider than the file says.
TRUE = {"left": 1.02, "right": 0.985, "separation": 1.04}


def _legs(kind: str) -> list[tuple[Twist, float]]:
    """A 1 m square turning in place (ccw or cw), or 2 m straight."""
    v, w = 0.2, 0.8
    if kind == "straight":
        return [(Twist(v, 0.0, 0.0), 2.0 / v)]
    turn = w if kind == "ccw" else -w
    return [(Twist(v, 0.0, 0.0), 1.0 / v), (Twist(0.0, 0.0, turn), math.pi / 2 / w)] * 4


def _record(kind: str, folder: Path) -> Path:
    cfg = virtual_config(DIFF, f"wg-cal-{kind}", rate_hz=100.0)
    return drive(cfg, _legs(kind), folder / f"{kind}.log").log


def _with(factors: dict[str, float]) -> dict[str, object]:
    raw: dict[str, object] = yaml.safe_load(DIFF.read_text())
    kinematics = raw.get("kinematics") or {}
    assert isinstance(kinematics, dict)
    raw["kinematics"] = {**kinematics,
                         "wheel_radius_multipliers": {"left": factors["left"],
                                                      "right": factors["right"]},
                         "wheel_separation_multiplier": factors["separation"]}
    return raw


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, tuple[Path, str]]:
    """Per run: its log and its end as measured on the true robot (``X,Y,THETA``)."""
    folder = tmp_path_factory.mktemp("calibrate")
    truth = parse_config(_with(TRUE), str(DIFF))
    out = {}
    for kind in ("ccw", "cw", "straight"):
        path = _record(kind, folder)
        pose = replay_file(truth, path).odometry.state.pose
        out[kind] = (path, f"{pose.x_m!r},{pose.y_m!r},{math.degrees(pose.theta_rad)!r}")
    return out


def _fitted(output: str) -> dict[str, float]:
    block = yaml.safe_load(output.split("# fitted by wheelgate calibrate: these keys in the "
                                        "configuration's kinematics: block (its other keys as "
                                        "they are)\n", 1)[1])["kinematics"]
    return {**block["wheel_radius_multipliers"],
            "separation": block.get("wheel_separation_multiplier", 1.0)}


def test_squares_both_ways_and_a_straight_run_give_the_true_factors(
        runner: CliRunner, runs: dict[str, tuple[Path, str]], tmp_path: Path) -> None:
    args = [f"{path}={end}" for path, end in runs.values()]
    result = runner.invoke(main, ["calibrate", "-c", str(DIFF), *args])
    assert result.exit_code == 0, result.output
    found = _fitted(result.stdout)
    assert found == pytest.approx(TRUE, abs=2e-4), result.stdout
    rms = re.search(r"fit: end poses ([\d.]+) mm RMS from the measured -> ([\d.]+) mm",
                    result.stdout)
    assert rms is not None and float(rms[1]) > 20.0 and float(rms[2]) < 0.2, result.stdout
    assert "not told by these runs" not in result.stdout
    # The printed block, put in the file, ends every run where it was measured.
    fixed = parse_config(_with(found), str(DIFF))
    for path, end in runs.values():
        pose = replay_file(fixed, path).odometry.state.pose
        x, y, theta = (float(v) for v in end.split(","))
        assert (pose.x_m, pose.y_m) == pytest.approx((x, y), abs=1e-3)
        assert math.degrees(pose.theta_rad) == pytest.approx(theta, abs=0.05)


def test_two_squares_do_not_tell_the_overall_size_and_say_so(
        runner: CliRunner, runs: dict[str, tuple[Path, str]]) -> None:
    args = [f"{path}={end}" for kind, (path, end) in runs.items() if kind != "straight"]
    result = runner.invoke(main, ["calibrate", "-c", str(DIFF), *args])
    assert result.exit_code == 0, result.output
    said = re.search(r"not told by these runs, left as it was: (.*) \(a 1 % change moves the "
                     r"ends less than the 5 mm accuracy", result.stdout)
    assert said is not None, result.stdout
    assert said[1] == "0.58 left + 0.57 right + 0.58 separation"
    found = _fitted(result.stdout)
    # What squares tell UMBmark's way: the wheels' size ratio and the turn (track / size).
    assert found["left"] / found["right"] == pytest.approx(TRUE["left"] / TRUE["right"],
                                                            rel=1e-3)
    assert (found["separation"] / (found["left"] + found["right"])
            == pytest.approx(TRUE["separation"] / (TRUE["left"] + TRUE["right"]), rel=2e-3))
    # Measured to a millimetre, the same squares tell it too (2.3 mm per 1 %).
    sharp = runner.invoke(main, ["calibrate", "-c", str(DIFF), "--accuracy", "1", *args])
    assert sharp.exit_code == 0, sharp.output
    assert "not told" not in sharp.stdout
    assert _fitted(sharp.stdout) == pytest.approx(TRUE, abs=2e-4)


def test_the_fit_leaves_an_undetermined_combination_where_it_was() -> None:
    """Pure: two factors whose sum alone matters."""
    result = fit(lambda v: [v[0] + v[1] - 2.1, 0.0], 2)
    assert result.factors == pytest.approx((1.05, 1.05))
    assert len(result.undetermined) == 1
    assert result.undetermined[0] == pytest.approx((2 ** -0.5, -(2 ** -0.5)))


def test_measurements_in_the_wrong_unit_are_refused(
        runner: CliRunner, runs: dict[str, tuple[Path, str]]) -> None:
    path, end = runs["straight"]
    x, y, theta = (float(v) for v in end.split(","))
    wrong = f"{path}={x * 100},{y * 100},{theta}"  # centimetres
    result = runner.invoke(main, ["calibrate", "-c", str(DIFF), wrong])
    assert result.exit_code == 2, result.output
    assert "outside 0.5 to 2: check the measured poses (metres and degrees" in result.output


@pytest.mark.parametrize(("arg", "message"), [
    ("run.log=1,2", "expected LOG=X,Y,THETA"),
    ("run.log=1,2,nan", "expected LOG=X,Y,THETA"),
    ("1,2,3", "expected LOG=X,Y,THETA"),
    ("run.log=1,2,400", "expected LOG=X,Y,THETA"),
    ("{missing}=0.1,0,0", "cannot read the log"),
    ("{empty}=0.1,0,0", "got no odometry update from it"),
    ("{mcap}=0.1,0,0", "got an MCAP recording, which calibrate does not read"),
])
def test_bad_runs_are_usage_errors(runner: CliRunner, tmp_path: Path, arg: str,
                                   message: str) -> None:
    (tmp_path / "empty.log").write_text("(0.0) can0 123#00 R\n")
    (tmp_path / "run.mcap").write_bytes(b"\x89MCAP0\r\n")
    arg = arg.format(missing=tmp_path / "none.log", empty=tmp_path / "empty.log",
                     mcap=tmp_path / "run.mcap")
    result = runner.invoke(main, ["calibrate", "-c", str(DIFF), arg])
    assert result.exit_code == 2, result.output
    assert message in result.output


@pytest.mark.parametrize("name", ["default", "differential_castor", "swerve"])
def test_integrated_again_as_configured_it_ends_where_the_replay_ends(
        name: str, tmp_path: Path) -> None:
    """The geometry rebuilt for factors 1.0 is the loader's (a preset with a track, a castor
    robot integrated on its fixed wheels, swerve modules with the angles their actuators
    measured), and a factor changes the end."""
    session = record(name, tmp_path)
    with open(session.log, encoding="ascii") as f:
        run = read_run(session.config, name, f, Pose())
    factors = factors_of(session.config)
    ones = [1.0] * len(factors.names)
    expected = replay_file(session.config, session.log).odometry.state.pose
    (end,) = end_poses(session.config, factors, ones, [run])
    assert (end.x_m, end.y_m, end.theta_rad) == pytest.approx(
        (expected.x_m, expected.y_m, expected.theta_rad), abs=1e-9)
    assert factors.separation is (name != "differential_castor")
    (moved,) = end_poses(session.config, factors, [*ones[:-1], 1.01], [run])
    assert math.hypot(moved.x_m - end.x_m, moved.y_m - end.y_m) > 1e-3


def test_the_fit_goes_on_top_of_the_files_own_factors(
        runner: CliRunner, runs: dict[str, tuple[Path, str]], tmp_path: Path) -> None:
    own = tmp_path / "robot.yaml"
    own.write_text(yaml.safe_dump(_with({"left": 1.01, "right": 1.0, "separation": 1.02})))
    args = [f"{path}={end}" for path, end in runs.values()]
    result = runner.invoke(main, ["calibrate", "-c", str(own), *args])
    assert result.exit_code == 0, result.output
    assert _fitted(result.stdout) == pytest.approx(TRUE, abs=2e-4)
    assert re.search(r"wheel_radius_multipliers\.left +1\.0100 -> 1\.0200 ", result.stdout)
    assert re.search(r"wheel_separation_multiplier +1\.0200 -> 1\.0400 ", result.stdout)


def test_json_holds_the_runs_the_factors_and_the_block(
        runner: CliRunner, runs: dict[str, tuple[Path, str]], tmp_path: Path) -> None:
    args = [f"{path}={end}" for kind, (path, end) in runs.items() if kind != "straight"]
    result = runner.invoke(main, ["calibrate", "-c", str(DIFF), "--json", *args])
    assert result.exit_code == 0, result.output
    out = json.loads(result.stdout)
    assert out["ok"] is True and [r["log"] for r in out["runs"]] == [
        str(runs["ccw"][0]), str(runs["cw"][0])]
    assert out["runs"][0]["measured"]["x_m"] == pytest.approx(float(runs["ccw"][1].split(",")[0]))
    assert [f["key"] for f in out["factors"]] == [
        "wheel_radius_multipliers.left", "wheel_radius_multipliers.right",
        "wheel_separation_multiplier"]
    assert out["kinematics"]["wheel_radius_multipliers"]["left"] == round(
        out["factors"][0]["fitted"], 4)
    (untold,) = out["undetermined"]
    assert untold == pytest.approx({"left": 0.58, "right": 0.57, "separation": 0.58}, abs=0.01)
    bad = runner.invoke(main, ["calibrate", "-c", str(DIFF), "--json", "run.log=1,2"])
    assert bad.exit_code == 2
    assert json.loads(bad.stdout)["error"]["code"] == "bad_usage"


def test_a_passive_wheels_own_factor_stays_in_the_block(runner: CliRunner, tmp_path: Path
                                                        ) -> None:
    """The castor's radius factor is not fitted (no motor turns it) and not lost: the block
    printed to paste holds it as the file has it."""
    session = record("differential_castor", tmp_path)
    raw = yaml.safe_load((CONFIG_DIR / "differential_castor.yaml").read_text())
    raw["kinematics"] = {"wheel_radius_multipliers": {"castor": 1.1}}
    own = tmp_path / "robot.yaml"
    own.write_text(yaml.safe_dump(raw))
    end = replay_file(parse_config(raw, str(own)), session.log).odometry.state.pose
    result = runner.invoke(main, ["calibrate", "-c", str(own), f"{session.log}="
                                  f"{end.x_m!r},{end.y_m!r},{math.degrees(end.theta_rad)!r}"])
    assert result.exit_code == 0, result.output
    block = yaml.safe_load(result.stdout.split("they are)\n", 1)[1])["kinematics"]
    assert block["wheel_radius_multipliers"] == {"left": 1.0, "right": 1.0, "castor": 1.1}
    assert "wheel_separation_multiplier" not in block  # (drive: generic: no track)
