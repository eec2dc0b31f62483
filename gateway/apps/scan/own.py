"""The frames a scan names as the gateway's own (``wheelgate`` rows), from a configuration.

* Its five messages at ``gateway.can_ids`` (their DBC names, :mod:`gateway.wire.can`), always:
  a gateway's pose on 0x101 is where an ODrive at node 8 would send its heartbeat;
* with ``drivers``, the frames the configured drivers send to all their controllers at once
  (the claims a driver makes with no motor, :meth:`~gateway.drive.driver.MotorDriver.claims`):
  CiA 402's NMT, SYNC and the gateway's own heartbeat (as node ``host_node_id``, which would
  otherwise look like a CANopen node that answers no SDO), DJI's command frames.
"""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING

from gateway.core.errors import GatewayError
from gateway.drive.driveset import DriveSet
from gateway.drive.labels import DRIVER_TITLES, OWN_MESSAGES

if TYPE_CHECKING:
    from gateway.core.settings import GatewayConfig

log = logging.getLogger(__name__)


def own_messages(config: GatewayConfig, drivers: bool) -> dict[tuple[int, bool], str]:
    """``(identifier, extended)`` -> name of the frames the gateway of ``config`` sends
    (see the module)."""
    ids = config.loop.can_ids
    out = {(getattr(ids, key), ids.extended): name for key, name in OWN_MESSAGES.items()}
    if not drivers:
        return out
    try:
        groups = DriveSet(config).groups
    except GatewayError as err:
        log.warning("scan: cannot name the drivers' frames: %s", err)
        return out
    for drv, _ in groups:
        name = drv.motors[0].driver
        title = DRIVER_TITLES.get(name, name)
        for claim in drv.claims():
            if claim.receive or claim.motor is not None:
                continue
            for ident in claim.identifiers() or ():
                message = drv.message_name(ident, claim.extended) or f"0x{ident:X}"
                out.setdefault((ident, claim.extended), f"{title} {message}")
    return out
