"""A configuration against its bus: the bitrate its controllers talk at, and the load its
frames put on the bus (:mod:`gateway.drive.traffic`), for ``wheelgate check`` and ``run``.

The gateway's own periodic frames join the drivers' streams: ``WG_Odom_Pose`` and
``WG_Odom_Velocity`` at ``gateway.odom_rate_hz`` and ``WG_Status`` at
``gateway.status_rate_hz`` (8 bytes each; :mod:`gateway.wire.can`).  A pilot's
``WG_Twist_Cmd`` comes at the pilot's own rate and is not counted.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from gateway.core.errors import ConfigError
from gateway.drive.traffic import FULL_PERCENT, HIGH_PERCENT, BusBudget, Sender, Stream

if TYPE_CHECKING:
    from gateway.core.settings import GatewayConfig
    from gateway.drive.driveset import DriveSet

__all__ = ["bus_budget", "check_bus"]


def bus_budget(config: GatewayConfig, drives: DriveSet, rate_hz: float | None = None
               ) -> BusBudget:
    """Every periodic frame of this configuration against ``bus.bitrate`` (at the loop rate
    ``rate_hz``, else ``gateway.rate_hz``)."""
    loop = config.loop
    traffic = drives.traffic(rate_hz)
    ext = loop.can_ids.extended
    own = (
        Stream("WG_Odom_Pose", Sender.GATEWAY, loop.odom_rate_hz, 8, ext,
               f"gateway.odom_rate_hz {loop.odom_rate_hz:g}"),
        Stream("WG_Odom_Velocity", Sender.GATEWAY, loop.odom_rate_hz, 8, ext,
               f"gateway.odom_rate_hz {loop.odom_rate_hz:g}"),
        Stream("WG_Status", Sender.GATEWAY, loop.status_rate_hz, 8, ext,
               f"gateway.status_rate_hz {loop.status_rate_hz:g}"),
    )
    return BusBudget((*traffic.streams, *own), config.bus.bitrate, traffic.unknown)


def check_bus(config: GatewayConfig, drives: DriveSet) -> list[str]:
    """The bitrate and the bus load of ``config`` (see the module docstring).

    :return: warnings: a load above :data:`~gateway.drive.traffic.HIGH_PERCENT` with worst-case
        bit stuffing.
    :raises ConfigError: for a bitrate some controllers cannot talk at, or periodic frames
        that need the whole bus without stuff bits (they could not all go out).
    """
    where, bitrate = f"{config.source}: bus.bitrate", config.bus.bitrate
    for drv, _ in drives.groups:
        if drv.BITRATES and bitrate not in drv.BITRATES:
            rates = " or ".join(f"{r} bit/s" for r in drv.BITRATES)
            raise ConfigError(f"{where}: expected {rates}, the only bitrate of the "
                              f"{drv.PROTOCOL} controllers (fixed in them), got {bitrate}")
    budget = bus_budget(config, drives)
    if not budget.high():
        return []
    top = _top_rate(config, drives, budget, HIGH_PERCENT)
    if budget.full():
        raise ConfigError(
            f"{where}: the configuration's periodic frames need {budget.load():.1f} % of the "
            f"{bitrate / 1000:g} kbit/s bus without a single stuff bit "
            f"({budget.load(worst_case=True):.1f} % with the most), so they could not all be "
            f"sent ({budget.brief()}; the controllers' at their firmware's defaults or as "
            f"stated); expected under {FULL_PERCENT:g} %: " + _fixes(top))
    return [f"{where}: the configuration's periodic frames need {budget.summary()}, above "
            f"{HIGH_PERCENT:g} % with worst-case bit stuffing: the frames of the highest "
            f"identifiers wait for arbitration and error frames have no room; fix: "
            + _fixes(top) + " (`wheelgate check` lists every stream)"]


def _fixes(top_rate_hz: float) -> str:
    return ((f"gateway.rate_hz below {top_rate_hz:.0f}, " if top_rate_hz >= 1.0 else "")
            + "lower feedback rates, a higher bitrate (every node of the bus set to it), or "
            "the motors over two buses")


def _top_rate(config: GatewayConfig, drives: DriveSet, budget: BusBudget, percent: float
              ) -> float:
    """The loop rate at which the declared streams would need ``percent`` of the bus (worst
    case): the load is linear in the rate, so the budget at twice the rate gives it."""
    rate = config.loop.rate_hz
    here = budget.load(worst_case=True)
    per_hz = (bus_budget(config, drives, 2.0 * rate).load(worst_case=True) - here) / rate
    return (percent - (here - per_hz * rate)) / per_hz if per_hz > 0.0 else 0.0
