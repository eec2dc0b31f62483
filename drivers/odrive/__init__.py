"""ODrive "CANSimple" driver for firmware 0.5.x (ODrive v3.x) and 0.6.x (Pro, S1, Micro).

Reference: the `ODrive CAN protocol
<https://docs.odriverobotics.com/v/latest/manual/can-protocol.html>`_ and the official DBC
``odrive-cansimple.dbc``; summarised with worked frames in the ODrive CAN protocol documentation
(docs.odriverobotics.com, can-protocol).

* :mod:`drivers.odrive.enums`: command IDs, axis states, modes, error flags and their mapping
  onto :class:`gateway.core.types.DriveFault`.
* :mod:`drivers.odrive.messages`: every message's layout, the decoded messages and the
  axis-state transition table, as data.
* :mod:`drivers.odrive.codec`: the pure :class:`OdriveCodec`.
* :mod:`drivers.odrive.options`: the protocol keys of a motor block (:class:`OdriveOptions`).
* :mod:`drivers.odrive.faults`: heartbeat and error-reply words mapped onto faults and text.
* :mod:`drivers.odrive.watchdog` and :mod:`drivers.odrive.protection`: the axis watchdog,
  set over CAN on 0.6 (endpoint IDs, the write and read-back), stated on 0.5.
* :mod:`drivers.odrive.axis`: the driver's record of one axis and its enable sequence.
* :mod:`drivers.odrive.driver`: the stateful :class:`OdriveDriver` (registry name ``odrive``).
* :mod:`drivers.odrive.sim`: ``OdriveSimulator``, the device side for tests and ``--sim``
  (found through :data:`drivers.BUILTIN_SIMULATORS`; the driver never imports it).
"""

from __future__ import annotations

from drivers.odrive.codec import OdriveCodec
from drivers.odrive.driver import OdriveDriver
from drivers.odrive.enums import AxisError, AxisError05, AxisState, ControlMode, Firmware, InputMode
from drivers.odrive.options import OdriveOptions

__all__ = [
    "AxisError",
    "AxisError05",
    "AxisState",
    "ControlMode",
    "Firmware",
    "InputMode",
    "OdriveCodec",
    "OdriveDriver",
    "OdriveOptions",
]
