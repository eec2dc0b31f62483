"""Names for the frames on a robot's bus, for ``wheelgate monitor`` and fault messages.

A frame is named once per (ID, ID type, remote) and the name is cached, so naming costs nothing
per frame.  The facts come from where they are declared:

* the gateway's own messages: ``gateway.can_ids`` of the configuration and the message names
  of ``config/wheelgate.dbc`` (:mod:`gateway.wire.can`);
* the drivers' frames: the claims every driver makes for its motors
  (:meth:`~gateway.drive.driver.MotorDriver.claims`), the same declaration that dispatches
  received frames and sets the kernel's receive filters; a frame of several motors of one
  protocol (a DJI command for four ESCs, a CANopen SYNC) names the protocol and every wheel,
  without a node;
* the message name inside the protocol: the driver's
  :meth:`~gateway.drive.driver.MotorDriver.message_name`.  Unknown IDs are named by their hex ID.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from gateway.core.errors import GatewayError
from gateway.core.types import Frame
from gateway.drive.driveset import DriveSet
from gateway.wire.can import ERROR, ODOM_POSE, ODOM_VELOCITY, STATUS, TWIST_CMD

if TYPE_CHECKING:
    from gateway.core.settings import GatewayConfig
    from gateway.core.types import MotorConfig
    from gateway.drive.claims import FrameClaim
    from gateway.drive.driver import MotorDriver

log = logging.getLogger(__name__)

#: How the built-in protocols are written in labels (others: their config name).
DRIVER_TITLES = {"odrive": "ODrive", "vesc": "VESC", "cia402": "CiA 402", "dji": "DJI",
                 "dbc": "DBC"}
#: ``gateway.can_ids`` key -> message name in ``config/wheelgate.dbc``.
OWN_MESSAGES = {"twist": TWIST_CMD, "odom_pose": ODOM_POSE, "odom_velocity": ODOM_VELOCITY,
                "status": STATUS, "error": ERROR}
#: Label source of the gateway's own messages.
GATEWAY = "wheelgate"


@dataclass(frozen=True, slots=True)
class FrameLabel:
    """What a frame is.

    :param text: the whole label, e.g. ``"ODrive node 3 Get_Encoder_Estimates (rear_left)"``.
    :param source: ``"wheelgate"``, a driver's config name, or ``None`` when unknown.
    :param node_id: the controller's node ID when one motor owns the frame.
    :param message: the message name inside the protocol, when known.
    :param wheels: the wheels whose motors own the frame.
    """

    text: str
    source: str | None = None
    node_id: int | None = None
    message: str | None = None
    wheels: tuple[str, ...] = ()


class FrameLabeler:
    """Names frames of one configured robot.

    :param config: the robot's configuration (motors and ``gateway.can_ids``).
    """

    def __init__(self, config: GatewayConfig) -> None:
        ids = config.loop.can_ids
        self._own = {(getattr(ids, key), ids.extended): name for key, name in OWN_MESSAGES.items()}
        self._drivers: list[MotorDriver[Any]] = []
        try:
            self._drivers = [drv for drv, _ in DriveSet(config).groups]
        except GatewayError as err:
            log.warning("monitor: cannot name the drivers' frames: %s", err)
        #: Every claim of every driver, sent and received, in driver order.
        self._claims: list[tuple[FrameClaim, MotorDriver[Any]]] = [
            (claim, drv) for drv in self._drivers for claim in drv.claims()
        ]
        self._cache: dict[tuple[int, bool, bool], FrameLabel] = {}

    def probes(self) -> list[tuple[MotorConfig, MotorDriver[Any]]]:
        """(motor, its driver) for every configured motor whose driver could be loaded."""
        return [(m, drv) for drv in self._drivers for m in drv.motors]

    def label(self, frame: Frame) -> FrameLabel:
        """The label of ``frame`` (cached per ID, ID type and remote flag)."""
        key = (frame.arbitration_id, frame.is_extended_id, frame.is_remote_frame)
        found = self._cache.get(key)
        if found is None:
            found = self._cache[key] = self._describe(*key)
        return found

    def label_id(self, arbitration_id: int, extended: bool) -> FrameLabel:
        """The label of a data frame known only by its ID (the daemon's counts)."""
        return self.label(Frame(arbitration_id, bytes(8), extended))

    def _describe(self, arbitration_id: int, extended: bool, remote: bool) -> FrameLabel:
        rtr = " RTR" if remote else ""
        own = self._own.get((arbitration_id, extended))
        if own is not None:
            return FrameLabel(f"{own}{rtr}", GATEWAY, None, own)
        matching = [(c, d) for c, d in self._claims if c.matches(arbitration_id, extended)]
        if not matching:
            return FrameLabel(_hex(arbitration_id, extended) + rtr)
        drv = matching[0][1]
        claims = [c for c, d in matching if d is drv]
        if any(c.motor is None for c in claims):
            motors = list(drv.motors)
        else:
            owned = sorted({c.motor for c in claims if c.motor is not None})
            motors = [drv.motors[i] for i in owned]
        node = motors[0].node_id if len(motors) == 1 else None
        driver = drv.motors[0].driver
        message = drv.message_name(arbitration_id, extended)
        wheels = tuple(m.wheel for m in motors)
        parts = [DRIVER_TITLES.get(driver, driver)]
        if node is not None:
            parts.append(f"node {node}")
        if message:
            parts.append(message + rtr)
        elif rtr:
            parts.append(rtr.strip())
        parts.append(f"({', '.join(wheels)})")
        return FrameLabel(" ".join(parts), driver, node, message, wheels)


def _hex(arbitration_id: int, extended: bool) -> str:
    width = 8 if extended else 3
    return f"0x{arbitration_id:0{width}X}"
