"""The identifiers of one robot's bus, from the drivers' claims and ``gateway.can_ids``: the
kernel receive filters the gateway opens its bus with, and the collisions between the gateway's
own messages and its controllers' frames that the configuration refuses."""

from __future__ import annotations

from typing import TYPE_CHECKING

from gateway.drive.filters import CanFilter

if TYPE_CHECKING:
    from gateway.core.settings import GatewayConfig
    from gateway.drive.driveset import DriveSet


def gateway_filters(config: GatewayConfig, drives: DriveSet) -> tuple[CanFilter, ...]:
    """Every identifier the gateway consumes: what its drivers claim to take
    (:meth:`~gateway.drive.driveset.DriveSet.receive_filters`) and, with ``gateway.can_input``,
    the twist command (``gateway.can_ids.twist``)."""
    declared = drives.receive_filters()
    ids = config.loop.can_ids
    if not config.loop.can_input:
        return declared
    twist = CanFilter.exact(ids.twist, ids.extended)
    return declared if twist in declared else (*declared, twist)


def own_id_collisions(config: GatewayConfig, drives: DriveSet) -> list[str]:
    """The gateway's own messages (``gateway.can_ids``) whose identifier a controller also
    uses: one its driver claims, sent or received (:mod:`gateway.drive.claims`).  A twist input
    on a controller's ID would take that controller's frames for twists; an odometry frame on
    it would reach the controller as a command.

    :return: one sentence per collision, naming both sides.
    """
    ids = config.loop.can_ids
    own = {name: getattr(ids, name) for name in ("twist", "odom_pose", "odom_velocity",
                                                   "status", "error")}
    out = []
    for drv, _ in drives.groups:
        claims = drv.claims()
        for i, motor in enumerate(drv.motors):
            mine = [c for c in claims if c.motor in (i, None)]
            hits = [f"{key} 0x{can_id:X}" for key, can_id in own.items()
                    if any(c.matches(can_id, ids.extended) for c in mine)]
            if hits:
                out.append(f"gateway.can_ids {', '.join(hits)}: also identifiers of the "
                           f"{motor.driver} controller of {motor.wheel!r} (node {motor.node_id})")
    return out
