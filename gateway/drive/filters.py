"""Which frames the gateway consumes, declared: kernel receive filters from the drivers' word.

Each driver states the identifiers it takes (:meth:`gateway.drive.driver.MotorDriver.
receive_filters`), and the gateway adds its own input (the twist command).  On SocketCAN the
bus is opened with these as ``CAN_RAW_FILTER`` (Linux ``Documentation/networking/can.rst``,
section "RAW Protocol Sockets with can_filters"; python-can ``can/interfaces/socketcan/
utils.py::pack_filters``), so foreign traffic never reaches the process: a busy bus costs the
loop nothing.  A filter matches a frame when ``(can_id ^ arbitration_id) & can_mask == 0`` and
the identifier types agree.  Error frames are not subject to these filters (the kernel delivers
them by their own error mask).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import TYPE_CHECKING

from gateway.core.errors import GatewayError

if TYPE_CHECKING:
    from collections.abc import Iterable

    from gateway.core.settings import GatewayConfig
    from gateway.drive.driveset import DriveSet

log = logging.getLogger(__name__)

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


def gateway_filters(config: GatewayConfig, drives: DriveSet) -> tuple[CanFilter, ...] | None:
    """Every identifier the gateway consumes: its drivers' feedback and replies
    (:meth:`~gateway.drive.driveset.DriveSet.receive_filters`) and, with ``gateway.can_input``, the
    twist command (``gateway.can_ids.twist``).

    :return: ``None`` when a driver does not declare what it takes (a plug-in written before
        the declaration): the bus is then opened unfiltered, and a warning names the driver.
    """
    declared = drives.receive_filters()
    if declared is None:
        log.warning("driver %s does not declare the CAN IDs it takes (receive_filters): the "
                    "bus is opened without kernel receive filters",
                    ", ".join(drives.undeclared()))
        return None
    ids = config.loop.can_ids
    if not config.loop.can_input:
        return declared
    twist = CanFilter.exact(ids.twist, ids.extended)
    return declared if twist in declared else (*declared, twist)


def own_id_collisions(config: GatewayConfig, drives: DriveSet) -> list[str]:
    """The gateway's own messages (``gateway.can_ids``) whose identifier a controller also
    uses: one it sends (its filters) or one the gateway sends it (the enable, poll, disable
    and command frames of a fresh driver for that motor alone).  A twist input on a
    controller's ID would take that controller's frames for twists; an odometry frame on it
    would reach the controller as a command.

    :return: one sentence per collision, naming both sides.
    """
    ids = config.loop.can_ids
    own = {name: getattr(ids, name) for name in ("twist", "odom_pose", "odom_velocity",
                                                   "status", "error")}
    out = []
    for drv, _ in drives.groups:
        for motor in drv.motors:
            # A driver of this motor alone: its filters and frames are this controller's.
            single = type(drv)([motor])
            filters = single.receive_filters() or ()
            try:
                sent = {(f.arbitration_id, f.is_extended_id) for f in (
                    *single.enable(0.0), *single.poll(0.0), *single.disable(0.0),
                    *single.preview_command([0.0]))}
            except GatewayError:  # a driver that needs answers first: its filters still count
                sent = set()
            hits = [f"{key} 0x{can_id:X}" for key, can_id in own.items()
                    if any(f.matches(can_id, ids.extended) for f in filters)
                    or (can_id, ids.extended) in sent]
            if hits:
                out.append(f"gateway.can_ids {', '.join(hits)}: also identifiers of the "
                           f"{motor.driver} controller of {motor.wheel!r} (node {motor.node_id})")
    return out
