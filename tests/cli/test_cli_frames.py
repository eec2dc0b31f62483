"""``wheelgate frames``: golden output in cansend syntax."""

from __future__ import annotations

import struct
from typing import TYPE_CHECKING

from gateway.cli import main
from tests.conftest import CONFIG_DIR

if TYPE_CHECKING:
    from click.testing import CliRunner


def test_odrive_frames_are_set_input_vel(runner: CliRunner) -> None:
    # TurtleBot3: vx = 0.1, wz = 0.5 -> left (0.1 - 0.04)/0.033 rad/s, right (0.1 + 0.04)/0.033,
    # in turns/s at gear 1 (right motor inverted); ODrive node 1 -> 0x02D, node 2 -> 0x04D.
    result = runner.invoke(main, ["frames", "-c", str(CONFIG_DIR / "turtlebot3_burger.yaml"),
                                  "--vx", "0.1", "--wz", "0.5"])
    assert result.exit_code == 0, result.output
    tau = 6.283185307179586
    left = struct.pack("<ff", 0.06 / 0.033 / tau, 0.0).hex().upper()
    right = struct.pack("<ff", -0.14 / 0.033 / tau, 0.0).hex().upper()
    assert result.stdout.splitlines() == [f"02D#{left}", f"04D#{right}"]


def test_vesc_frames_use_extended_ids(runner: CliRunner) -> None:
    # differential_tub: r = 0.1, b = 0.4, gear 5, 7 pole pairs; vx = 0.5: 5 rad/s per wheel
    # -> 5 * 5 * 60/(2 pi) * 7 = 1671.1 eRPM -> 1671; node 10 / 11 (inverted).
    result = runner.invoke(main, ["frames", "-c", str(CONFIG_DIR / "differential_tub.yaml"),
                                  "--vx", "0.5"])
    assert result.exit_code == 0, result.output
    assert result.stdout.splitlines() == ["0000030A#00000687", "0000030B#FFFFF979"]


def test_dji_frames_say_they_assume_zero_speed(runner: CliRunner) -> None:
    result = runner.invoke(main, ["frames", "-c", str(CONFIG_DIR / "mecanum.yaml"), "--vx", "0"])
    assert result.exit_code == 0, result.output
    assert result.stdout.splitlines() == ["200#0000000000000000"]
    assert "dji frames show the current for zero measured speed" in result.stderr


def test_frames_infeasible_exits_3(runner: CliRunner) -> None:
    result = runner.invoke(main, ["frames", "-c", str(CONFIG_DIR / "differential_tub.yaml"),
                                  "--vy", "0.5"])
    assert result.exit_code == 3
    assert "breaks its sliding constraint" in result.stderr
    assert result.stdout == ""


def test_frames_speed_limit_is_applied_and_said(runner: CliRunner) -> None:
    result = runner.invoke(main, ["frames", "-c", str(CONFIG_DIR / "turtlebot3_burger.yaml"),
                                  "--vx", "1.0"])
    assert result.exit_code == 0
    assert "note: speed limits scale this twist by 0.2" in result.stderr
