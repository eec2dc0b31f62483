"""DJI RoboMaster C620 (M3508) / C610 (M2006) ESCs: current commands, host-side speed loop.

Protocol reference: DJI's `Development-Board-C-Examples
<https://github.com/RoboMaster/Development-Board-C-Examples>`_ (``14.CAN/application/
CAN_receive.{h,c}``) and the RoboMaster C620/C610 user guides' CAN protocol sections.

* :mod:`drivers.dji.codec`: the pure wire format (frame IDs, field tables, unwrapping);
* :mod:`drivers.dji.options`: the motor-block keys (:class:`DjiOptions`);
* :mod:`drivers.dji.pi`: the pure rotor-speed PI controller;
* :mod:`drivers.dji.position`: the pure position loop of a steering actuator;
* :mod:`drivers.dji.protection`: what stops the ESC when wheelgate dies (nothing known), and the
  ``no_controller_stop: acknowledged`` every motor block must carry;
* :mod:`drivers.dji.axis`: one motor's constants and loop state;
* :mod:`drivers.dji.driver`: :class:`DjiDriver`, the stateful driver;
* :mod:`drivers.dji.sim`: a simulated ESC with a current-driven motor, for tests and ``--sim``
  (registered apart, :data:`drivers.BUILTIN_SIMULATORS`; nothing here imports it).
"""

from __future__ import annotations

from drivers.dji.codec import (
    C610,
    C620,
    ESC_MODELS,
    M2006_GEAR_RATIO,
    M3508_GEAR_RATIO,
    DjiFeedback,
    DjiFrameId,
    EscModel,
)
from drivers.dji.driver import TEMP_HYSTERESIS_C, DjiDriver
from drivers.dji.options import DjiOptions
from drivers.dji.pi import SpeedPi
from drivers.dji.position import STEERING_OPTIONS, PositionLoop, power_up_position_rad

__all__ = [
    "C610",
    "C620",
    "ESC_MODELS",
    "M2006_GEAR_RATIO",
    "M3508_GEAR_RATIO",
    "STEERING_OPTIONS",
    "TEMP_HYSTERESIS_C",
    "DjiDriver",
    "DjiFeedback",
    "DjiFrameId",
    "DjiOptions",
    "EscModel",
    "PositionLoop",
    "SpeedPi",
    "power_up_position_rad",
]
