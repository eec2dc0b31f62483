"""DJI RoboMaster C620 (M3508) / C610 (M2006) ESCs: current commands, host-side speed loop.

Protocol reference: DJI's `Development-Board-C-Examples
<https://github.com/RoboMaster/Development-Board-C-Examples>`_ (``14.CAN/application/
CAN_receive.{h,c}``) and the RoboMaster C620/C610 user guides' CAN protocol sections.

* :mod:`drivers.dji.codec`: the pure wire format (frame IDs, field tables, unwrapping);
* :mod:`drivers.dji.pi`: the pure rotor-speed PI controller;
* :mod:`drivers.dji.position`: the pure position loop of a steering actuator;
* :mod:`drivers.dji.protection`: what stops the ESC when wheelgate dies (nothing known), and the
  ``no_controller_stop: acknowledged`` every motor block must carry;
* :mod:`drivers.dji.driver`: :class:`DjiDriver`, the stateful driver;
* :mod:`drivers.dji.sim`: :class:`DjiSimulator`, a simulated ESC with a current-driven motor.
"""

from __future__ import annotations

from drivers.dji.codec import (
    C610,
    C620,
    ESC_MODELS,
    M2006_GEAR_RATIO,
    M3508_GEAR_RATIO,
    DjiCodec,
    DjiFeedback,
    DjiFrameId,
    EscModel,
)
from drivers.dji.driver import TEMP_HYSTERESIS_C, DjiDriver
from drivers.dji.pi import SpeedPi
from drivers.dji.position import STEERING_OPTIONS, PositionLoop, power_up_position_rad
from drivers.dji.sim import DjiMotorModel, DjiSimulator

__all__ = [
    "C610",
    "C620",
    "ESC_MODELS",
    "M2006_GEAR_RATIO",
    "M3508_GEAR_RATIO",
    "STEERING_OPTIONS",
    "TEMP_HYSTERESIS_C",
    "DjiCodec",
    "DjiDriver",
    "DjiFeedback",
    "DjiFrameId",
    "DjiMotorModel",
    "DjiSimulator",
    "EscModel",
    "PositionLoop",
    "SpeedPi",
    "power_up_position_rad",
]
