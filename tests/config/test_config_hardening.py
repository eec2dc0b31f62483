"""Configuration files that PyYAML alone would take wrongly or slowly: duplicate keys, aliases,
huge scalars, huge files, deep nesting; and what is allowed but warned about."""

from __future__ import annotations

import time
from typing import TYPE_CHECKING

import pytest
import yaml

from gateway.cli import main
from gateway.config import load_config
from gateway.config.yaml_text import MAX_BYTES
from gateway.core.errors import ConfigError
from tests.conftest import CONFIG_DIR

if TYPE_CHECKING:
    from pathlib import Path

    from click.testing import CliRunner

MECANUM = (CONFIG_DIR / "mecanum.yaml").read_text()


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "robot.yaml"
    path.write_text(text)
    return path


def test_a_motor_given_twice_is_refused_naming_both_lines(tmp_path: Path) -> None:
    lines = MECANUM.splitlines()
    k = next(i for i, line in enumerate(lines) if line.strip().startswith("rear_right:"))
    text = "\n".join([*lines[: k + 1], lines[k].split(":")[0] + ": {node_id: 4}",
                      *lines[k + 1:]])
    with pytest.raises(ConfigError) as err:
        load_config(write(tmp_path, text))
    assert f"line {k + 2}: key 'rear_right' is given twice in one mapping (first on line " \
           f"{k + 1})" in str(err.value)


def test_a_second_limits_block_is_refused(tmp_path: Path) -> None:
    text = MECANUM + "\nlimits:\n  max_linear_m_s: 2.0\n"
    with pytest.raises(ConfigError, match="key 'limits' is given twice"):
        load_config(write(tmp_path, text))


def test_an_alias_bomb_is_refused_at_once(tmp_path: Path) -> None:
    bomb = "a: &a [lol, lol, lol, lol, lol, lol, lol, lol, lol]\n" + "".join(
        f"{chr(98 + i)}: &{chr(98 + i)} [{', '.join([f'*{chr(97 + i)}'] * 9)}]\n"
        for i in range(8)
    )
    start = time.process_time()
    with pytest.raises(ConfigError, match="anchors and aliases are not accepted"):
        load_config(write(tmp_path, MECANUM + bomb))
    assert time.process_time() - start < 1.0  # nothing was expanded


def test_a_huge_integer_is_a_clear_error_not_a_traceback(
    tmp_path: Path, runner: CliRunner
) -> None:
    path = write(tmp_path, MECANUM.replace("node_id: 1", "node_id: " + "9" * 5000, 1))
    result = runner.invoke(main, ["check", "-c", str(path)])
    assert result.exit_code == 2, result.output
    assert "expected a value of at most 4096 characters, got 5000" in result.output
    path = write(tmp_path, MECANUM.replace("node_id: 1", "node_id: " + "9" * 200, 1))
    with pytest.raises(ConfigError, match="expected a number of at most 80 characters"):
        load_config(path)


def test_a_huge_file_is_refused_before_it_is_parsed(tmp_path: Path) -> None:
    path = write(tmp_path, MECANUM + "#" * MAX_BYTES)
    with pytest.raises(ConfigError, match=f"at most {MAX_BYTES} bytes"):
        load_config(path)


def test_deep_nesting_is_refused(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="levels of nesting"):
        load_config(write(tmp_path, MECANUM + "\nx: " + "[" * 40 + "]" * 40 + "\n"))


def test_a_world_writable_socket_is_warned_about(tmp_path: Path, runner: CliRunner) -> None:
    path = write(tmp_path, MECANUM + "\ngateway:\n  socket_mode: 0777\n")
    result = runner.invoke(main, ["check", "-c", str(path)])
    assert result.exit_code == 0, result.output
    assert "gateway.socket_mode: 0o777 makes the control socket writable by every local user" \
        in result.output
    # One more than the shipped robot's own (its DJI ESCs have no controller-side stop).
    own = load_config(CONFIG_DIR / "mecanum.yaml").warnings
    assert not any("socket_mode" in w for w in own)
    assert f"ok, with {len(own) + 1} warning(s)" in result.output


def test_every_shipped_config_still_loads() -> None:
    for path in sorted(CONFIG_DIR.glob("*.yaml")):
        load_config(path)


def test_a_file_without_a_bus_block_is_warned_about(tmp_path: Path) -> None:
    """No bus: block means the virtual bus, where only simulators answer: a real robot's
    configuration without one would never reach its controllers."""
    text = "\n".join(line for line in MECANUM.splitlines()
                     if not line.startswith(("bus:", "  interface:", "  channel:", "  bitrate:")))
    assert "bus:" not in text
    cfg = load_config(write(tmp_path, text))
    assert any("no bus: block" in w and "virtual bus" in w for w in cfg.warnings), cfg.warnings
    told = load_config(write(tmp_path, text), {"interface": "socketcan", "channel": "can0"})
    assert not any("no bus: block" in w for w in told.warnings)
    assert not any("no bus: block" in w for w in load_config(None).warnings)  # the demo's own


def test_a_file_without_an_acceleration_limit_is_warned_about(tmp_path: Path) -> None:
    """No limits (or no max_wheel_accel_rad_s2): a twist steps the wheels to full speed in
    one cycle; the shipped examples and the demo set one and are not warned about."""
    lines = MECANUM.splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("limits:"))
    end = next(i for i in range(start + 1, len(lines)) if not lines[i].startswith("  "))
    without = "\n".join(lines[:start] + lines[end:])
    only_speed = "\n".join([*lines[:start], "limits: {max_linear_m_s: 1.0}", *lines[end:]])
    only_decel = "\n".join([*lines[:start], "limits: {max_wheel_decel_rad_s2: 40.0}",
                            *lines[end:]])
    for text, what in ((without, "no limits: block"),
                       (only_speed, "limits: no max_wheel_accel_rad_s2"),
                       (only_decel, "speeds every wheel up in one cycle (max_wheel_decel_rad_s2 "
                                    "bounds only slowing down)")):
        warned = [w for w in load_config(write(tmp_path, text)).warnings
                  if "max_wheel_accel_rad_s2" in w]
        assert len(warned) == 1 and what in warned[0], warned
        assert ("new speed" in warned[0]) == (text != only_decel)
    for path in (None, *sorted(CONFIG_DIR.glob("*.yaml"))):
        assert not any("max_wheel_accel_rad_s2" in w for w in load_config(path).warnings), path


def test_every_problem_of_a_file_is_reported_at_once(tmp_path: Path) -> None:
    # Five problems in five blocks, and two in one block: a person fixing the file sees all
    # seven in one run, each naming the file and its key path, in the file's order of blocks.
    path = write(tmp_path, """\
drive: mecanum
colour: red
geometry: {wheel_radius: 0.05, wheelbase: 0.4, track: 0.36}
motor_defaults: {driver: odrive, gear_ratio: 10, max_rpm: 3000}
motors:
  front_left: {node_id: 1, inverted: true}
  front_right: {node_id: 2, invert: true}
  rear_left: {node_id: 3}
  rear_right: {node_id: 4, invert: yes please}
limits: {max_linear_m_s: -1, max_angular_rad_s: fast}
bus: {interface: virtual, channel: wheelgate, bitrate: 0}
gateway: {rate_hz: 5}
""")
    with pytest.raises(ConfigError) as info:
        load_config(path)
    problems = info.value.problems
    assert len(problems) == 7, problems
    where = [p.split(": ")[1] for p in problems]
    assert where == ["colour", "motors.front_left.inverted", "motors.rear_right.invert",
                     "limits.max_linear_m_s", "limits.max_angular_rad_s", "bus.bitrate",
                     "gateway.rate_hz"], problems
    assert all(p.startswith(f"{path}: ") for p in problems)
    assert "did you mean 'invert'?" in problems[1]
    assert str(info.value).splitlines() == list(problems)


def test_a_broken_geometry_or_general_key_hides_no_other_problem(tmp_path: Path) -> None:
    # The geometry fails (a misspelt key), yet the motor blocks, which only need the wheels'
    # names, are checked on stand-in wheels; in each block a missing general key, an unknown
    # key and an out-of-range node ID are all reported; the swerve's steering block too.
    path = write(tmp_path, """\
drive: swerve
geometry: {wheel_radius: 0.05, wheelbas: 0.4, track: 0.36}
motor_defaults: {driver: odrive, gear_ratio: 10}
motors:
  front_left: {node_id: 99, inverted: true}
  front_right: {node_id: 2, max_rpm: 3000}
  rear_left: {node_id: 3, max_rpm: 3000}
  rear_right: {node_id: 4, max_rpm: 3000}
steering:
  front_left: {driver: odrive, node_id: 5, gear_ratio: 10, max_rpm: 3000, zero: 1}
limits: {max_linear_m_s: -1}
""")
    with pytest.raises(ConfigError) as info:
        load_config(path)
    where = [p.split(": ")[1] for p in info.value.problems]
    assert where == ["geometry.wheelbas", "geometry.wheelbase", "motors.front_left.max_rpm",
                     "motors.front_left.inverted", "motors.front_left.node_id",
                     "steering.front_left.zero", "limits.max_linear_m_s"], info.value.problems
    assert "a swerve drive" not in info.value.problems[0]  # swerve has a wheelbase
    assert "did you mean 'wheelbase'?" in info.value.problems[0]


def test_a_block_that_needs_a_broken_one_is_not_checked(tmp_path: Path) -> None:
    # An unknown drive has no wheels to put motors on: its motors are not judged (no second,
    # misleading problem), but the independent blocks still are.
    path = write(tmp_path, """\
drive: mecanumm
motors: {front_left: {node_id: 1}}
limits: {max_linear_m_s: -1}
""")
    with pytest.raises(ConfigError) as info:
        load_config(path)
    problems = info.value.problems
    assert len(problems) == 2, problems
    assert "drive: expected one of" in problems[0] and "mecanumm" in problems[0]
    assert "limits.max_linear_m_s" in problems[1]


def test_a_motor_block_reports_its_unknown_keys_and_its_protocol_problems_together(
    tmp_path: Path,
) -> None:
    path = write(tmp_path, """\
drive: differential
geometry: {wheel_radius: 0.05, track: 0.3}
motor_defaults: {driver: vesc, max_rpm: 3000, gear_ratio: 5, controller_timeout_s: 1.0}
motors: {left: {node_id: 1, inverted: true}, right: {node_id: 2}}
bus: {interface: socketcan, channel: can0}
""")
    with pytest.raises(ConfigError) as info:
        load_config(path)
    assert [p.split(": ")[1] for p in info.value.problems] == [
        "motors.left.inverted", "motors.left.pole_pairs", "motors.right.pole_pairs"]


def test_a_driver_s_doubt_is_a_warning_of_the_file(tmp_path: Path) -> None:
    # DJI motors have gearboxes: a gear_ratio of 1.0 (left from another driver's example) is
    # said once per motor among the file's warnings, which check counts and run logs.
    raw = yaml.safe_load((CONFIG_DIR / "mecanum.yaml").read_text())
    raw["motor_defaults"]["gear_ratio"] = 1.0
    cfg = load_config(write(tmp_path, yaml.safe_dump(raw)))
    doubts = [w for w in cfg.warnings if "gear_ratio is 1.0" in w]
    assert len(doubts) == 4, cfg.warnings
    assert doubts[0].endswith("motor 'front_left': gear_ratio is 1.0; an M3508 needs 19.2032 "
                              "(its gearbox)"), doubts
    assert not any("gear_ratio is 1.0" in w for w in load_config(CONFIG_DIR / "mecanum.yaml")
                   .warnings)


def test_an_empty_file_and_a_gateway_key_among_the_motors_say_what_they_are(
        tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="the file is empty; expected a robot's config"):
        load_config(write(tmp_path, ""))
    with pytest.raises(ConfigError) as info:
        load_config(write(tmp_path, """\
drive: differential
geometry: {wheel_radius: 0.033, track: 0.16}
motor_defaults: {driver: odrive, max_rpm: 100, controller_watchdog: warn}
motors: {left: {node_id: 1, driver: odrive}, right: {node_id: 2, kpp: 1}}
"""))
    # An unknown key of motor_defaults is named there, once for the blocks that inherit it
    # (a block that names the defaults' driver again too); one of a motor block in that block.
    problems = info.value.problems
    assert len(problems) == 2, problems
    assert ": motor_defaults.controller_watchdog: unknown key" in problems[0]
    assert problems[0].endswith(
        "('controller_watchdog', given in motor_defaults, is a gateway: key)")
    assert ": motors.right.kpp: unknown key" in problems[1]
    # A bad value of motor_defaults is named there too, once: not at motors.left and
    # motors.right, which do not have the key; a block's own value stays the block's.
    with pytest.raises(ConfigError) as info:
        load_config(write(tmp_path, """\
drive: differential
geometry: {wheel_radius: 0.033, track: 0.16}
motor_defaults: {driver: odrive, max_rpm: 100, gear_ratio: FILL, firmware: "0.7"}
motors: {left: {node_id: 1}, right: {node_id: 2, max_rpm: 0}}
"""))
    assert [p.partition(": ")[2] for p in info.value.problems] == [
        "motor_defaults.gear_ratio: expected float, got 'FILL'",
        "motor_defaults.firmware: expected one of '0.5', '0.6', got '0.7'",
        "motors.right.max_rpm: expected more than 0, got 0.0"], info.value.problems
    # ...and so is one of steering_defaults, for every actuator that inherits it.
    raw = yaml.safe_load((CONFIG_DIR / "swerve.yaml").read_text())
    raw["steering_defaults"] = {**raw.get("steering_defaults", {}), "gear_ratio": 0}
    with pytest.raises(ConfigError) as info:
        load_config(write(tmp_path, yaml.safe_dump(raw)))
    assert [p.partition(": ")[2] for p in info.value.problems] == [
        "steering_defaults.gear_ratio: expected at least 0.0001, got 0.0"], info.value.problems
    # A key of the defaults that only a block's own driver does not take is that block's; a
    # gateway key in steering_defaults says so.
    raw = yaml.safe_load((CONFIG_DIR / "swerve.yaml").read_text())
    raw["motors"]["front_left"] = {**raw["motors"]["front_left"], "driver": "vesc",
                                   "pole_pairs": 7}
    raw["steering_defaults"] = {**raw.get("steering_defaults", {}), "controller_watchdog": "warn"}
    with pytest.raises(ConfigError) as info:
        load_config(write(tmp_path, yaml.safe_dump(raw)))
    problems = info.value.problems
    inherited = [p for p in problems if "watchdog_endpoints: unknown key" in p]
    assert len(inherited) == 1 and ": motors.front_left.watchdog_endpoints:" in inherited[0], \
        problems
    assert inherited[0].endswith("(given in motor_defaults, which the vesc driver does not take)")
    steering = [p for p in problems if "controller_watchdog" in p]
    assert len(steering) == 1 and ": steering_defaults.controller_watchdog: unknown key" in \
        steering[0] and steering[0].endswith(
        "('controller_watchdog', given in steering_defaults, is a gateway: key)"), problems
