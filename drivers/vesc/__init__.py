"""VESC (vedderb/bldc) over CAN: velocity in electrical RPM, odometry from the tachometer.

Protocol reference: https://github.com/vedderb/bldc/blob/master/documentation/comm_can.md
(simple commands and status messages) and ``comm/comm_can.c``.

* :mod:`drivers.vesc.codec`: the pure frame builders and parsers.
* :mod:`drivers.vesc.driver`: :class:`VescDriver`, the stateful driver (registry name ``vesc``);
  :mod:`drivers.vesc.axis`: what it keeps per motor, and the unit conversions.
* :mod:`drivers.vesc.settings`: the protocol keys of a motor block (:class:`VescOptions`): the
  VESC Tool settings it states (timeout, status messages, minimum ERPM), with their factory
  values.
* :mod:`drivers.vesc.appconf`: COMM_GET_APPCONF over the CAN buffer protocol (the request, the
  reassembly of the reply, its timeout); :mod:`drivers.vesc.readback`: the timeouts read back
  while enabling, and the policy; :mod:`drivers.vesc.frames`: the driver's claims and labels.
* :mod:`drivers.vesc.min_erpm`: the wheel speeds below ``s_pid_min_erpm`` that a VESC does not
  speed-control.
* :mod:`drivers.vesc.sim`: ``VescSimulator`` (and :mod:`drivers.vesc.sim_appconf`, its
  COMM_GET_APPCONF answer), the controller side for tests and ``--sim``, at
  the firmware's factory settings unless built from a configuration (``simulator_for``); not
  imported here: production code carries no test device.
"""

from __future__ import annotations

from drivers.vesc.codec import (
    BROADCAST_ID,
    CanPacketId,
    HwType,
    VescCommand,
    VescPing,
    VescPong,
    VescStatus,
    VescStatus5,
)
from drivers.vesc.driver import VescDriver
from drivers.vesc.settings import VescOptions

__all__ = [
    "BROADCAST_ID",
    "CanPacketId",
    "HwType",
    "VescCommand",
    "VescDriver",
    "VescOptions",
    "VescPing",
    "VescPong",
    "VescStatus",
    "VescStatus5",
]
