"""Generic driver for any motor controller whose CAN messages are described by a DBC file.

The user names a DBC file and, in the motor block, the message and signal that carry the
velocity command (a drive motor) or the position command (a steering actuator, with the
message that selects position control, if any) and those that carry the velocity and
position feedback, with their units;
cantools (https://cantools.readthedocs.io/) encodes and decodes them.  The DBC format is
Vector's "DBC File Format Documentation" (v1.0.5); ``config/example_controller.dbc`` is a small
commented example and ODrive's official ``odrive-cansimple.dbc``
(https://github.com/odriverobotics/ODrive/blob/master/tools/odrive-cansimple.dbc) works too.

Modules: :mod:`~drivers.dbc.options` (the protocol keys), :mod:`~drivers.dbc.units` (unit
conversions), :mod:`~drivers.dbc.database` (the DBC files, loaded once),
:mod:`~drivers.dbc.binding` (names -> cantools messages and signals),
:mod:`~drivers.dbc.frames` and :mod:`~drivers.dbc.codec` (the pure :class:`DbcCodec`),
:mod:`~drivers.dbc.axis` (one motor's state) and :mod:`~drivers.dbc.driver`
(:class:`DbcDriver`).  The device simulator, :mod:`drivers.dbc.sim`, is for tests and
``--sim`` only: nothing here imports it.
"""

from __future__ import annotations

from drivers.dbc.codec import DbcCodec, DbcReading, DbcRequest, Role, describe_fault
from drivers.dbc.driver import DbcDriver
from drivers.dbc.options import DbcOptions, parse_options
from drivers.dbc.units import UnitConversion

__all__ = [
    "DbcCodec",
    "DbcDriver",
    "DbcOptions",
    "DbcReading",
    "DbcRequest",
    "Role",
    "UnitConversion",
    "describe_fault",
    "parse_options",
]
