"""``wheelgate monitor``'s pure core: a decoded, rate-annotated view of one robot's bus.

* :mod:`gateway.drive.labels` names frames (the gateway's own messages, each driver's
  messages by node, hex IDs otherwise);
* :mod:`gateway.apps.monitor.aggregate` turns frames (:class:`BusMonitor`) or the daemon's status
  replies (:class:`StatusMonitor`) into :class:`MonitorSnapshot` s;
* :mod:`gateway.apps.monitor.view` holds the snapshot types and writes them as JSON
  (:func:`snapshot_json`);
* :mod:`gateway.apps.monitor.screen` draws them as text that fits the terminal (:func:`render`).

The edge, which opens the bus, the log or the socket and keeps the time, is
:mod:`gateway.cli.commands.monitor`.
"""

from __future__ import annotations

from gateway.apps.monitor.aggregate import ARMING_ON_BUS, WINDOW_S, BusMonitor, StatusMonitor
from gateway.apps.monitor.screen import render
from gateway.apps.monitor.view import BusLoad, IdView, MonitorSnapshot, MotorView, snapshot_json
from gateway.drive.labels import FrameLabel, FrameLabeler

__all__ = [
    "ARMING_ON_BUS", "WINDOW_S", "BusLoad", "BusMonitor", "FrameLabel", "FrameLabeler", "IdView",
    "MonitorSnapshot", "MotorView", "StatusMonitor", "render", "snapshot_json",
]
