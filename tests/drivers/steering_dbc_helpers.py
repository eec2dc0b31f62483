"""Shared fixtures and builders of the DBC steering tests (test_steering_dbc_*): a
position-commanded copy of the example DBC, and steering and drive motors."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import pytest

from tests import factories
from tests.conftest import CONFIG_DIR
from tests.drivers.dbc_helpers import EXAMPLE, TWO_PI, odrive_options

if TYPE_CHECKING:
    from pathlib import Path

    from gateway.core.types import MotorConfig

#: Appended to a copy of the example DBC: a position set-point that also selects the mode.
POSITION_MESSAGE = """
BO_ 896 WD_Position_Command: 8 Master
 SG_ Target_Position : 0|32@1- (1,0) [-2147483648|2147483647] "counts" WD100
 SG_ Position_Mode : 32|8@1+ (1,0) [0|3] "" WD100

BO_ 928 WD_Small_Position_Command: 2 Master
 SG_ Small_Target : 0|16@1- (1,0) [-32768|32767] "counts" WD100
"""
GEAR = 12.8
#: One encoder count of the example controller, as a steering angle (rad).
COUNT_STEER = TWO_PI / 4096 / GEAR
STEER_EXAMPLE: dict[str, object] = {
    **{k: v for k, v in EXAMPLE.items() if not k.startswith("command_")},
    "position_command_message": "WD_Position_Command",
    "position_command_signal": "Target_Position",
    "position_command_unit": "counts",
    "position_mode_message": "WD_Position_Command",
    "position_mode_values": {"Position_Mode": 3},
}


@pytest.fixture
def steer_dbc(tmp_path: Path) -> str:
    """The example DBC with the position-command messages added (before the comments)."""
    text = (CONFIG_DIR / "example_controller.dbc").read_text()
    at = text.index("\nCM_ ")
    path = tmp_path / "steer_controller.dbc"
    path.write_text(text[:at] + POSITION_MESSAGE + text[at:])
    return str(path)


def steer_motor(
    dbc: str,
    node: int = 5,
    zero_rad: float = 0.0,
    invert: bool = False,
    gear: float = GEAR,
    travel: float = math.pi,
    **over: object,
) -> MotorConfig:
    """A steering actuator of the factory (:func:`tests.factories.steer_motor`) on the example
    controller's position command in ``dbc``, travelling ``travel`` either way."""
    return factories.steer_motor(
        "dbc", node, zero_rad=zero_rad, gear_ratio=gear, invert=invert,
        steer_range_rad=(-travel, travel), options={**STEER_EXAMPLE, "dbc": dbc, **over},
    )


def drive_motor(dbc: str, node: int = 1) -> MotorConfig:
    """A drive motor of the factory on the example controller's velocity command in ``dbc``."""
    return factories.motor("dbc", node, "rear", gear_ratio=10.0, options={**EXAMPLE, "dbc": dbc})


def odrive_steer(node: int = 3, zero_rad: float = 0.0, gear: float = GEAR) -> MotorConfig:
    """A steering actuator of the factory on ODrive axis ``node``'s position command."""
    opts = odrive_options(node)
    del opts["command_message"], opts["command_signal"], opts["command_unit"]
    opts.update(
        position_command_message=f"Axis{node}_Set_Input_Pos",
        position_command_signal="Input_Pos",
        position_command_unit="rev",
        position_mode_message=f"Axis{node}_Set_Controller_Mode",
        position_mode_values={"Control_Mode": 3, "Input_Mode": 1},
    )
    return factories.steer_motor("dbc", node, zero_rad=zero_rad, gear_ratio=gear, options=opts)


def counts(motor_rad: float) -> int:
    return round(motor_rad / TWO_PI * 4096)
