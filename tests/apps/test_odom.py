"""``wheelgate odom`` and :mod:`gateway.apps.replay.replay`: a candump log replayed through the
drivers
and the odometry.

The logs are recorded in the test by the gateway itself (``Gateway(record=...)``, as ``wheelgate
run --record`` does) driving simulated controllers on simulated time, so the replay can be held
against the gateway's own odometry of the same session and against the ground truth (the
simulators' exact wheel angles).
"""

from __future__ import annotations

import csv
import dataclasses
import json
import math
import sys
from dataclasses import dataclass
from typing import TYPE_CHECKING

import can
import pytest
import yaml

from drivers.odrive.codec import OdriveCodec
from gateway.apps.replay.replay import Replay, SteeringSource, fixed_subset, reconstruct_steer
from gateway.cli import COMMANDS, main
from gateway.cli.commands.odom import CSV_COLUMNS, MAX_REPORTED, NO_MATPLOTLIB, command
from gateway.config import load_config
from gateway.core.control import Source
from gateway.core.kinematics import se2_exp
from gateway.core.types import Twist
from tests.conftest import CONFIG_DIR
from tests.e2e_helpers import Rig, path_legs, virtual_config

if TYPE_CHECKING:
    from collections.abc import Callable
    from pathlib import Path

    from click.testing import CliRunner, Result

    from gateway.core.kinematics import OdometryState
    from gateway.core.settings import GatewayConfig

OBJ = {"interface": None, "channel": None, "debug": False}
DIFF = CONFIG_DIR / "turtlebot3_burger.yaml"


def wrap(angle: float) -> float:
    return (angle + math.pi) % (2 * math.pi) - math.pi


# ----------------------------------------------------------------- recorded sessions


class SimClockLog(can.Listener):
    """A candump writer that stamps frames with the rig's simulated time (the gateway stamps
    them with ``time.time()``, which would make the test depend on the wall clock)."""

    def __init__(self, path: Path, clock: Callable[[], float]) -> None:
        self.writer = can.CanutilsLogWriter(str(path))
        self.clock = clock

    def on_message_received(self, msg: can.Message) -> None:
        msg.timestamp = self.clock()
        self.writer.on_message_received(msg)

    def stop(self) -> None:
        self.writer.stop()


@dataclass(frozen=True)
class Session:
    config: GatewayConfig
    log: Path
    gateway: OdometryState
    truth: OdometryState


def short_legs(config: GatewayConfig) -> list[tuple[Twist, float]]:
    """A straight metre, a quarter turn of radius 1.5 m, another metre (car-like robots)."""
    v = 0.4
    return [(Twist(v, 0.0, 0.0), 2.5), (Twist(v, 0.0, v / 1.5), math.pi / 2 * 1.5 / v),
            (Twist(v, 0.0, 0.0), 2.5)]


def record(name: str, folder: Path) -> Session:
    """Drive a session of ``config/<name>.yaml`` and keep its log and odometry; a name ending
    in ``_external`` drives that robot without its steering actuators (steered outside the
    gateway, so the log holds no angles)."""
    base = name.removesuffix("_external")
    cfg = virtual_config(CONFIG_DIR / f"{base}.yaml", f"wg-odom-{name}", rate_hz=100.0)
    if base != name:
        cfg = dataclasses.replace(cfg, steering=())
    legs = short_legs(cfg) if base == "ackermann" else path_legs(cfg, "square")
    path = folder / f"{name}.log"
    with Rig(cfg) as rig:
        log = SimClockLog(path, lambda: rig.t)
        rig.gw.edge.record = log
        try:
            rig.enable()
            for twist, seconds in legs:
                rig.advance(seconds, lambda r, t=twist: r.gw.twist(t, r.t, Source.SOCKET))  # type: ignore[misc]
            rig.advance(1.0)
        finally:
            log.stop()
        return Session(cfg, path, rig.gw.odometry.state, rig.truth.state)


@pytest.fixture(scope="module")
def sessions(tmp_path_factory: pytest.TempPathFactory) -> Callable[[str], Session]:
    """Sessions by config name, recorded once per module."""
    folder = tmp_path_factory.mktemp("odom")
    cache: dict[str, Session] = {}

    def get(name: str) -> Session:
        if name not in cache:
            cache[name] = record(name, folder)
        return cache[name]

    return get


def replay_file(config: GatewayConfig, path: Path, **kw: float) -> Replay:
    replay = Replay(config, **kw)
    with open(path, encoding="ascii") as f:
        for _ in replay.feed_lines(f):
            pass
    return replay


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


def line(t: float, node: int, turns: float, direction: str = "R") -> str:
    """A Get_Encoder_Estimates line of an ODrive axis (turtlebot3: nodes 1 and 2, gear 1)."""
    f = OdriveCodec.from_options({}).make_encoder_estimates(node, turns, 0.0)
    return f"({t:.6f}) can0 {f.arbitration_id:03X}#{f.data.hex().upper()} {direction}\n"


def times(replay: Replay, lines: list[str]) -> list[float]:
    return [round(s.time_s, 6) for s in replay.feed_lines(lines)]


def test_updates_wait_until_every_wheel_has_a_new_sample() -> None:
    cfg = load_config(DIFF)
    log = [line(0.0, 1, 0.0), line(0.0005, 2, 0.0),   # both: the first update (baseline)
           line(0.001, 1, 0.1), line(0.002, 1, 0.2),  # left only: wait
           line(0.0025, 2, -0.2),                     # right too: update at 0.0025
           line(0.003, 1, 0.3)]                       # pending at the end: last update
    assert times(Replay(cfg, 0.0), log) == [0.0005, 0.0025, 0.003]


def test_frames_with_one_time_stamp_make_one_update() -> None:
    cfg = load_config(DIFF)
    log = [line(k * 0.01, node, k * 0.1 * (1 if node == 1 else -1))
           for k in range(5) for node in (1, 2)]
    assert times(Replay(cfg, 0.0), log) == [0.0, 0.01, 0.02, 0.03, 0.04]


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


def test_a_wheel_that_falls_silent_delays_updates_by_the_longest_interval() -> None:
    cfg = load_config(DIFF)
    log = [line(0.0, 1, 0.0), line(0.0, 2, 0.0)]
    log += [line(k * 0.01, 1, k * 0.01) for k in range(1, 51)]   # right falls silent
    got = times(Replay(cfg, 0.0, max_interval_s=0.1), log)
    assert got == [0.0, 0.1, 0.2, 0.3, 0.4, 0.5]


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


def test_cli_plot_without_matplotlib_exits_2_before_replaying(
    sessions: Callable[[str], Session], runner: CliRunner, tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    s = sessions("turtlebot3_burger")
    monkeypatch.setitem(sys.modules, "matplotlib", None)
    out = tmp_path / "traj.csv"
    result = run(runner, "-c", str(DIFF), str(s.log), "--plot", str(tmp_path / "p.png"),
                 "--csv", str(out))
    assert result.exit_code == 2
    assert NO_MATPLOTLIB in result.stderr
    assert not out.exists()
    assert not (tmp_path / "p.png").exists()


def test_cli_plot_writes_a_png(sessions: Callable[[str], Session], runner: CliRunner,
                               tmp_path: Path) -> None:
    pytest.importorskip("matplotlib")
    s = sessions("turtlebot3_burger")
    png = tmp_path / "p.png"
    result = run(runner, "-c", str(DIFF), str(s.log), "--plot", str(png), "--every", "5")
    assert result.exit_code == 0, result.output
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert f"plot: {png}" in result.stdout


def test_cli_wrong_config_exits_1(sessions: Callable[[str], Session],
                                  runner: CliRunner) -> None:
    s = sessions("turtlebot3_burger")
    result = run(runner, "-c", str(CONFIG_DIR / "mecanum.yaml"), str(s.log))
    assert result.exit_code == 1
    assert "no odometry: 0 of" in result.stderr
    assert "is it the right config?" in result.stderr
