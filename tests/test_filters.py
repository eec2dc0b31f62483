"""The identifiers each driver declares it takes: what the kernel's receive filters let
through must be everything the driver would take, and little else; the gateway's own IDs must
not be a controller's."""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gateway.config import load_config
from gateway.driver import MotorDriver
from gateway.drives import DriveSet
from gateway.errors import ConfigError
from gateway.filters import CanFilter, gateway_filters, matches_any
from gateway.types import Frame
from tests.conftest import CONFIG_DIR
from tests.e2e_helpers import Rig, virtual_config

if TYPE_CHECKING:
    from pathlib import Path

    from gateway.config import GatewayConfig

CONFIGS = [None, *sorted(p.name for p in CONFIG_DIR.glob("*.yaml"))]


def config(name: str | None) -> GatewayConfig:
    return load_config(None if name is None else CONFIG_DIR / name)


@pytest.mark.parametrize("name", CONFIGS)
@settings(max_examples=300, deadline=None)
@given(arb=st.integers(0, 0x1FFFFFFF), extended=st.booleans(), size=st.integers(0, 8),
       remote=st.booleans())
def test_every_frame_a_driver_takes_passes_its_filters(
    name: str | None, arb: int, extended: bool, size: int, remote: bool
) -> None:
    if not extended:
        arb &= 0x7FF
    frame = Frame(arb, bytes(size), extended, remote, size)
    for drv, _ in DriveSet(config(name)).groups:
        filters = drv.receive_filters()
        assert filters is not None
        if drv.on_frame(frame):
            assert matches_any(filters, arb, extended), (type(drv).__name__, frame, filters)


@pytest.mark.parametrize("name", CONFIGS)
def test_what_the_simulated_controllers_send_passes_the_filters(
    name: str | None, channel: str
) -> None:
    cfg = virtual_config(None if name is None else CONFIG_DIR / name, channel, rate_hz=100.0)
    with Rig(cfg) as rig:
        rig.enable()
        rig.advance(0.5)
        filters = rig.gw.receive_filters
        assert filters is not None
        sent_by_gateway = {(i, e) for (i, e, tx) in rig.gw.id_counts if tx}
        from gateway.bus import drain

        from_devices = {(f.arbitration_id, f.is_extended_id) for f in drain(rig.pilot)
                        } - sent_by_gateway
        assert from_devices  # the devices did talk
        for can_id, extended in from_devices:
            assert matches_any(filters, can_id, extended), (hex(can_id), extended, filters)


@pytest.mark.parametrize(("name", "foreign"), [
    (None, [(5 << 5 | 0x09, False), (0x009, False)]),  # ODrive node 5, node 0
    ("skid_steer.yaml", [(9 << 8 | 5, True), (9 << 8 | 1, False), (1 << 16 | 9 << 8 | 1, True)]),
    ("synchro.yaml", [(0x185, False), (0x705, False), (0x181, True)]),
    ("mecanum.yaml", [(0x205, False), (0x201, True)]),
    ("example_dbc.yaml", [(0x283, False)]),
])
def test_the_filters_keep_out_other_nodes(name: str | None, foreign: list[tuple[int, bool]]
                                          ) -> None:
    cfg = config(name)
    filters = gateway_filters(cfg, DriveSet(cfg))
    assert filters is not None
    for can_id, extended in foreign:
        assert not matches_any(filters, can_id, extended), (hex(can_id), extended)


def test_golden_filters_of_the_default_robot() -> None:
    cfg = config(None)
    filters = gateway_filters(cfg, DriveSet(cfg))
    assert filters is not None
    assert [str(f) for f in filters] == ["020/7E0", "040/7E0", "060/7E0", "080/7E0", "100/7FF"]
    assert filters[0].as_python_can() == {"can_id": 0x20, "can_mask": 0x7E0, "extended": False}


def test_an_undeclared_driver_opens_the_bus_unfiltered_with_a_warning(
    monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    cfg = config(None)
    drives = DriveSet(cfg)
    monkeypatch.setattr(type(drives.groups[0][0]), "receive_filters", MotorDriver.receive_filters)
    with caplog.at_level(logging.WARNING, logger="gateway.filters"):
        assert gateway_filters(cfg, drives) is None
    assert "OdriveDriver does not declare the CAN IDs it takes" in caplog.text


def test_no_twist_filter_without_can_input(tmp_path: Path) -> None:
    path = tmp_path / "r.yaml"
    path.write_text((CONFIG_DIR / "mecanum.yaml").read_text() + "\ngateway:\n  can_input: false\n")
    cfg = load_config(path)
    filters = gateway_filters(cfg, DriveSet(cfg))
    assert filters is not None and CanFilter.exact(0x100, False) not in filters


def test_own_ids_that_are_a_controllers_are_refused(tmp_path: Path) -> None:
    path = tmp_path / "r.yaml"
    text = (CONFIG_DIR.parent / "gateway" / "data" / "default.yaml").read_text()
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
