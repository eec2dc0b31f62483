"""What stops an ODrive axis when wheelgate falls silent: its axis watchdog.

On firmware 0.6 the driver writes the watchdog over CAN and reads it back before arming when the
motor block names the watchdog's endpoint IDs (:class:`~drivers.odrive.watchdog.WatchdogSetup`:
:attr:`~gateway.core.protection.Guard.CONFIGURED`); on 0.5, which has no parameter access over
CAN, the block states what ``odrivetool`` set (``controller_timeout_s``:
:attr:`~gateway.core.protection.Guard.STATED`).  Sources: the `ODrive CAN protocol
<https://docs.odriverobotics.com/v/latest/manual/can-protocol.html>`_ and the official
``examples/can_watchdog.py`` (``odriverobotics/ODriveResources``).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from drivers.odrive.enums import CmdId, Firmware
from drivers.odrive.watchdog import (
    DEFAULT_TIMEOUT_S,
    RX_SDO,
    WatchdogSetup,
    endpoints_from_options,
)
from gateway.core.errors import ConfigError
from gateway.core.protection import Guard, Protection

if TYPE_CHECKING:
    from drivers.odrive.codec import OdriveCodec
    from drivers.odrive.options import OdriveOptions
    from gateway.core.types import MotorConfig

#: What an axis does when its watchdog expires.
TIMEOUT_ACTION = "latches WATCHDOG_TIMER_EXPIRED and goes IDLE: the motor coasts"


def watchdog_setup(
    motor: MotorConfig, options: OdriveOptions, codec: OdriveCodec
) -> WatchdogSetup | None:
    """The 0.6 watchdog setup of ``motor`` (``None`` when its block names no endpoint IDs).

    :raises ConfigError: for endpoint IDs on firmware 0.5, or bad endpoint keys
        (:func:`~drivers.odrive.watchdog.endpoints_from_options`).
    """
    where = f"motor {motor.wheel!r}"
    endpoints = endpoints_from_options(options, where)
    if endpoints is None:
        return None
    if codec.firmware is not Firmware.V0_6:
        raise ConfigError(
            f"{where}: flat_endpoints/watchdog_endpoints: expected firmware 0.6 (0.5 has "
            f"no parameter access over CAN: set the watchdog with odrivetool and state "
            f"controller_timeout_s), got firmware {codec.firmware.value}"
        )
    arb = codec.arbitration_id
    return WatchdogSetup(
        endpoints,
        options.controller_timeout_s or DEFAULT_TIMEOUT_S,
        arb(motor.node_id, RX_SDO),
        arb(motor.node_id, CmdId.GET_VERSION),
        codec.extended_id,
    )


def axis_protection(
    node_id: int, firmware: Firmware, setup: WatchdogSetup | None, stated_s: float
) -> Protection:
    """The protection of one axis: CONFIGURED with a 0.6 setup; otherwise STATED by
    ``controller_timeout_s`` (0.5, set with odrivetool) or UNSTATED, with the fix.

    :param stated_s: the block's ``controller_timeout_s`` (0: not stated).
    """
    if setup is not None:
        ep = setup.endpoints
        return Protection(
            Guard.CONFIGURED, setup.timeout_s, TIMEOUT_ACTION,
            f"axis watchdog written over CAN (RxSdo endpoints {ep.timeout_id}, "
            f"{ep.enable_id} of firmware {ep.fw_version}) and read back before arming",
        )
    v06 = firmware is Firmware.V0_6
    if stated_s > 0 and not v06:
        return Protection(
            Guard.STATED, stated_s, TIMEOUT_ACTION,
            "axis watchdog set with odrivetool (0.5 cannot set it over CAN); stated by "
            "controller_timeout_s, not verifiable over CAN",
        )
    if v06:
        return Protection(
            Guard.UNSTATED, stated_s or None, "unknown",
            "not set over CAN: the motor block names no endpoint IDs (flat_endpoints or "
            "watchdog_endpoints)" + (
                f"; controller_timeout_s {stated_s:g} s is not confirmed" if stated_s else ""
            ),
            "give flat_endpoints: the flat_endpoints.json of the axis' firmware release "
            "(https://docs.odriverobotics.com/releases/firmware)",
            configurable=True,
        )
    return Protection(
        Guard.UNSTATED, None, "unknown",
        "not stated: an ODrive's watchdog is off from the factory",
        odrivetool_fix(node_id, DEFAULT_TIMEOUT_S),
    )


def odrivetool_fix(node_id: int, timeout_s: float) -> str:
    """How to set the watchdog of the 0.5 axis at CAN node ``node_id`` with odrivetool, in
    its own syntax (the ``Axis.config`` attributes ``watchdog_timeout`` and
    ``enable_watchdog``, then ``save_configuration()`` of the board, from the firmware's
    ``Firmware/odrive-interface.yaml`` in odriverobotics/ODrive).

    Which of a board's two axes has the node ID is set on the board (``config.can.node_id``;
    ``config.can_node_id`` before 0.5.2) and is not on the bus, so the advice names axis0
    and says how to tell.
    """
    axis = "odrv0.axis0"
    return (f"on the ODrive whose axis has CAN node {node_id}, in odrivetool: {axis}.config."
            f"watchdog_timeout = {timeout_s:g}; {axis}.config.enable_watchdog = True; "
            f"odrv0.save_configuration() (axis1 for axis0 if odrv0.axis1.config.can.node_id "
            f"is {node_id}); then state controller_timeout_s: {timeout_s:g}")
