"""``wheelgate odom FILE.mcap`` (:mod:`gateway.apps.replay.mcap_source`,
:mod:`gateway.apps.replay.mcap_report`): a live-view recording replayed through the odometry
and compared with the recording's own ``/odom``; damaged files, missing packages, wrong configs.

The recordings are made by :class:`gateway.runtime.liveview.LiveView` itself (``serve=False``,
as ``wheelgate run --record-mcap`` does) from synthetic snapshots whose wheel angles are those of
a known motion.
"""

from __future__ import annotations

import dataclasses
import json
import math
import re
import shutil
import sys
import time
from typing import TYPE_CHECKING

import pytest

from gateway.apps.replay.mcap_source import INSTALL_HINT
from gateway.cli import main
from gateway.config import load_config
from gateway.core.bridge_settings import FoxgloveSettings
from gateway.core.kinematics.odometry import OdometryState, Pose
from gateway.core.types import GatewayState, Twist
from gateway.runtime import liveview
from gateway.runtime.mailbox import Snapshot, SteerSample, WheelSample
from tests.conftest import CONFIG_DIR

if TYPE_CHECKING:
    from pathlib import Path

    from click.testing import CliRunner, Result

    from gateway.core.settings import GatewayConfig

EXTRA = "pip install 'wheelgate[foxglove]'"
pytest.importorskip("foxglove", reason=f"foxglove-sdk not installed: {EXTRA}")
pytest.importorskip("mcap", reason=f"mcap not installed: {EXTRA}")

MECANUM = load_config()   # the embedded default: demo_mecanum, 4 wheels of radius 0.05 m
SWERVE = CONFIG_DIR / "swerve.yaml"
RADIUS_M = 0.05
STEP_S = 0.02
T0 = 1_700_000_000_000_000_000
WAIT_S = 5.0
ORIGIN = Pose()


def drive(config: GatewayConfig, n: int = 51, wheel_rad_s: float = 4.0, start: Pose = ORIGIN,
          start_distance_m: float = 0.0, heading: float = 0.0, odom_error_m: float = 0.0,
          steering: tuple[SteerSample, ...] = ()) -> list[Snapshot]:
    """A straight drive at ``heading`` (body frame) from ``start``: every driven wheel turns at
    ``wheel_rad_s``; the recorded odometry says so, off by ``odom_error_m`` at the end."""
    names = [m.wheel for m in config.motors if m is not None]
    out = []
    for k in range(n):
        t = k * STEP_S
        d = RADIUS_M * wheel_rad_s * t + odom_error_m * k / (n - 1)
        a = start.theta_rad + heading
        pose = Pose(start.x_m + d * math.cos(a), start.y_m + d * math.sin(a), start.theta_rad)
        odom = OdometryState(pose, Twist(0.2, 0.0, 0.0), 0.0, start_distance_m + d, t)
        wheels = tuple(WheelSample(w, wheel_rad_s, wheel_rad_s, 1.0 + wheel_rad_s * t)
                       for w in names)
        out.append(Snapshot(T0 + round(t * 1e9), odom, GatewayState.RUNNING, "", wheels,
                            steering))
    return out


def record(path: Path, config: GatewayConfig, snapshots: list[Snapshot]) -> Path:
    """Record through a live view, every snapshot taken before the next is posted."""
    names = [m.wheel for m in config.motors if m is not None]
    steers = [a.wheel for a in config.steering]
    with liveview.LiveView(FoxgloveSettings(), config.name, names, steers,
                           record_mcap=str(path), serve=False) as view:
        for count, s in enumerate(snapshots, start=1):
            view.mailbox.post(snapshot=s)
            deadline = time.monotonic() + WAIT_S
            while view.stats().snapshots < count:
                assert time.monotonic() < deadline, "the live view did not take a snapshot"
                time.sleep(0.0005)
    return path


def odom(runner: CliRunner, path: Path, *args: str) -> Result:
    return runner.invoke(main, ["odom", *args, str(path)])


def summary(runner: CliRunner, path: Path, *args: str) -> dict[str, object]:
    result = odom(runner, path, "--json", *args)
    assert result.exit_code == 0, result.output
    data: dict[str, object] = json.loads(result.stdout)
    return data


def test_odom_replays_a_recorded_straight_drive(runner: CliRunner, tmp_path: Path) -> None:
    path = record(tmp_path / "drive.mcap", MECANUM, drive(MECANUM))
    result = odom(runner, path)
    assert result.exit_code == 0, result.output
    out = result.stdout
    # 51 snapshots 20 ms apart: 1 s at 4 rad/s on wheels of 0.05 m: 0.2 m ahead.
    assert re.search(r"final pose: x \+0\.2000 m, y [+-]0\.0000 m, theta [+-]0\.0000 rad", out)
    assert "distance: 0.200 m" in out
    assert "odometry: 51 updates" in out
    assert "messages: 255 read (51 on /wheels, 0 on /steering, 51 on /odom)" in out
    assert "robot: demo_mecanum (mecanum, 4 wheels)" in out
    assert "steering: none" in out
    assert "recorded: x +0.2000 m" in out
    assert re.search(r"difference: x [+-]0\.0000 m, y [+-]0\.0000 m, .*\(0\.0000 m apart\)", out)
    assert result.stderr == ""
    data = summary(runner, path)
    assert data["distance_m"] == pytest.approx(0.2, abs=1e-9)
    assert data["format"] == "mcap" and data["recorded_robot"] == "demo_mecanum"


def test_the_difference_is_what_the_recorded_odometry_says_otherwise(
        runner: CliRunner, tmp_path: Path) -> None:
    path = record(tmp_path / "drive.mcap", MECANUM, drive(MECANUM, odom_error_m=0.01))
    out = odom(runner, path).stdout
    assert "recorded: x +0.2100 m" in out
    assert re.search(r"difference: x -0\.0100 m, y [+-]0\.0000 m, .*\(0\.0100 m apart\); "
                     r"distance -0\.0100 m", out)
    difference = summary(runner, path)["difference"]
    assert isinstance(difference, dict)
    assert difference["x"] == pytest.approx(-0.01, abs=1e-9)


def test_the_replay_starts_at_the_recordings_pose(runner: CliRunner, tmp_path: Path) -> None:
    start = Pose(1.0, 2.0, math.pi / 2)
    path = record(tmp_path / "drive.mcap", MECANUM,
                  drive(MECANUM, start=start, start_distance_m=5.0))
    data = summary(runner, path)
    assert data["start_pose"] == pytest.approx({"x": 1.0, "y": 2.0, "theta": math.pi / 2})
    assert data["pose"] == pytest.approx({"x": 1.0, "y": 2.2, "theta": math.pi / 2})
    assert data["distance_m"] == pytest.approx(5.2)
    assert "(the recording's pose there)" in odom(runner, path).stdout
    assert data["difference"] == pytest.approx(
        {"x": 0.0, "y": 0.0, "theta": 0.0, "distance_m": 0.0}, abs=1e-9)


def test_steered_wheels_take_the_recorded_steering_angles(runner: CliRunner,
                                                         tmp_path: Path) -> None:
    """A swerve robot driving sideways: measured angles win over commanded ones, a commanded
    angle stands in for one not measured (as the loop's measured_steer)."""
    swerve = load_config(SWERVE)
    left = math.pi / 2
    actuators = [a.wheel for a in swerve.steering]
    steering = (*(SteerSample(a, 0.0, left) for a in actuators[:3]),
                SteerSample(actuators[3], left, None))
    path = record(tmp_path / "side.mcap", swerve, drive(swerve, heading=left, steering=steering))
    data = summary(runner, path, "-c", str(SWERVE))
    assert data["steering"] == "actuators"
    assert data["pose"] == pytest.approx({"x": 0.0, "y": 0.2, "theta": 0.0}, abs=1e-6)
    assert data["messages"]["/steering"] == 51  # type: ignore[index]


def test_a_recording_is_told_by_its_magic_bytes(runner: CliRunner, tmp_path: Path) -> None:
    path = record(tmp_path / "drive.mcap", MECANUM, drive(MECANUM, n=11))
    renamed = tmp_path / "drive.log"
    shutil.copy(path, renamed)
    assert summary(runner, renamed)["pose"] == summary(runner, path)["pose"]


def test_a_damaged_recording_replays_up_to_the_damage(runner: CliRunner, tmp_path: Path,
                                                       monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(liveview, "FLUSH_S", 0.0)   # a chunk per snapshot: damage loses one
    path = record(tmp_path / "drive.mcap", MECANUM, drive(MECANUM))
    data = path.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) // 2])
    result = odom(runner, cut)
    assert result.exit_code == 0, result.output
    updates = int(re.findall(r"odometry: (\d+) updates", result.stdout)[0])
    assert 5 < updates < 51
    assert f"warning: {cut}: truncated or damaged after" in result.stderr
    distance = float(re.findall(r"distance: ([\d.]+) m", result.stdout)[0])
    assert distance == pytest.approx(RADIUS_M * 4.0 * STEP_S * (updates - 1), abs=1e-3)
    flipped = bytearray(data)
    flipped[chunk_crc_at(data, 10)] ^= 0xFF   # the 10th chunk's records no longer match it
    cut.write_bytes(bytes(flipped))
    damaged = odom(runner, cut)
    assert damaged.exit_code == 0 and "CRCValidationError" in damaged.stderr
    assert "odometry: 9 updates" in damaged.stdout   # one snapshot a chunk


def chunk_crc_at(data: bytes, n: int) -> int:
    """Where the uncompressed CRC of the ``n``-th chunk is (https://mcap.dev/spec#chunk-op0x06:
    opcode, length, start and end time, size, then the CRC)."""
    i = 8   # the magic
    while True:
        opcode, length = data[i], int.from_bytes(data[i + 1:i + 9], "little")
        if opcode == 0x06:
            n -= 1
            if n == 0:
                return i + 9 + 24
        i += 9 + length


def test_a_recording_cut_before_any_message_exits_2(runner: CliRunner, tmp_path: Path) -> None:
    """As a candump log with nothing of the robot's: no odometry is bad input, exit 2."""
    path = record(tmp_path / "drive.mcap", MECANUM, drive(MECANUM, n=5))
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(path.read_bytes()[:200])
    result = odom(runner, cut)
    assert result.exit_code == 2
    assert (f"Error: {cut}: no odometry: 0 /wheels messages in 0; truncated or damaged after 0 "
            "messages of a file of 200 bytes") in result.stderr


def test_a_file_that_is_not_mcap_exits_2(runner: CliRunner, tmp_path: Path) -> None:
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(b"(1700000000.000000) vcan0 123#00\n")
    result = odom(runner, bad)
    assert result.exit_code == 2
    assert "not an MCAP file: expected the magic bytes" in result.stderr


def test_without_the_mcap_package_exits_2(runner: CliRunner, tmp_path: Path,
                                          monkeypatch: pytest.MonkeyPatch) -> None:
    path = record(tmp_path / "drive.mcap", MECANUM, drive(MECANUM, n=3))
    for name in ("mcap", "mcap.records", "mcap.stream_reader"):
        monkeypatch.setitem(sys.modules, name, None)
    result = odom(runner, path)
    assert result.exit_code == 2
    assert INSTALL_HINT in result.stderr


def test_the_wrong_config_exits_2(runner: CliRunner, tmp_path: Path) -> None:
    path = record(tmp_path / "drive.mcap", MECANUM, drive(MECANUM, n=5))
    result = odom(runner, path, "-c", str(CONFIG_DIR / "turtlebot3_burger.yaml"))
    assert result.exit_code == 2
    assert "none with an angle of" in result.stderr
    assert "is it the right config?" in result.stderr
    assert "the recording is of robot 'demo_mecanum'" in result.stderr
    assert "difference: none (nothing was replayed)" in result.stdout


def test_csv_of_a_recording(runner: CliRunner, tmp_path: Path) -> None:
    path = record(tmp_path / "drive.mcap", MECANUM, drive(MECANUM, n=11))
    table = tmp_path / "t.csv"
    result = odom(runner, path, "--csv", str(table))
    assert result.exit_code == 0, result.output
    rows = table.read_text().splitlines()
    assert len(rows) == 12 and rows[0].startswith("time_s,x_m")
    assert f"csv: {table} (11 rows)" in result.stdout


def test_messages_that_are_not_json_objects_are_skipped(runner: CliRunner,
                                                        tmp_path: Path) -> None:
    """A file of another writer (the mcap package's, uncompressed): what is not a JSON object
    on a replayed topic is counted and skipped, the rest replayed."""
    from mcap.writer import CompressionType, Writer

    path = tmp_path / "other.mcap"
    with path.open("wb") as f:
        writer = Writer(f, compression=CompressionType.NONE)
        writer.start()
        wheels = writer.register_channel("/wheels", "json", 0)
        angles = [json.dumps({w: {"position_rad": 1.0 + 0.08 * k} for w in MECANUM.model.names})
                  for k in range(3)]
        for k, data in enumerate([b"not json", b"[1, 2]", *(a.encode() for a in angles)]):
            writer.add_message(wheels, T0 + k * 20_000_000, data, T0 + k * 20_000_000)
        writer.finish()   # type: ignore[no-untyped-call]
    result = odom(runner, path)
    assert result.exit_code == 0, result.output
    assert "odometry: 3 updates" in result.stdout
    assert "distance: 0.008 m" in result.stdout   # 2 steps of 0.08 rad on 0.05 m wheels
    assert "2 messages on /wheels, /steering or /odom were not JSON objects" in result.stderr
    assert "recorded: none (no /odom messages" in result.stdout
    assert "(the origin: no /odom before the first /wheels)" in result.stdout


def test_a_corrupt_wheel_angle_is_no_motion_of_the_replay(runner: CliRunner,
                                                           tmp_path: Path) -> None:
    """One snapshot with a wheel angle of 1e30 rad: the replay takes neither step to it nor
    back (as the daemon's loop did not), and says so."""
    snapshots = drive(MECANUM)
    bad = snapshots[25]
    first = dataclasses.replace(bad.wheels[0], position_rad=1e30)
    snapshots[25] = dataclasses.replace(bad, wheels=(first, *bad.wheels[1:]))
    path = record(tmp_path / "jump.mcap", MECANUM, snapshots)
    data = summary(runner, path)
    assert data["position_jumps"] == 2
    # One wheel of four misses two steps of 20 ms at 4 rad/s: at most a quarter of 8 mm.
    assert 0.2 - 0.002 - 1e-9 < data["distance_m"] < 0.2 - 0.001  # type: ignore[operator]
    result = odom(runner, path)
    assert "2 steps of a wheel's position went beyond what the wheel can turn" in result.output
