"""Built-in motor-controller drivers, one protocol per module.

:data:`BUILTIN_DRIVERS` maps a config ``driver:`` name to ``(module, class)``; classes are
imported lazily by :mod:`gateway.drive.registry`; :data:`BUILTIN_SIMULATORS` names their device
simulators, found by :mod:`gateway.sim.registry`, and :data:`BUILTIN_SCANNERS` their
``wheelgate scan`` probes.  Third-party packages add drivers through the
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

#: Driver name -> (module, function) of its device simulator, for tests and ``--sim``
#: (:mod:`gateway.sim.registry`); the drivers themselves never import these modules.
BUILTIN_SIMULATORS: dict[str, tuple[str, str]] = {
    "odrive": ("drivers.odrive.sim", "simulator_for"),
    "vesc": ("drivers.vesc.sim", "simulator_for"),
    "cia402": ("drivers.cia402.sim", "simulator_for"),
    "dji": ("drivers.dji.sim", "simulator_for"),
    "dbc": ("drivers.dbc.sim", "simulator_for"),
}

#: Driver name -> (module, class) of its protocol's ``wheelgate scan`` probe
#: (:class:`gateway.drive.scan.ScanProbe`, found by :mod:`gateway.apps.scan.registry`); a DBC
#: file names no controller to look for, so ``dbc`` has none.
BUILTIN_SCANNERS: dict[str, tuple[str, str]] = {
    "odrive": ("drivers.odrive.scan", "OdriveProbe"),
    "vesc": ("drivers.vesc.scan", "VescProbe"),
    "cia402": ("drivers.cia402.scan", "CanopenProbe"),
    "dji": ("drivers.dji.scan", "DjiProbe"),
}
