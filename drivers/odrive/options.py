"""Protocol keys of a ``driver: odrive`` motor block, described once, and the bus they imply.

Every key is an :class:`~gateway.drive.driver.OptionSpec` in :data:`OPTIONS`;
:func:`bus_settings` checks that the motors of one bus agree on the keys that hold for the
whole bus (firmware family and ID mode).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from drivers.odrive.enums import Firmware, InputMode
from drivers.odrive.messages import DEFAULT_EXTENDED_ID, DEFAULT_FIRMWARE
from gateway.core.errors import ConfigError
from gateway.drive.driver import MotorDriver, OptionSpec

if TYPE_CHECKING:
    from collections.abc import Mapping, Sequence

    from gateway.core.types import MotorConfig

#: Every protocol key of a ``driver: odrive`` motor block.
OPTIONS: dict[str, OptionSpec] = {
    "firmware": OptionSpec(
        str,
        DEFAULT_FIRMWARE.value,
        choices=tuple(f.value for f in Firmware),
        help="firmware family: 0.5 (ODrive v3.x) or 0.6 (ODrive Pro, S1, Micro)",
    ),
    "extended_id": OptionSpec(
        bool, DEFAULT_EXTENDED_ID, help="29-bit identifiers (axis.config.can.is_extended)"
    ),
    "input_mode": OptionSpec(
        int,
        int(InputMode.PASSTHROUGH),
        choices=(int(InputMode.PASSTHROUGH), int(InputMode.VEL_RAMP)),
        help="controller input mode: 1 passthrough, 2 vel_ramp (the axis ramps speed)",
    ),
    "encoder_request": OptionSpec(
        str,
        "cyclic",
        choices=("cyclic", "rtr"),
        help="cyclic encoder estimates, or an RTR request on every poll",
    ),
    "controller_timeout_s": OptionSpec(
        float,
        0.0,
        minimum=0.0,
        maximum=60.0,
        help="the axis watchdog timeout (s): on 0.6 written over CAN and read back (0: "
        "0.25 s); on 0.5 a statement of what odrivetool set (0: not stated)",
    ),
    "flat_endpoints": OptionSpec(
        str,
        "",
        help="0.6: the firmware's flat_endpoints.json (from docs.odriverobotics.com/releases/"
        "firmware), for the watchdog's endpoint IDs",
    ),
    "watchdog_endpoints": OptionSpec(
        dict,
        {},
        help="0.6: {fw_version, enable_watchdog, watchdog_timeout[, hw_version]}: the "
        "watchdog's endpoint IDs of that firmware version, instead of flat_endpoints",
    ),
    "config_dir": OptionSpec(
        str, "", help="directory a relative flat_endpoints starts from; '' = current directory"
    ),
    "liveness_s": OptionSpec(
        float,
        MotorDriver.DEFAULT_LIVENESS_S,
        minimum=0.001,
        help="seconds without heartbeat or encoder estimates before a motor is OFFLINE",
    ),
}


def bus_settings(
    motors: Sequence[MotorConfig], opts: Sequence[Mapping[str, object]]
) -> tuple[Firmware, bool]:
    """The firmware family and ID mode of one bus, which every motor on it must share.

    :param motors: the motors of the bus.
    :param opts: their validated protocol keys, in the same order.
    :return: ``(firmware, extended_id)``; the defaults for no motors.
    :raises ConfigError: if a motor disagrees with the first on ``firmware`` or
        ``extended_id``.
    """
    first = opts[0] if opts else {"firmware": DEFAULT_FIRMWARE.value, "extended_id": False}
    for m, o in zip(motors, opts, strict=True):
        for key in ("firmware", "extended_id"):
            if o[key] != first[key]:
                raise ConfigError(
                    f"motor {m.wheel!r}.{key}: expected {first[key]!r} like motor "
                    f"{motors[0].wheel!r} on the same ODrive bus, got {o[key]!r}"
                )
    return Firmware(first["firmware"]), bool(first["extended_id"])
