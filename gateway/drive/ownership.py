"""The identifiers of one robot's bus, from the drivers' claims and ``gateway.can_ids``: the
kernel receive filters the gateway opens its bus with, and the collisions between the gateway's
own messages and its controllers' frames that the configuration refuses."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from gateway.drive.filters import EXT_MASK, STD_MASK, CanFilter

if TYPE_CHECKING:
    from collections.abc import Iterable

    from gateway.core.settings import GatewayConfig
    from gateway.drive.claims import FrameClaim
    from gateway.drive.driver import MotorDriver
    from gateway.drive.driveset import DriveSet


def gateway_filters(config: GatewayConfig, drives: DriveSet,
                    watched: Iterable[tuple[int, bool]] = ()) -> tuple[CanFilter, ...]:
    """Every identifier the gateway consumes: what its drivers claim to take
    (:meth:`~gateway.drive.driveset.DriveSet.receive_filters`), with ``gateway.can_input``
    the twist command (``gateway.can_ids.twist``), and the identifiers ``watched`` (its own
    frames, heard only when another sends them: :mod:`gateway.runtime.commanders`)."""
    declared = drives.receive_filters()
    ids = config.loop.can_ids
    twist = ((ids.twist, ids.extended),) if config.loop.can_input else ()
    more = (CanFilter.exact(i, e) for i, e in (*twist, *watched))
    return tuple(dict.fromkeys((*declared, *more)))


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


def driver_collisions(drives: DriveSet) -> list[str]:
    """Identifiers that controllers of two protocols both use: a claim of one driver, sent or
    received, that matches some identifier of another's (:mod:`gateway.drive.claims`).  On
    the bus, one controller's frames would reach the other as commands, and the gateway would
    give them to the first claimant as its motor's feedback (a CiA 402 EMCY at 0x089 is an
    ODrive node 4 ``Get_Encoder_Estimates``).

    :return: one sentence per pair of colliding claims, naming both motors.
    """
    groups = [(drv, drv.claims()) for drv, _ in drives.groups]
    return [f"{_whose(a, ca.motor)} and {_whose(b, cb.motor)} both use {_ids(ca, cb)}"
            for k, (a, a_claims) in enumerate(groups) for b, b_claims in groups[k + 1:]
            for ca in a_claims for cb in b_claims if ca.overlaps(cb)]


def _whose(drv: MotorDriver[Any], motor: int | None) -> str:
    if motor is None:
        return f"the {drv.motors[0].driver} driver's broadcast frames"
    m = drv.motors[motor]
    return f"the {m.driver} controller of {m.wheel!r} (node {m.node_id})"


def _ids(a: FrameClaim, b: FrameClaim) -> str:
    """The identifiers two overlapping claims share, as a value/mask pair or one ID."""
    mask = a.mask | b.mask
    can_id = (a.can_id & a.mask) | (b.can_id & b.mask)
    kind = "29-bit" if a.extended else "11-bit"
    full = EXT_MASK if a.extended else STD_MASK
    if mask & full == full:
        return f"{kind} identifier 0x{can_id:X}"
    return f"{kind} identifiers 0x{can_id:X} under mask 0x{mask & full:X}"
