"""The kernel's own view of a SocketCAN interface (``gateway.bus.link``, through iproute2), on
the ``socketcan`` tier's vcan: up, down, no bit timing (a vcan has none: nothing to refuse)."""

from __future__ import annotations

import logging
import subprocess

import pytest

from gateway.bus.can_bus import open_bus
from gateway.bus.link import Link, read_link

pytestmark = [pytest.mark.socketcan, pytest.mark.timeout(120)]


def test_a_vcan_is_read_from_the_kernel_and_a_bus_down_is_told_how_to_come_up(
    vcan: str, caplog: pytest.LogCaptureFixture
) -> None:
    assert read_link(vcan) == Link(vcan, "vcan", True, None, None)
    subprocess.run(["ip", "link", "set", vcan, "down"], check=True, timeout=30)
    try:
        assert read_link(vcan) == Link(vcan, "vcan", False, None, None)
        with caplog.at_level(logging.WARNING, logger="gateway.bus"):
            bus = open_bus("socketcan", vcan, 1_000_000)  # (it opens: it may come up later)
        bus.shutdown()
    finally:
        subprocess.run(["ip", "link", "set", vcan, "up"], check=True, timeout=30)
    assert read_link(vcan) == Link(vcan, "vcan", True, None, None)
    assert [r.getMessage() for r in caplog.records] == [
        f"{vcan} is down: nothing can be sent until it is up (sudo ip link set {vcan} up)"]
