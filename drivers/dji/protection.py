"""What stops a DJI C620 / C610 ESC when wheelgate dies: nothing known, so the configuration
must say that it knows (issue 14).

**What is known.**  The ESC takes one int16 current set point per frame (``0x200`` / ``0x1FF``)
and has no enable, no heartbeat and no parameter to set over CAN.  No public source found says
what it does when the frames stop: the C620 (2017.09 v1.0) and C610 (2019.03 v1.0) user
guides' CAN protocol sections describe only the two frame formats; DJI's
Development-Board-C-Examples (``14.CAN/application/CAN_receive.c``) only sends currents; the
RoboMaster teams' firmware that was searched sends zero current explicitly whenever it wants the
motors to go limp (a "relax" or "zero force" mode, a remote or motor gone offline), which fits
an ESC that holds its set point but does not prove it.  So wheelgate assumes the worst: **the
ESC holds its last current for ever**.  wheelgate closes the wheel's speed loop itself, so
when it dies the wheel keeps the torque of the last cycle, and an unloaded wheel speeds up.

The simulator (:class:`drivers.dji.sim.DjiSimulator`) holds its last set point for ever too,
never kinder than this assumption.

Every DJI motor block must therefore carry ``no_controller_stop: acknowledged``
(:data:`ACK_KEY`, :data:`ACK_VALUE`); without it the block is refused
(:func:`check_acknowledged`), naming the motor, the consequence and the fix: power the ESCs
through a relay or an e-stop loop that opens by itself when the gateway computer stops feeding
a hardware watchdog.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from gateway.core.errors import ConfigError
from gateway.core.options import OptionSpec
from gateway.core.protection import Guard, Protection

if TYPE_CHECKING:
    from collections.abc import Mapping

    from gateway.core.types import MotorConfig

__all__ = ["ACK_KEY", "ACK_OPTION", "ACK_VALUE", "check_acknowledged", "protection"]

#: The motor-block key that acknowledges that nothing on the ESC stops the motor.
ACK_KEY = "no_controller_stop"
#: Its only accepted value.
ACK_VALUE = "acknowledged"
#: The key's spec (its default, ``""``, is refused by :func:`check_acknowledged`).
ACK_OPTION = OptionSpec(
    str,
    "",
    help=f"must be {ACK_VALUE!r}: the ESC has no known command timeout and holds its last "
    "current if wheelgate dies",
)

#: What the ESC does after the last frame, as assumed.
ACTION = "holds its last current (assumed: no known timeout)"
#: What happens when wheelgate dies, for the refusal.
CONSEQUENCE = (
    "a C620/C610 ESC has no known command timeout and is assumed to hold its last current for "
    "ever, and wheelgate runs this motor's speed loop, so if wheelgate dies (kill -9, out of "
    "memory, a frozen host) the motor keeps that torque, and an unloaded wheel speeds up, until "
    "the ESC's power is cut"
)
#: The hardware answer, for the refusal and the protection's ``fix``.
HARDWARE_FIX = (
    "power the ESCs through a relay or an e-stop loop that opens by itself when the gateway "
    "computer stops feeding a hardware watchdog (e.g. an external watchdog relay; systemd's "
    "WatchdogSec= restarts a stalled wheelgate, RuntimeWatchdogSec= resets a frozen host)"
)


def check_acknowledged(options: Mapping[str, object], where: str) -> None:
    """Refuse a DJI motor block that does not acknowledge that its ESC has no stop of its own.

    :param options: the block's protocol keys.
    :param where: the block, e.g. ``"robot.yaml: motors.front_left"`` or ``"motor 'left'"``.
    :raises ConfigError: unless ``options[ACK_KEY]`` is exactly :data:`ACK_VALUE`, naming the
        block, what happens when wheelgate dies and what to add.
    """
    value = options.get(ACK_KEY, "")
    if value == ACK_VALUE:
        return
    got = "nothing" if value == "" else repr(value)
    raise ConfigError(
        f"{where}.{ACK_KEY}: expected {ACK_VALUE!r}, got {got}: {CONSEQUENCE}. Fix: "
        f"{HARDWARE_FIX}; then add '{ACK_KEY}: {ACK_VALUE}' to this motor's block (or to "
        f"motor_defaults / steering_defaults)"
    )


def protection(motor: MotorConfig) -> Protection:
    """:attr:`Guard.NONE` for an acknowledged DJI motor (see the module docstring)."""
    what = (
        "steering actuator keeps its torque and turns on"
        if motor.steering
        else "wheel keeps its torque (unloaded, it speeds up)"
    )
    return Protection(
        Guard.NONE,
        None,
        ACTION,
        f"the C620/C610 ESC has no known command timeout and is assumed to hold its last "
        f"current, and wheelgate runs the speed loop, so if wheelgate dies this {what} until "
        f"the ESC's power is cut ({ACK_KEY}: {ACK_VALUE})",
        HARDWARE_FIX,
    )
