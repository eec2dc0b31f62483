"""Fixtures of the tools' tests."""

from __future__ import annotations

from typing import TYPE_CHECKING

import can
import pytest

if TYPE_CHECKING:
    from collections.abc import Iterator


@pytest.fixture
def buses(channel: str) -> Iterator[tuple[can.BusABC, can.BusABC]]:
    """The anchor's bus and another on the same virtual channel."""
    a = can.Bus(interface="virtual", channel=channel)
    b = can.Bus(interface="virtual", channel=channel)
    yield a, b
    a.shutdown()
    b.shutdown()
