"""CANopen CiA 402 drives in profile velocity mode (driver name ``cia402``); steering
actuators in cyclic synchronous position mode.

* :mod:`~drivers.cia402.enums`: wire enums and the CiA 402 state machine as tables.
* :mod:`~drivers.cia402.faults`: SDO abort codes, EMCY codes, error register.
* :mod:`~drivers.cia402.codec`: pure frame builders and parsers (:class:`Cia402Codec`).
* :mod:`~drivers.cia402.options`: the protocol keys of a motor block (:class:`Cia402Options`).
* :mod:`~drivers.cia402.steps`: what is written into a node before it starts, as data.
* :mod:`~drivers.cia402.sequence`: the non-blocking enable and stop sequence of one node.
* :mod:`~drivers.cia402.protection`: controller-side protection: the gateway's heartbeat, each
  drive's heartbeat consumer (0x1016) and abort connection option code (0x6007).
* :mod:`~drivers.cia402.targets`: the command RPDOs' targets (velocity, CSP position).
* :mod:`~drivers.cia402.axis`: one motor's record, and what its node's messages do to it.
* :mod:`~drivers.cia402.driver`: :class:`Cia402Driver`, one instance per bus.
* :mod:`~drivers.cia402.sim`: ``Cia402Simulator``, a simulated drive (``simulator_for``, for
  tests and ``--sim``; never imported by the driver), with its object dictionary
  (:mod:`~drivers.cia402.sim_od`), device control (:mod:`~drivers.cia402.sim_device`,
  :mod:`~drivers.cia402.sim_control`) and PDO exchange (:mod:`~drivers.cia402.sim_pdo`).

Reference: CiA 301 / CiA 402 (https://www.can-cia.org/can-knowledge/cia402-series) and
CiA 301 / CiA 402 as the canopen library (christiansandberg/canopen) implements them.
"""

from __future__ import annotations

from drivers.cia402.codec import Cia402Codec, PdoLayout
from drivers.cia402.driver import Cia402Driver
from drivers.cia402.options import Cia402Options

__all__ = ["Cia402Codec", "Cia402Driver", "Cia402Options", "PdoLayout"]
