"""Driver registry: built-ins, entry-point plugins, clear errors."""

from __future__ import annotations

import importlib.metadata
import logging
from importlib.metadata import EntryPoint
from typing import TYPE_CHECKING

import pytest

from drivers import BUILTIN_DRIVERS
from gateway.core.errors import DriverNotFoundError
from gateway.drive import registry
from gateway.drive.driver import MotorDriver

if TYPE_CHECKING:
    from collections.abc import Iterator


@pytest.mark.parametrize("name", sorted(BUILTIN_DRIVERS))
def test_every_builtin_loads_and_has_a_simulator(name: str) -> None:
    cls = registry.get_driver_class(name)
    assert issubclass(cls, MotorDriver)
    assert name in registry.VALID_DRIVERS


def test_unknown_driver_lists_the_known_ones() -> None:
    with pytest.raises(DriverNotFoundError) as info:
        registry.get_driver_class("tesla")
    assert str(info.value) == (
        "Unknown driver 'tesla'; expected one of: cia402, dbc, dji, odrive, vesc"
    )
    assert isinstance(info.value, LookupError)


@pytest.fixture
def plugins(monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    eps = [
        EntryPoint("vesc_clone", "drivers.vesc:VescDriver", registry.ENTRY_POINT_GROUP),
        EntryPoint("broken", "no_such_module_xyz:Driver", registry.ENTRY_POINT_GROUP),
        EntryPoint("notadriver", "gateway.core.types:Frame", registry.ENTRY_POINT_GROUP),
    ]

    def fake(group: str) -> list[EntryPoint]:
        return eps if group == registry.ENTRY_POINT_GROUP else []

    monkeypatch.setattr(importlib.metadata, "entry_points", fake)  # imported when needed
    yield


@pytest.mark.usefixtures("plugins")
def test_entry_point_plugins(caplog: pytest.LogCaptureFixture) -> None:
    assert {"vesc_clone", "broken", "odrive"} <= registry.valid_drivers()
    from drivers.vesc import VescDriver

    assert registry.get_driver_class("vesc_clone") is VescDriver
    with caplog.at_level(logging.WARNING), pytest.raises(
        DriverNotFoundError, match=r"Driver plugin 'broken' \(no_such_module_xyz:Driver\) failed"
    ):
        registry.get_driver_class("broken")
    assert "driver plugin 'broken'" in caplog.text
    # A broken plugin never empties the registry.
    assert registry.get_driver_class("odrive").__name__ == "OdriveDriver"
    with pytest.raises(DriverNotFoundError, match="is not a MotorDriver subclass"):
        registry.get_driver_class("notadriver")
