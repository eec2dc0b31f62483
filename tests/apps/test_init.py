"""``wheelgate init``'s configurations: from every shipped example, on every driver, a file that
``wheelgate check`` accepts, that holds the example's data and comments, and that says what
to measure and fill in."""

from __future__ import annotations

import logging
import re
import shutil
from typing import TYPE_CHECKING, Any

import pytest
import yaml

from gateway.apps.init import Chosen, choose, generate
from gateway.apps.init.annotated import WIDTH, read, render
from gateway.apps.init.notes import FILL_IN, MEASURE
from gateway.config import load_config
from gateway.config.budget import check_bus
from gateway.config.keys import MOTOR_KEYS
from gateway.core.errors import ConfigError
from gateway.drive.driveset import DriveSet
from gateway.drive.registry import VALID_DRIVERS, get_driver_class
from tests.conftest import CONFIG_DIR

if TYPE_CHECKING:
    from pathlib import Path

    from gateway.apps.init import Written
    from gateway.core.settings import GatewayConfig

EXAMPLES = {p.stem: p.read_text("utf-8") for p in sorted(CONFIG_DIR.glob("*.yaml"))}
#: The shipped files besides the examples (the DBC files they name, the unit).
SHIPPED = sorted(p.name for p in CONFIG_DIR.iterdir()
                 if p.is_file() and p.suffix not in (".yaml", ".py"))
DRIVERS = [None, *sorted(VALID_DRIVERS)]
EXAMPLES_DRIVE = {name: yaml.safe_load(text)["drive"] for name, text in EXAMPLES.items()}


@pytest.fixture(autouse=True)
def _quiet_drivers(caplog: pytest.LogCaptureFixture) -> None:
    """A driver warns about a gear ratio its motor does not have (a DJI M3508 on the
    example's 1:1): what ``check`` shows, not a failure here."""
    caplog.set_level(logging.ERROR)


def make(name: str, driver: str | None = None, **kw: Any) -> Written:
    return generate(EXAMPLES, name, driver, shipped=SHIPPED, **kw)


def load_written(written: Written, folder: Path) -> GatewayConfig:
    """The configuration as ``wheelgate check -c`` judges it, with the files it names beside:
    loaded, and its bus budget (a bitrate the controllers cannot talk at, a full bus)."""
    path = folder / "robot.yaml"
    path.write_text(written.text, "utf-8")
    for name in written.files:
        shutil.copy(CONFIG_DIR / name, folder / name)
    config = load_config(path)
    check_bus(config, DriveSet(config))
    return config


def data(text: str) -> Any:
    return yaml.safe_load(text)


def prose(text: str) -> str:
    """A YAML text's comments as one line of words (wrapped comments joined)."""
    return " ".join(" ".join(comments(text)).split())


def comments(text: str) -> list[str]:
    """The texts of a YAML text's comments (whole-line and end-of-line), without ``#``."""
    out = []
    for line in text.splitlines():
        at = line.find("#")
        if at >= 0 and (at == 0 or line[:at].strip() == "" or line[at - 1] == " "):
            out.append(line[at + 1:].strip())
    return out


# ----------------------------------------------------------------------------- check accepts


@pytest.mark.parametrize("driver", DRIVERS)
@pytest.mark.parametrize("name", sorted(EXAMPLES))
def test_every_example_on_every_driver_makes_a_file_check_accepts(
    name: str, driver: str | None, tmp_path: Path
) -> None:
    written = make(name, driver)
    config = load_written(written, tmp_path)
    example = load_config(CONFIG_DIR / f"{name}.yaml")
    assert config.drive == example.drive == written.drive
    assert [w.name for w in config.model.wheels] == [w.name for w in example.model.wheels]
    motors = [m for m in config.motors if m is not None]
    assert len(motors) == len([m for m in example.motors if m is not None])
    if driver is not None:
        assert {m.driver for m in motors} == {driver} and written.drivers == (driver,)
    assert [(a.driver, a.node_id) for a in config.steering] == [
        (a.driver, a.node_id) for a in example.steering]
    assert max(len(line) for line in written.text.splitlines()) <= WIDTH


@pytest.mark.parametrize("name", sorted(EXAMPLES))
def test_without_choices_the_file_holds_the_examples_data(name: str) -> None:
    written = make(name)
    assert data(written.text) == data(EXAMPLES[name])
    assert written.example == name and not written.assignments


@pytest.mark.parametrize("driver", sorted(VALID_DRIVERS))
@pytest.mark.parametrize("name", sorted(EXAMPLES))
def test_a_driver_switch_changes_only_the_drive_motors_protocol(name: str, driver: str) -> None:
    before, after = data(EXAMPLES[name]), data(make(name, driver).text)
    old_motors, new_motors = _motor_blocks(before), _motor_blocks(after)
    for raw in (before, after):
        raw.pop("motor_defaults", None)
        for block in _motor_blocks(raw):
            block.clear()
    rates = get_driver_class(driver).BITRATES  # (DJI ESCs talk at 1 Mbit/s only)
    if rates and before["bus"].get("bitrate") not in rates:
        before["bus"]["bitrate"] = rates[0]
    assert after == before  # geometry, wheels, steering, limits, bus, name: as they were
    common = set(MOTOR_KEYS) - {"driver", "node_id"}
    assert [{k: v for k, v in b.items() if k in common} for b in new_motors] == [
        {k: v for k, v in b.items() if k in common} for b in old_motors]


def _motor_blocks(raw: dict[str, Any]) -> list[dict[str, Any]]:
    if raw["drive"] == "generic":
        return [w["motor"] for w in raw["wheels"] if w.get("motor")]
    return list(raw["motors"].values())


def test_a_switched_driver_takes_its_keys_and_comments_from_an_example_that_uses_it() -> None:
    text = make("mecanum", "vesc").text
    raw = data(text)
    tub = data(EXAMPLES["differential_tub"])["motor_defaults"]
    assert raw["motor_defaults"] == {**{k: v for k, v in tub.items() if k not in MOTOR_KEYS},
                                     "driver": "vesc", "gear_ratio": 19.203208556149733,
                                     "max_rpm": 9000}
    assert "no_controller_stop" not in text and "C620/C610" not in text.split("motors:")[0]
    assert "# Set on each VESC in VESC Tool" in text
    assert "drive motors are on the vesc driver (the example's: dji" in prose(text)


def test_node_ids_another_driver_cannot_take_are_numbered_afresh(tmp_path: Path) -> None:
    written = make("differential_tub", "dji")  # VESC nodes 10 and 11; DJI ESCs are 1..8
    assert data(written.text)["motors"] == {"left": {"node_id": 1},
                                            "right": {"node_id": 2, "invert": True}}
    assert "the example's node IDs (10, 11) are not free dji node IDs (1..8)" in \
        prose(written.text)
    load_written(written, tmp_path)
    kept = data(make("differential_tub", "odrive").text)["motors"]
    assert [m["node_id"] for m in kept.values()] == [10, 11]


def test_a_tricycle_switch_moves_the_driver_into_motor_defaults() -> None:
    raw = data(make("tricycle", "odrive").text)
    assert list(raw)[:4] == ["name", "drive", "geometry", "motor_defaults"]
    assert raw["motor_defaults"]["driver"] == "odrive"
    assert raw["motors"]["front"] == {"node_id": 5, "gear_ratio": 20.0, "max_rpm": 3000}
    assert raw["steering"]["front"]["driver"] == "cia402"


def test_the_dbc_file_it_names_is_one_to_put_beside_it_or_named_where_installed() -> None:
    assert make("example_dbc").files == ("example_controller.dbc",)
    assert make("mecanum", "dbc").files == ("example_controller.dbc",)
    assert make("mecanum").files == ()
    placed = make("mecanum", "dbc", place={"example_controller.dbc": "/opt/x/e.dbc"})
    assert data(placed.text)["motor_defaults"]["dbc"] == "/opt/x/e.dbc"


def test_an_unknown_driver_is_refused_with_the_known_ones() -> None:
    with pytest.raises(ConfigError, match=r"--driver: Unknown driver 'canopen'; expected one "
                                          r"of: cia402, dbc"):
        make("mecanum", "canopen")


# ----------------------------------------------------------------------------- comments


@pytest.mark.parametrize("driver", [None, "vesc"])
@pytest.mark.parametrize("name", sorted(EXAMPLES))
def test_the_examples_own_comments_stay(name: str, driver: str | None) -> None:
    text = make(name, driver).text
    ours = prose(text)
    theirs = comments(EXAMPLES[name])
    if driver is not None:  # the protocol keys' comments go with the keys
        theirs = comments(EXAMPLES[name].split("motors:")[0].split("motor_defaults:")[0])
    for comment in theirs:
        assert " ".join(comment.split()) in ours, comment


@pytest.mark.parametrize("name", sorted(EXAMPLES))
def test_the_file_says_what_each_block_is_and_what_to_measure_and_fill_in(name: str) -> None:
    text = make(name).text
    lines = text.splitlines()
    assert prose("\n".join(lines[:3])).startswith(
        f"wheelgate configuration of a robot with drive: {EXAMPLES_DRIVE[name]}, written by "
        f"`wheelgate init` from the shipped example '{name}'.")
    assert "wheelgate check -c robot.yaml" in text
    for key in data(text):  # a comment above every block
        at = lines.index(next(line for line in lines if line.startswith(f"{key}:")))
        assert lines[at - 1].startswith("#"), key
    raw = data(text)
    for key in ("wheel_radius", "track", "wheelbase", "wheel_distance", "max_steer"):
        if key in raw.get("geometry", {}):
            assert MEASURE in _note_of(lines, f"  {key}:"), key
    if raw["drive"] == "generic":
        assert f"{MEASURE} l, radius and d" in prose(text)
    for key in ("gear_ratio", "max_rpm"):
        if key in raw.get("motor_defaults", {}):
            assert FILL_IN in _note_of(lines, f"  {key}:"), key
    motors = "wheels" if raw["drive"] == "generic" else "motors"
    assert "invert: true where the motor turns its wheel backwards" in _block_note(lines, motors)
    if "limits" in raw:
        assert "Limits on every command" in _block_note(lines, "limits")
    if "steering" in raw:
        assert f"{MEASURE} zero_rad" in _block_note(lines, "steering")


def _note_of(lines: list[str], start: str) -> str:
    """The comment at the end of the line that starts with ``start``, or on the line above."""
    at = next(i for i, line in enumerate(lines) if line.startswith(start))
    end = lines[at].partition("#")[2]
    return end or lines[at - 1]


def _block_note(lines: list[str], key: str) -> str:
    at = next(i for i, line in enumerate(lines) if line.startswith(f"{key}:"))
    above: list[str] = []
    while lines[at - 1].startswith("#"):
        at -= 1
        above.insert(0, lines[at])
    return prose("\n".join(above))


def test_the_header_says_what_init_changed() -> None:
    text = make("mecanum", "odrive", file="/etc/wheelgate/robot.yaml").text
    head = prose(text.split("\nname:")[0])
    assert "from the shipped example 'mecanum'" in head
    assert "drive motors are on the odrive driver (the example's: dji; protocol keys from the " \
           "example 'differential_castor')" in head
    assert "wheelgate check -c /etc/wheelgate/robot.yaml" in head
    assert "Four-wheel mecanum robot of seeds 001 and 003" in head  # the example's own header


# ----------------------------------------------------------------------------- --drive


def test_drive_names_an_example_or_the_one_example_of_a_drive() -> None:
    assert choose(EXAMPLES, "mecanum") == Chosen("mecanum")
    assert choose({"a": "drive: omni\n", "b": "drive: mecanum\n"}, "omni") == Chosen("a", "omni")
    # Without a table, a drive of several examples is refused, naming them (see
    # test_init_drive.py for the shipped table).
    with pytest.raises(ConfigError, match=re.escape(
            "--drive differential: 3 shipped examples have drive: differential "
            "(differential_tub, example_dbc, turtlebot3_burger) and none is its first; "
            "expected the name of one")):
        choose(EXAMPLES, "differential")
    with pytest.raises(ConfigError, match="--drive hexapod: no shipped example of that name or "
                                          "drive; expected one of ackermann, differential_castor"):
        choose(EXAMPLES, "hexapod")


# ----------------------------------------------------------------------------- the YAML writer


TRICKY = """\
# top
name: x   # the name
gateway:
  # above a block
  can_ids:   # after a block's key
    twist: 0x200
wheels:
  # above an item
  - name: a
    # above a key in an item
    type: fixed   # end of a key in an item
  - {name: b, type: fixed, alpha: 1.5707963267948966, l: 0.2, beta: 0.0, radius: 0.05, \
motor: {node_id: 1, invert: true}}  # long
list: [1, 2]
empty: {}
text: 'yes'
"""


def test_the_writer_keeps_data_comments_and_style_of_what_configurations_use() -> None:
    doc = read(TRICKY, "t.yaml")
    text = render(doc)
    assert yaml.safe_load(text) == yaml.safe_load(TRICKY)
    assert doc.header == ("top",)
    for comment in comments(TRICKY):
        assert comment in comments(text), comment
    assert "  can_ids:                      # after a block's key" in text
    assert "  - {name: b, type: fixed, alpha: 1.5707963267948966" in text  # flow stays flow
    assert "list: [1, 2]" in text and "empty: {}" in text and "text: 'yes'" in text
    assert max(len(line) for line in text.splitlines()) <= WIDTH
    assert text.index("# long") < text.index("- {name: b")  # a long line's end comment: above


def test_a_document_that_is_not_a_mapping_is_named_and_quoted_briefly() -> None:
    with pytest.raises(ConfigError) as err:
        read("just some text, " * 40, "notes.txt")
    assert str(err.value) == (
        "notes.txt: expected a mapping at the top level (a robot's configuration, key: value), "
        "got a string of 639 characters, 'just some text, just some text, just some text, just "
        "some t...")
