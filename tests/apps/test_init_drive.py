"""``wheelgate init --drive DRIVE``: a drive type starts from its shipped example (a table,
``shipped.BY_DRIVE``), names the others, and example names still work; the root options
``--interface``/``--channel`` go into the written ``bus:`` block; what the file and the
output say to do next is ``wheelgate spin``, the per-wheel tool."""

from __future__ import annotations

from typing import TYPE_CHECKING

import pytest
import yaml

from gateway.apps.init import Chosen, choose, shipped
from gateway.cli import main
from gateway.config import load_config
from gateway.core.kinematics import PRESETS
from tests.conftest import CONFIG_DIR

if TYPE_CHECKING:
    from pathlib import Path

    from click.testing import CliRunner

EXAMPLES = {p.stem: p.read_text("utf-8") for p in sorted(CONFIG_DIR.glob("*.yaml"))}
DRIVES = {name: yaml.safe_load(text)["drive"] for name, text in EXAMPLES.items()}


def test_every_drive_has_one_example_in_the_table() -> None:
    """Every preset and generic, and every drive an example has: a new example of a drive
    that had one must not make ``--drive`` of it ambiguous."""
    assert set(shipped.BY_DRIVE) == {*PRESETS, "generic"} == set(DRIVES.values())
    for drive, name in shipped.BY_DRIVE.items():
        assert DRIVES[name] == drive, (drive, name)


@pytest.mark.parametrize(("drive", "example", "others"), [
    ("differential", "turtlebot3_burger", ("differential_tub", "example_dbc")),
    ("omni", "omni3", ("omni_delta",)),
    ("generic", "differential_castor", ("omni3_swedish",)),
])
def test_a_drive_chooses_its_example_and_names_the_others(drive: str, example: str,
                                                          others: tuple[str, ...]) -> None:
    assert choose(EXAMPLES, drive, shipped.BY_DRIVE) == Chosen(example, drive, others)


def test_an_example_name_still_names_that_example() -> None:
    assert choose(EXAMPLES, "example_dbc", shipped.BY_DRIVE) == Chosen("example_dbc")
    assert choose(EXAMPLES, "mecanum", shipped.BY_DRIVE) == Chosen("mecanum")  # a name too


def test_init_drive_differential_writes_a_file_check_accepts(runner: CliRunner,
                                                            tmp_path: Path) -> None:
    out = tmp_path / "robot.yaml"
    result = runner.invoke(main, ["init", "--drive", "differential", "-o", str(out)])
    assert result.exit_code == 0, result.output
    lines = result.stdout.splitlines()
    assert lines[0] == (f"wrote {out}: drive differential, from the example "
                        f"'turtlebot3_burger', drive motors on odrive")
    assert lines[1] == ("--drive differential: 'turtlebot3_burger' is the shipped example for "
                        "drive: differential; the other examples of that drive: "
                        "differential_tub, example_dbc (--drive NAME starts from one)")
    assert load_config(out).name == "turtlebot3_burger"


def test_the_root_bus_options_go_into_the_bus_block(runner: CliRunner, tmp_path: Path) -> None:
    out = tmp_path / "robot.yaml"
    result = runner.invoke(main, ["--interface", "socketcan", "--channel", "vcan0", "init",
                                  "--drive", "turtlebot3_burger", "-o", str(out)])
    assert result.exit_code == 0, result.output
    assert yaml.safe_load(out.read_text())["bus"] == {
        "interface": "socketcan", "channel": "vcan0", "bitrate": 250000}
    bus = load_config(out).bus  # no override: the file says vcan0
    assert (bus.interface, bus.channel) == ("socketcan", "vcan0")
    assert ("bus: interface socketcan, channel vcan0 (from the root options; the example's: "
            "interface socketcan, channel can0, bitrate 250000)") in result.stdout
    assert "# Its bus: interface socketcan, channel vcan0, as given to init" in out.read_text()
    plain = runner.invoke(main, ["init", "--drive", "turtlebot3_burger", "-o", "-"])
    assert yaml.safe_load(plain.stdout)["bus"]["channel"] == "can0"
    assert "from the root options" not in plain.stderr
    rated = runner.invoke(main, ["--interface", "pcan", "--bitrate", "500000", "init",
                                 "--drive", "turtlebot3_burger", "-o", "-"])
    assert rated.exit_code == 0, rated.output
    assert yaml.safe_load(rated.stdout)["bus"] == {  # an integer, as check reads it
        "interface": "pcan", "channel": "can0", "bitrate": 500000}


def test_what_to_do_next_is_spin_not_jog(runner: CliRunner, tmp_path: Path) -> None:
    scan = tmp_path / "scan.json"
    scan.write_text('[{"protocol": "odrive", "node_id": 4, "driver": "odrive"},'
                    ' {"protocol": "odrive", "node_id": 5, "driver": "odrive"}]')
    out = tmp_path / "robot.yaml"
    result = runner.invoke(main, ["init", "--drive", "differential", "--from-scan", str(scan),
                                  "-o", str(out)])
    assert result.exit_code == 0, result.output
    text = out.read_text()
    for said in (result.stdout, text):
        assert "jog each" not in said and "(wheelgate jog)" not in said
    assert (f"node IDs from the scan {scan}, in order (check each wheel: wheelgate spin -c "
            f"{out} WHEEL):") in result.stdout
    prose = " ".join(text.replace("# ", " ").split())  # the comments, unwrapped
    assert f"and spin each wheel (wheelgate spin -c {out} WHEEL, the wheel lifted)" in prose
    assert "then spin each wheel, lifted (`wheelgate spin -c FILE WHEEL`)" in prose
