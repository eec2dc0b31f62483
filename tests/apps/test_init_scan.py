"""``wheelgate init --from-scan``: a ``wheelgate scan --json`` output read, its nodes given to
the controllers in order, and a clear refusal when they do not fit."""

from __future__ import annotations

import json
import re
from typing import TYPE_CHECKING, Any

import pytest
import yaml

from gateway.apps.init import FoundNode, generate, parse_scan
from gateway.config import load_config
from gateway.core.errors import ConfigError
from tests.conftest import CONFIG_DIR

if TYPE_CHECKING:
    from pathlib import Path

EXAMPLES = {p.stem: p.read_text("utf-8") for p in sorted(CONFIG_DIR.glob("*.yaml"))}


def row(protocol: str, node_id: int | None, driver: str | None = None) -> dict[str, Any]:
    """A row as ``wheelgate scan --json`` writes it (the fields init reads, and some others)."""
    return {"protocol": protocol, "node_id": node_id, "driver": driver or protocol,
            "extended_id": False, "firmware": None, "notes": []}


def nodes(driver: str, *ids: int) -> list[FoundNode]:
    return [FoundNode(driver, i) for i in ids]


# ----------------------------------------------------------------------------- reading


def test_the_scan_is_read_by_driver_each_node_once_without_the_other_rows() -> None:
    text = json.dumps([
        row("odrive", 7), row("canopen", 4, "cia402"), row("odrive", 3), row("odrive", 7),
        {"protocol": "wheelgate", "node_id": None, "driver": None, "message": "WG_Twist"},
        row("unknown", None), {"protocol": "vesc", "node_id": 2},
    ])
    assert parse_scan(text, "scan.json") == (
        FoundNode("cia402", 4), FoundNode("odrive", 3), FoundNode("odrive", 7),
        FoundNode("vesc", 2))


@pytest.mark.parametrize(("text", "message"), [
    ("odrive 1", "scan.json: expected the JSON of `wheelgate scan --json`, got text that is not "
                 "JSON"),
    ('{"nodes": []}', "scan.json: expected a JSON list of nodes (`wheelgate scan --json`), got "
                      "dict"),
    ("[1]", "scan.json: [0]: expected an object with driver (or protocol) and node_id, got 1"),
    ('[{"node_id": 1}]', "scan.json: [0].driver: expected a driver name, got None"),
    ('[{"driver": "vesc", "node_id": "3"}]',
     "scan.json: [0].node_id: expected a node ID (an integer >= 0), got '3'"),
    ('[{"driver": "vesc", "node_id": true}]',
     "scan.json: [0].node_id: expected a node ID (an integer >= 0), got True"),
])
def test_what_is_not_a_scan_is_refused_naming_the_entry(text: str, message: str) -> None:
    with pytest.raises(ConfigError, match=re.escape(message)):
        parse_scan(text, "scan.json")


# ----------------------------------------------------------------------------- assigning


def test_the_lowest_node_goes_to_the_first_wheel_and_the_file_says_so(tmp_path: Path) -> None:
    written = generate(EXAMPLES, "mecanum", "odrive", nodes("odrive", 12, 3, 7, 4), "scan.json")
    raw = yaml.safe_load(written.text)
    assert raw["motors"] == {"front_left": {"node_id": 3},
                             "front_right": {"node_id": 4, "invert": True},
                             "rear_left": {"node_id": 7},
                             "rear_right": {"node_id": 12, "invert": True}}
    assert [(a.block, a.driver, a.node_id) for a in written.assignments] == [
        ("motors.front_left", "odrive", 3), ("motors.front_right", "odrive", 4),
        ("motors.rear_left", "odrive", 7), ("motors.rear_right", "odrive", 12)]
    assert "  rear_left: {node_id: 7}       # from the scan: odrive node 7" in written.text
    head = " ".join(line.lstrip("# ") for line in written.text.split("\nname:")[0].splitlines())
    assert "Node IDs from the scan scan.json, in order: check each wheel's." in head
    (tmp_path / "robot.yaml").write_text(written.text)
    load_config(tmp_path / "robot.yaml")


def test_steering_actuators_of_the_motors_driver_take_the_nodes_after_theirs() -> None:
    found = nodes("odrive", *range(11, 19))
    written = generate(EXAMPLES, "swerve", None, found, "scan.json")
    raw = yaml.safe_load(written.text)
    assert [m["node_id"] for m in raw["motors"].values()] == [11, 12, 13, 14]
    assert [s["node_id"] for s in raw["steering"].values()] == [15, 16, 17, 18]


def test_each_driver_takes_its_own_nodes() -> None:
    found = [*nodes("vesc", 21, 20), *nodes("odrive", 5)]
    raw = yaml.safe_load(generate(EXAMPLES, "ackermann", None, found, "s").text)
    assert [m["node_id"] for m in raw["motors"].values()] == [20, 21]
    assert raw["steering"]["front_axle"]["node_id"] == 5


def test_a_generic_robots_driven_wheels_take_the_nodes_and_the_castor_none() -> None:
    written = generate(EXAMPLES, "differential_castor", None, nodes("odrive", 9, 6), "s")
    wheels = yaml.safe_load(written.text)["wheels"]
    assert [w.get("motor") for w in wheels] == [{"node_id": 6}, {"node_id": 9}, None]
    assert [a.block for a in written.assignments] == ["wheels[0].motor (left)",
                                                      "wheels[1].motor (right)"]
    assert "# from the scan: odrive node 6" in written.text


def test_nodes_of_a_driver_no_controller_uses_are_reported_not_given() -> None:
    found = [*nodes("dji", 1, 2, 3, 4), *nodes("cia402", 40)]
    written = generate(EXAMPLES, "mecanum", None, found, "s")
    assert written.unused == (FoundNode("cia402", 40),)


def test_too_few_or_too_many_nodes_are_refused_naming_the_controllers() -> None:
    with pytest.raises(ConfigError, match=re.escape(
            "scan.json: the scan found 3 odrive node(s) (1, 2, 3); expected 4, one per odrive "
            "controller (motors.front_left, motors.front_right, motors.rear_left, "
            "motors.rear_right)")):
        generate(EXAMPLES, "mecanum", "odrive", nodes("odrive", 1, 2, 3), "scan.json")
    with pytest.raises(ConfigError, match=re.escape("found 4 vesc node(s) (1, 2, 3, 4); "
                                                    "expected 2")):
        generate(EXAMPLES, "differential_tub", None, nodes("vesc", 1, 2, 3, 4), "scan.json")


def test_another_protocol_is_refused_with_the_driver_that_would_fit() -> None:
    with pytest.raises(ConfigError) as caught:
        generate(EXAMPLES, "mecanum", None, [*nodes("vesc", 1, 2, 3, 4), *nodes("cia402", 9)],
                 "scan.json")
    assert str(caught.value) == (
        "scan.json: the scan found no dji node; expected 4, one per dji controller "
        "(motors.front_left, motors.front_right, motors.rear_left, motors.rear_right); it found "
        "cia402 nodes 9; vesc nodes 1, 2, 3, 4 (--driver vesc puts the drive motors on those)")


def test_every_driver_that_does_not_fit_is_named_at_once() -> None:
    with pytest.raises(ConfigError) as caught:
        generate(EXAMPLES, "ackermann", None, nodes("vesc", 1), "s")
    lines = str(caught.value).splitlines()
    assert lines == [
        "s: the scan found 1 vesc node(s) (1); expected 2, one per vesc controller "
        "(motors.rear_left, motors.rear_right)",
        "s: the scan found no odrive node; expected 1, one per odrive controller "
        "(steering.front_axle)",
    ]


def test_an_empty_scan_says_nothing_answered() -> None:
    with pytest.raises(ConfigError, match=re.escape(
            "s: the scan found no vesc node; expected 2, one per vesc controller")):
        generate(EXAMPLES, "differential_tub", None, [], "s")


# ----------------------------------------------------------------------------- identifiers


def test_a_scans_29_bit_odrives_get_extended_id_and_the_file_loads_so(tmp_path: Path) -> None:
    """ODrive axes found on 29-bit identifiers (``"extended_id": true``) get ``extended_id:
    true`` in the blocks that take them: with the node ID alone the driver would talk 11-bit
    to them and the motors would never enable."""
    text = json.dumps([{**row("odrive", 2), "extended_id": True},
                       {**row("odrive", 1), "extended_id": True}])
    found = parse_scan(text, "scan.json")
    assert found == (FoundNode("odrive", 1, True), FoundNode("odrive", 2, True))
    written = generate(EXAMPLES, "turtlebot3_burger", None, found, "scan.json")
    assert yaml.safe_load(written.text)["motors"] == {
        "left": {"node_id": 1, "extended_id": True},
        "right": {"node_id": 2, "invert": True, "extended_id": True}}
    assert [a.address() for a in written.assignments] == [
        "odrive node 1 on 29-bit identifiers", "odrive node 2 on 29-bit identifiers"]
    assert "# from the scan: odrive node 1 on 29-bit identifiers" in written.text
    (tmp_path / "robot.yaml").write_text(written.text)
    cfg = load_config(tmp_path / "robot.yaml")
    assert [m.options["extended_id"] for m in cfg.motors if m is not None] == [True, True]


def test_11_bit_nodes_leave_the_block_as_it_was_and_a_29_bit_scan_overrides_a_default() -> None:
    written = generate(EXAMPLES, "turtlebot3_burger", None, nodes("odrive", 1, 2), "s")
    assert "extended_id" not in written.text
    # An example saying 29-bit in its defaults gets 11-bit nodes' blocks told otherwise.
    example = EXAMPLES["turtlebot3_burger"].replace("  driver: odrive\n", "  driver: odrive\n"
                                                    "  extended_id: true\n", 1)
    assert example != EXAMPLES["turtlebot3_burger"]
    written = generate({**EXAMPLES, "t": example}, "t", None, nodes("odrive", 1, 2), "s")
    raw = yaml.safe_load(written.text)
    assert [m["extended_id"] for m in raw["motors"].values()] == [False, False]
    # VESCs are 29-bit by their protocol: nothing to write.
    vescs = [FoundNode("vesc", 1, True), FoundNode("vesc", 2, True)]
    assert "extended_id" not in generate(EXAMPLES, "differential_tub", None, vescs, "s").text


def test_an_extended_id_that_is_not_a_boolean_is_refused() -> None:
    with pytest.raises(ConfigError, match=re.escape(
            "scan.json: [0].extended_id: expected true (29-bit identifiers) or false (11-bit), "
            "got 'yes'")):
        parse_scan('[{"driver": "odrive", "node_id": 1, "extended_id": "yes"}]', "scan.json")
