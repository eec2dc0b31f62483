"""VESC (vedderb/bldc) over CAN: velocity in electrical RPM, odometry from the tachometer.

Protocol reference: https://github.com/vedderb/bldc/blob/master/documentation/comm_can.md
(simple commands and status messages) and ``comm/comm_can.c``.

* :mod:`drivers.vesc.codec`: the pure frame builders and parsers (:class:`VescCodec`).
* :mod:`drivers.vesc.driver`: :class:`VescDriver`, the stateful driver (registry name ``vesc``).
* :mod:`drivers.vesc.sim`: :class:`VescSimulator`, the controller side for tests and ``--sim``,
  at the firmware's factory settings unless built from a configuration.
* :mod:`drivers.vesc.settings`: the VESC Tool settings a motor block states (timeout, status
  messages, minimum ERPM), with their factory values.
* :mod:`drivers.vesc.min_erpm`: the wheel speeds below ``s_pid_min_erpm`` that a VESC does not
  speed-control.
"""

from __future__ import annotations

from drivers.vesc.codec import (
    BROADCAST_ID,
    CanPacketId,
    HwType,
    VescCodec,
    VescCommand,
    VescPing,
    VescPong,
    VescStatus,
    VescStatus5,
)
from drivers.vesc.driver import VescDriver
from drivers.vesc.sim import SimMode, VescSimulator

__all__ = [
    "BROADCAST_ID",
    "CanPacketId",
    "HwType",
    "SimMode",
    "VescCodec",
    "VescCommand",
    "VescDriver",
    "VescPing",
    "VescPong",
    "VescSimulator",
    "VescStatus",
    "VescStatus5",
]
