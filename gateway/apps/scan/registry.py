"""Probe lookup for ``wheelgate scan``: each protocol's :class:`~gateway.drive.scan.ScanProbe`,
registered apart from its driver.

The built-in table is :data:`drivers.BUILTIN_SCANNERS` (driver name -> module, class); other
packages add theirs in the ``gateway.scanners`` entry-point group, naming a ``ScanProbe``
subclass::

    [project.entry-points."gateway.scanners"]
    mydriver = "mypackage.scan:MyProbe"

A built-in probe that fails to load is an error naming it; a plugin that fails is a warning
naming the plugin and the exception, and the scan goes on without it.
"""

from __future__ import annotations

import importlib
import logging

from drivers import BUILTIN_SCANNERS
from gateway.core.errors import DriverNotFoundError
from gateway.drive.scan import ScanProbe

log = logging.getLogger(__name__)

ENTRY_POINT_GROUP = "gateway.scanners"


def _instance(cls: object, what: str) -> ScanProbe:
    if not (isinstance(cls, type) and issubclass(cls, ScanProbe)):
        raise DriverNotFoundError(f"Scan probe {what} is not a ScanProbe subclass: {cls!r}")
    return cls()


def load_probes() -> list[ScanProbe]:
    """One instance of every registered probe, in :attr:`~ScanProbe.PRECEDENCE` order.

    :raises DriverNotFoundError: if a built-in probe fails to load.
    """
    from importlib.metadata import entry_points  # noqa: PLC0415 - only the scan reads them

    probes = []
    for driver, (module_name, class_name) in BUILTIN_SCANNERS.items():
        what = f"{driver!r} ({module_name}.{class_name})"
        try:
            cls = getattr(importlib.import_module(module_name), class_name)
        except (ImportError, AttributeError) as err:
            raise DriverNotFoundError(f"Scan probe {what} failed to load: {err}") from err
        probes.append(_instance(cls, what))
    for ep in entry_points(group=ENTRY_POINT_GROUP):
        if ep.name in BUILTIN_SCANNERS:
            continue
        try:
            probes.append(_instance(ep.load(), f"{ep.name!r} ({ep.value})"))
        except Exception as err:  # a plugin may raise anything while importing
            log.warning("scan probe plugin %r (%s) failed to load: %r", ep.name, ep.value, err)
    return sorted(probes, key=lambda p: p.PRECEDENCE)
