"""The frames a scan names as the gateway's own (``wheelgate`` rows), from a configuration.

* Its five messages at ``gateway.can_ids`` (their DBC names, :mod:`gateway.wire.can`), always:
  a gateway's pose on 0x101 is where an ODrive at node 8 would send its heartbeat;
* with ``drivers``, the frames the configured drivers send to all their controllers at once
  (the claims a driver makes with no motor, :meth:`~gateway.drive.driver.MotorDriver.claims`):
  CiA 402's NMT, SYNC and the gateway's own heartbeat (as node ``host_node_id``, which would
  otherwise look like a CANopen node that answers no SDO), DJI's command frames;
* with ``drivers``, per configured motor, every frame its driver declares as that motor's
  (:func:`motor_claims`): the scan attributes what it hears there to the motor and never
  offers it to another protocol's probe (a DBC controller's feedback at 0x281 would otherwise
  look like the heartbeat of ODrive node 20).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import TYPE_CHECKING

from gateway.core.errors import GatewayError
from gateway.drive.driveset import DriveSet
from gateway.drive.labels import DRIVER_TITLES, OWN_MESSAGES

if TYPE_CHECKING:
    from gateway.core.settings import GatewayConfig
    from gateway.core.types import MotorConfig
    from gateway.drive.claims import FrameClaim

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


@dataclass(frozen=True, slots=True)
class MotorClaims:
    """The frames a configured motor's driver declares as that motor's (its controller's
    feedback, the commands to it: :meth:`~gateway.drive.driver.MotorDriver.claims`)."""

    motor: MotorConfig
    claims: tuple[FrameClaim, ...]

    def owns(self, arbitration_id: int, extended: bool) -> bool:
        """Whether a frame with this identifier is one of the motor's."""
        return any(c.matches(arbitration_id, extended) for c in self.claims)


def motor_claims(config: GatewayConfig) -> tuple[MotorClaims, ...]:
    """Every drive motor's and steering actuator's frames, as its driver declares them (none
    when the drivers cannot be built: a warning says why)."""
    try:
        groups = DriveSet(config).groups
    except GatewayError as err:
        log.warning("scan: cannot name the motors' frames: %s", err)
        return ()
    out = []
    for drv, _ in groups:
        claims = drv.claims()
        for i, motor in enumerate(drv.motors):
            mine = tuple(c for c in claims if c.motor == i)
            if mine:
                out.append(MotorClaims(motor, mine))
    return tuple(out)
