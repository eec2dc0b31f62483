"""Which frames the gateway consumes, declared: kernel receive filters from the drivers' word.

Each driver states the identifiers it takes (its claims, :mod:`gateway.drive.claims`), and the
gateway adds its own input (the twist command, :func:`gateway.drive.ownership.gateway_filters`).
On SocketCAN the bus is opened with these as ``CAN_RAW_FILTER`` (Linux
``Documentation/networking/can.rst``, section "RAW Protocol Sockets with can_filters";
python-can ``can/interfaces/socketcan/utils.py::pack_filters``), so foreign traffic never
reaches the process: a busy bus costs the loop nothing.
A filter matches a frame when ``(can_id ^ arbitration_id) & can_mask == 0`` and
the identifier types agree.  Error frames are not subject to these filters (the kernel delivers
them by their own error mask).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from collections.abc import Iterable



#: The mask of an exact 11-bit / 29-bit identifier.
STD_MASK = 0x7FF
EXT_MASK = 0x1FFFFFFF


@dataclass(frozen=True, slots=True)
class CanFilter:
    """One receive filter.

    :param can_id: the identifier bits to match.
    :param can_mask: which bits of the identifier must match.
    :param extended: the identifier type (29-bit when true).
    """

    can_id: int
    can_mask: int
    extended: bool

    @classmethod
    def exact(cls, can_id: int, extended: bool) -> CanFilter:
        """A filter for exactly one identifier."""
        return cls(can_id, EXT_MASK if extended else STD_MASK, extended)

    def matches(self, arbitration_id: int, is_extended_id: bool) -> bool:
        """Whether a frame with this identifier and identifier type passes (data and remote
        frames alike: python-can leaves the RTR bit out of the kernel's mask)."""
        return (is_extended_id == self.extended
                and not (self.can_id ^ arbitration_id) & self.can_mask)

    def as_python_can(self) -> dict[str, int | bool]:
        """The filter as python-can's ``can_filters`` takes it."""
        return {"can_id": self.can_id, "can_mask": self.can_mask, "extended": self.extended}

    def __str__(self) -> str:
        width = 8 if self.extended else 3
        return f"{self.can_id:0{width}X}/{self.can_mask:0{width}X}{'x' if self.extended else ''}"


def matches_any(filters: Iterable[CanFilter], arbitration_id: int, is_extended_id: bool) -> bool:
    """Whether a frame passes any of ``filters``."""
    return any(f.matches(arbitration_id, is_extended_id) for f in filters)
