"""``wheelgate scan``: which controllers are on a bus, by protocol, without moving anything.

* :mod:`gateway.drive.scan`: the contract each protocol's probe fulfils (in
  ``drivers/<protocol>/scan.py``, on its codec), found by :mod:`gateway.apps.scan.registry`;
* :mod:`gateway.apps.scan.classify`: the identifiers heard sorted into controllers (pure);
* :mod:`gateway.apps.scan.session`: the course of a scan: listen, ask, report (pure);
* :mod:`gateway.apps.scan.known`: the configuration's motors matched with what was found, by
  driver, node ID and identifier type (pure);
* :mod:`gateway.apps.scan.report`: the report, as a table and as JSON (pure);
* :mod:`gateway.apps.scan.scanner`: the edge that opens the bus and sends what the session asks
  (it says which requests go out and why none can move a motor).
"""

from __future__ import annotations

from gateway.apps.scan.report import (
    ScannedDevice,
    ScanReport,
    render,
    report_json,
    summary,
    wrap,
)
from gateway.apps.scan.scanner import scan, scan_bus
from gateway.apps.scan.session import ScanSession, ScanTiming

__all__ = ["ScanReport", "ScanSession", "ScanTiming", "ScannedDevice", "render", "report_json",
           "scan", "scan_bus", "summary", "wrap"]
