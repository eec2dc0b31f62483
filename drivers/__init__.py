"""Built-in motor-controller drivers, one protocol per module.

:data:`BUILTIN_DRIVERS` maps a config ``driver:`` name to ``(module, class)``; classes are
imported lazily by :mod:`gateway.drive.registry`.  Third-party packages add drivers through the
``gateway.drivers`` entry-point group.
"""

from __future__ import annotations

#: Driver name -> (module, class name).
BUILTIN_DRIVERS: dict[str, tuple[str, str]] = {
    "odrive": ("drivers.odrive", "OdriveDriver"),
    "vesc": ("drivers.vesc", "VescDriver"),
    "cia402": ("drivers.cia402", "Cia402Driver"),
    "dji": ("drivers.dji", "DjiDriver"),
    "dbc": ("drivers.dbc", "DbcDriver"),
}
