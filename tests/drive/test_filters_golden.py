"""The receive filters each driver declares, golden: the filters of each shipped robot, of a robot
of two protocols, and ``CanFilter``'s semantics; and the gateway's own IDs, which must not be a
controller's."""

from __future__ import annotations

from typing import TYPE_CHECKING

import pytest
import yaml

from gateway.config import load_config
from gateway.core.errors import ConfigError
from gateway.drive.driveset import DriveSet
from gateway.drive.filters import CanFilter, matches_any
from gateway.drive.ownership import gateway_filters
from tests.conftest import CONFIG_DIR, REPO
from tests.drive.filter_helpers import ODRIVE_EXTENDED, Ident, config, declared, drivers

if TYPE_CHECKING:
    from pathlib import Path


# ----------------------------------------------------------------------------- golden


@pytest.mark.parametrize(("name", "expected"), [
    (None, ["020/7E0", "040/7E0", "060/7E0", "080/7E0"]),
    (ODRIVE_EXTENDED, ["00204060/1FFFFFE0x", "00000040/1FFFFFE0x", "00000060/1FFFFFE0x",
                       "00000080/1FFFFFE0x"]),
    ("skid_steer.yaml", [
        *(f"0000{packet:02X}{node:02X}/1FFFFFFFx" for node in (1, 2, 3, 4)
          for packet in (9, 14, 15, 16, 27, 58)),
        "00001200/1FFFFF00x",
        # The app configuration's read-back (FILL_RX_BUFFER, _LONG, PROCESS_RX_BUFFER,
        # PROCESS_SHORT_BUFFER) to the gateway's own ID 254.
        *(f"00000{packet}FE/1FFFFFFFx" for packet in (5, 6, 7, 8)),
    ]),
    ("synchro.yaml", [f"{base + node:03X}/7FF" for base in (0x80, 0x380, 0x480, 0x580, 0x700)
                      for node in (1, 2, 3, 4)]),
    ("mecanum.yaml", ["201/7FF", "202/7FF", "203/7FF", "204/7FF"]),
    ("example_dbc.yaml", ["281/7FF", "282/7FF"]),
])
def test_golden_filters_of_each_driver(name: str | None, expected: list[str]) -> None:
    (drv,) = drivers(name)
    assert [str(f) for f in declared(drv)] == expected


def test_golden_filters_of_the_default_robot() -> None:
    cfg = config(None)
    drives = DriveSet(cfg)
    filters = gateway_filters(cfg, drives)
    assert filters is not None
    assert [str(f) for f in filters] == ["020/7E0", "040/7E0", "060/7E0", "080/7E0", "100/7FF"]
    assert filters[:-1] == drives.receive_filters()
    assert filters[0].as_python_can() == {"can_id": 0x20, "can_mask": 0x7E0, "extended": False}


def test_a_robot_of_two_protocols_declares_both() -> None:
    cfg = config("ackermann.yaml")
    filters = DriveSet(cfg).receive_filters()
    assert filters is not None
    assert "060/7E0" in map(str, filters)  # the ODrive steering actuator, node 3
    assert matches_any(filters, 9 << 8 | 1, True)  # STATUS of VESC 1
    assert not matches_any(filters, 9 << 8 | 1, False)


@pytest.mark.parametrize(("name", "foreign"), [
    (None, [(5 << 5 | 0x09, False), (0x009, False), (1 << 5 | 0x09, True)]),  # other nodes, type
    ("skid_steer.yaml", [(9 << 8 | 5, True), (9 << 8 | 1, False), (1 << 16 | 9 << 8 | 1, True),
                         (3 << 8 | 1, True)]),  # another master's SET_RPM to our VESC 1
    ("synchro.yaml", [(0x185, False), (0x705, False), (0x181, True), (0x601, False)]),
    ("mecanum.yaml", [(0x205, False), (0x201, True), (0x200, False)]),
    ("example_dbc.yaml", [(0x283, False), (0x281, True)]),
])
def test_the_filters_keep_out_other_nodes_and_types(name: str | None,
                                                    foreign: list[Ident]) -> None:
    cfg = config(name)
    filters = gateway_filters(cfg, DriveSet(cfg))
    assert filters is not None
    for can_id, extended in foreign:
        assert not matches_any(filters, can_id, extended), (hex(can_id), extended)


def test_can_filter_semantics() -> None:
    f = CanFilter(0x120, 0x7E0, False)
    assert f.matches(0x13F, False) and not f.matches(0x140, False)
    assert not f.matches(0x120, True)  # the identifier type must agree
    assert CanFilter.exact(0x123, True) == CanFilter(0x123, 0x1FFFFFFF, True)
    assert str(CanFilter.exact(0x123, True)) == "00000123/1FFFFFFFx"


# ----------------------------------------------------------------------------- the gateway


def test_no_twist_filter_without_can_input(tmp_path: Path) -> None:
    path = tmp_path / "r.yaml"
    path.write_text((CONFIG_DIR / "mecanum.yaml").read_text() + "\ngateway:\n  can_input: false\n")
    cfg = load_config(path)
    filters = gateway_filters(cfg, DriveSet(cfg))
    assert filters is not None and CanFilter.exact(0x100, False) not in filters
    assert filters == DriveSet(cfg).receive_filters()


def test_own_ids_that_are_a_controllers_are_refused(tmp_path: Path) -> None:
    path = tmp_path / "r.yaml"
    text = (REPO / "gateway" / "data" / "default.yaml").read_text()
    path.write_text(text + "gateway:\n  can_ids: {twist: 0x21}\n")
    with pytest.raises(ConfigError) as err:
        load_config(path)
    assert ("gateway.can_ids twist 0x21: also identifiers of the odrive controller of "
            "'front_left' (node 1)") in str(err.value)
    # An ID the gateway sends a controller counts too: a CiA 402 drive's command RPDO.
    path.write_text((CONFIG_DIR / "synchro.yaml").read_text()
                    + "\ngateway:\n  can_ids: {status: 0x501}\n")
    with pytest.raises(ConfigError, match=r"status 0x501: also identifiers of the cia402 "):
        load_config(path)


def test_identifiers_two_protocols_share_are_refused(tmp_path: Path) -> None:
    """ODrive node N owns 0x20*N to 0x20*N+0x1F: CiA 402 steering drives on nodes 5 to 9 send
    their EMCY (0x080 + node) inside ODrive node 4's identifiers, and their SYNC (0x080) is that
    node's command 0.  On the bus the ODrive driver would take a steering drive's EMCY for its
    wheel's encoder estimate (0x089 is node 4's Get_Encoder_Estimates)."""
    raw = yaml.safe_load((CONFIG_DIR / "swerve.yaml").read_text())
    raw["steering_defaults"] = {"driver": "cia402", "gear_ratio": 12.8, "max_rpm": 3000,
                                "sync": True}
    raw["steering"] = {wheel: {"node_id": node} for wheel, node in (
        ("front_left", 5), ("front_right", 6), ("rear_left", 7), ("rear_right", 9))}
    path = tmp_path / "r.yaml"
    path.write_text(yaml.safe_dump(raw))
    with pytest.raises(ConfigError) as err:
        load_config(path)
    text = str(err.value)
    assert ("the odrive controller of 'rear_right' (node 4) and the cia402 controller of "
            "'rear_right steering' (node 9) both use 11-bit identifier 0x89") in text
    assert ("the odrive controller of 'rear_right' (node 4) and the cia402 driver's broadcast "
            "frames both use 11-bit identifier 0x80") in text
    assert text.endswith("choose other node IDs")
