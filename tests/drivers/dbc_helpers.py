"""Shared constants and builders of the generic DBC driver's tests (test_drivers_dbc_*): the
example and ODrive DBC files, their options, motors and codecs."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from hypothesis import HealthCheck, settings

from tests import factories
from tests.conftest import CONFIG_DIR, DATA_DIR

if TYPE_CHECKING:
    from collections.abc import Mapping

    from gateway.core.types import MotorConfig

EXAMPLE_DBC = str(CONFIG_DIR / "example_controller.dbc")
ODRIVE_DBC = str(DATA_DIR / "odrive-cansimple-0.5.6.dbc")
TWO_PI = 2.0 * math.pi
GEAR = 10.0
#: One encoder count of the example controller, as a wheel angle (rad).
COUNT_RAD = TWO_PI / 4096 / GEAR
SETTINGS = settings(
    max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)

EXAMPLE: dict[str, object] = {
    "dbc": EXAMPLE_DBC,
    "command_message": "WD_Velocity_Command",
    "command_signal": "Target_Velocity",
    "command_unit": "rpm",
    "feedback_message": "WD_Feedback",
    "velocity_signal": "Actual_Velocity",
    "velocity_unit": "rpm",
    "position_signal": "Position_Count",
    "position_unit": "counts",
    "counts_per_rev": 4096,
    "position_wrap_bits": 32,
    "enable_message": "WD_Enable",
    "enable_signal": "Enable",
    "fault_signal": "Fault_Code",
}
ANGLE: dict[str, object] = {
    "position_message": "WD_Angle",
    "position_signal": "Rotor_Angle",
    "position_unit": "deg",
    "position_wrap_bits": 13,
}


def odrive_options(axis: int = 3, **over: object) -> dict[str, object]:
    """A motor block that drives ODrive axis ``axis`` through the official DBC."""
    opts: dict[str, object] = {
        "dbc": ODRIVE_DBC,
        "command_message": f"Axis{axis}_Set_Input_Vel",
        "command_signal": "Input_Vel",
        "command_unit": "rev/s",
        "feedback_message": f"Axis{axis}_Get_Encoder_Estimates",
        "velocity_signal": "Vel_Estimate",
        "velocity_unit": "rev/s",
        "position_signal": "Pos_Estimate",
        "position_unit": "rev",
        "node_id_in_frame": "none",
        "enable_message": f"Axis{axis}_Set_Axis_State",
        "enable_signal": "Axis_Requested_State",
        "enable_value": 8,  # CLOSED_LOOP_CONTROL
        "disable_value": 1,  # IDLE
        "fault_message": f"Axis{axis}_Heartbeat",
        "fault_signal": "Axis_Error",
    }
    opts.update(over)
    return opts


def motor(
    node: int = 3,
    wheel: str = "left",
    gear: float = GEAR,
    invert: bool = False,
    extra: Mapping[str, object] | None = None,
    *,
    validate: bool = True,
    **over: object,
) -> MotorConfig:
    """An example-controller motor block of the factory (:func:`tests.factories.motor`), with
    ``extra`` and ``over`` replacing protocol keys."""
    return factories.motor("dbc", node, wheel, gear_ratio=gear, invert=invert, validate=validate,
                           options={**EXAMPLE, **(extra or {}), **over})


def odrive_motor(node: int = 3, **over: object) -> MotorConfig:
    """A motor block of the factory that drives ODrive axis ``node`` (:func:`odrive_options`)."""
    return factories.motor("dbc", node, options=odrive_options(node, **over))


def rpm(value: float) -> float:
    return value * TWO_PI / 60.0
