"""ODrive error reports as the gateway's faults: heartbeat error words and error replies.

Pure functions over the decoded messages of :mod:`drivers.odrive.messages`, with the flag
tables of :mod:`drivers.odrive.enums`; which axis reported what, and when to ask for more, is
the driver's state (:mod:`drivers.odrive.driver`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from drivers.odrive.enums import (
    AxisError05,
    Firmware,
    MotorError05,
    error_class,
    error_faults,
    flag_names,
)
from drivers.odrive.messages import ErrorStatus
from gateway.core.types import DriveFault

if TYPE_CHECKING:
    from drivers.odrive.messages import Heartbeat, MotorErrorStatus


#: What 0.5's INVALID_STATE means after the gateway's CLOSED_LOOP_CONTROL request (axis.cpp,
#: ``run_state_machine_loop``: a closed-loop request without a calibrated motor and encoder).
INVALID_STATE_HINT = (
    "the axis refused the state requested: for CLOSED_LOOP_CONTROL most often a motor or "
    "encoder not calibrated (with odrivetool: request FULL_CALIBRATION_SEQUENCE, set "
    "motor.config.pre_calibrated and encoder.config.pre_calibrated, save_configuration())"
)


def heartbeat_faults(firmware: Firmware, hb: Heartbeat) -> tuple[DriveFault, str]:
    """The faults a heartbeat reports, and their text for the motor's status detail.

    The axis error word maps by :func:`~drivers.odrive.enums.error_faults`; 0.5's motor,
    encoder and controller flags add ``MOTOR``, ``ENCODER`` and ``CONTROLLER``.

    :param firmware: the firmware family, for the axis error bit numbering.
    :param hb: the decoded heartbeat.
    :return: the faults (``NONE`` for a healthy axis) and e.g.
        ``"axis error 0x00000800: WATCHDOG_TIMER_EXPIRED; motor error flag"`` (``""`` then).
    """
    faults = error_faults(firmware, hb.axis_error)
    parts = []
    if hb.axis_error:
        names = flag_names(error_class(firmware), hb.axis_error)
        parts.append(f"axis error {hb.axis_error:#010x}: {names}")
        if firmware is Firmware.V0_5 and hb.axis_error & AxisError05.INVALID_STATE:
            parts.append(INVALID_STATE_HINT)
    for flag, fault, name in (
        (hb.motor_error, DriveFault.MOTOR, "motor"),
        (hb.encoder_error, DriveFault.ENCODER, "encoder"),
        (hb.controller_error, DriveFault.CONTROLLER, "controller"),
    ):
        if flag:
            faults |= fault
            parts.append(f"{name} error flag")
    return faults, "; ".join(parts)


def error_query_adds_detail(firmware: Firmware, hb: Heartbeat) -> bool:
    """Whether the error reply would add to a faulted heartbeat's text: always Get_Error in
    0.6 (active errors and disarm reason), Get_Motor_Error in 0.5 only when the motor is at
    fault."""
    return (
        firmware is Firmware.V0_6
        or hb.motor_error
        or bool(hb.axis_error & AxisError05.MOTOR_FAILED)
    )


def error_reply_detail(firmware: Firmware, msg: ErrorStatus | MotorErrorStatus) -> str:
    """The text of a Get_Error (0.6: the disarm reason) or Get_Motor_Error (0.5) reply."""
    if isinstance(msg, ErrorStatus):
        return f"disarm reason: {flag_names(error_class(firmware), msg.disarm_reason)}"
    return f"motor error {msg.motor_error:#x}: {flag_names(MotorError05, msg.motor_error)}"
