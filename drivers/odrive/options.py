"""Protocol keys of a ``driver: odrive`` motor block, declared once as :class:`OdriveOptions`.

The keys every protocol shares come from :mod:`gateway.drive.options`: ``liveness_s`` (here
the silence of either the heartbeat or the encoder estimates) and ``controller_timeout_s``
(here the axis watchdog: written over CAN on 0.6, stated on 0.5, see
:mod:`drivers.odrive.watchdog`).  ``firmware`` and ``extended_id`` hold for the whole bus: the
driver lists them in its ``BUS_WIDE`` keys.

``heartbeat_msg_rate_ms`` and ``encoder_msg_rate_ms`` state the axis's cyclic message periods
as set on the ODrive (0.6 ``axis.config.can.heartbeat_msg_rate_ms`` and
``encoder_msg_rate_ms``; 0.5 ``heartbeat_rate_ms`` and ``encoder_rate_ms``), which wheelgate
does not write: 100 ms and 10 ms from the factory (0.5 ``can_simple.cpp``; the 0.6 CAN protocol
page).  The bus-load budget counts them (:mod:`drivers.odrive.traffic`), ``liveness_s`` must
cover two of the slower, and a simulator built from the block sends at them.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import TYPE_CHECKING, cast

from drivers.odrive.enums import Firmware, InputMode
from drivers.odrive.messages import DEFAULT_EXTENDED_ID, DEFAULT_FIRMWARE
from gateway.core.errors import ConfigError
from gateway.drive.options import (
    CONTROLLER_TIMEOUT_OPTION,
    DriverOptions,
    StatedTimeout,
    option,
    spec_field,
)

if TYPE_CHECKING:
    from collections.abc import Mapping

__all__ = ["FACTORY_ENCODER_MS", "FACTORY_HEARTBEAT_MS", "OdriveOptions"]

#: The factory heartbeat and encoder-estimate periods (ms).
FACTORY_HEARTBEAT_MS = 100
FACTORY_ENCODER_MS = 10

_LIVENESS = DriverOptions.specs()["liveness_s"]


@dataclass(frozen=True, kw_only=True)
class OdriveOptions(StatedTimeout):
    """The validated protocol keys of one ODrive motor block.

    :param firmware: the firmware family, ``"0.5"`` or ``"0.6"`` (:attr:`firmware_family`).
    :param extended_id: 29-bit identifiers (``axis.config.can.is_extended``).
    :param input_mode: the controller input mode when arming (1 passthrough, 2 vel_ramp).
    :param encoder_request: ``"cyclic"`` estimates, or ``"rtr"``: one request per poll.
    :param flat_endpoints: 0.6: the firmware's ``flat_endpoints.json`` (watchdog endpoint IDs).
    :param watchdog_endpoints: 0.6: the watchdog's endpoint IDs, instead of ``flat_endpoints``.
    :param config_dir: the directory a relative ``flat_endpoints`` starts from.
    :param heartbeat_msg_rate_ms: the heartbeat period set on the axis (ms).
    :param encoder_msg_rate_ms: the cyclic estimates' period set on the axis (ms; 0: off).
    """

    liveness_s: float = spec_field(
        dataclasses.replace(
            _LIVENESS,
            help="seconds without heartbeat or encoder estimates before a motor is OFFLINE",
        )
    )
    controller_timeout_s: float = spec_field(
        dataclasses.replace(
            CONTROLLER_TIMEOUT_OPTION,
            help="the axis watchdog timeout (s): on 0.6 written over CAN and read back (0: "
            "0.25 s); on 0.5 a statement of what odrivetool set (0: not stated)",
        )
    )
    firmware: str = option(
        str,
        DEFAULT_FIRMWARE.value,
        choices=tuple(f.value for f in Firmware),
        help="firmware family: 0.5 (ODrive v3.x) or 0.6 (ODrive Pro, S1, Micro)",
    )
    extended_id: bool = option(
        bool, DEFAULT_EXTENDED_ID, help="29-bit identifiers (axis.config.can.is_extended)"
    )
    input_mode: int = option(
        int,
        int(InputMode.PASSTHROUGH),
        choices=(int(InputMode.PASSTHROUGH), int(InputMode.VEL_RAMP)),
        help="controller input mode: 1 passthrough, 2 vel_ramp (the axis ramps speed)",
    )
    encoder_request: str = option(
        str,
        "cyclic",
        choices=("cyclic", "rtr"),
        help="cyclic encoder estimates, or an RTR request on every poll",
    )
    flat_endpoints: str = option(
        str,
        "",
        help="0.6: the firmware's flat_endpoints.json (from docs.odriverobotics.com/releases/"
        "firmware), for the watchdog's endpoint IDs",
    )
    watchdog_endpoints: Mapping[str, object] = option(
        dict,
        {},
        help="0.6: {fw_version, enable_watchdog, watchdog_timeout[, hw_version]}: the "
        "watchdog's endpoint IDs of that firmware version, instead of flat_endpoints",
    )
    config_dir: str = option(
        str, "", help="directory a relative flat_endpoints starts from; '' = current directory"
    )
    heartbeat_msg_rate_ms: int = option(
        int, FACTORY_HEARTBEAT_MS, minimum=1, maximum=60_000,
        help="the axis's heartbeat period as set on the ODrive (0.5: heartbeat_rate_ms; 100 "
        "from the factory), for the bus budget and liveness_s",
    )
    encoder_msg_rate_ms: int = option(
        int, FACTORY_ENCODER_MS, minimum=0, maximum=60_000,
        help="the period of the cyclic encoder estimates as set on the ODrive (0.5: "
        "encoder_rate_ms; 10 from the factory; 0: off, with encoder_request: rtr)",
    )

    @classmethod
    def validate(cls, raw: Mapping[str, object], where: str) -> dict[str, object]:
        """The keys of a motor block, checked one by one and against each other: cyclic
        estimates need a period, and ``liveness_s`` must cover two periods of the slower
        stream it watches (one late frame must not make the motor OFFLINE).

        :raises ConfigError: naming the key, what was expected and what came.
        """
        values = super().validate(raw, where)
        cyclic = values["encoder_request"] == "cyclic"
        beat, estimates = cast("int", values["heartbeat_msg_rate_ms"]), cast(
            "int", values["encoder_msg_rate_ms"])
        liveness = cast("float", values["liveness_s"])
        if cyclic and not estimates:
            raise ConfigError(f"{where}.encoder_msg_rate_ms: expected the period (ms) of the "
                              f"cyclic estimates the driver reads (encoder_request: cyclic), "
                              f"or encoder_request: rtr; got 0")
        slowest = max(beat, estimates if cyclic else 0)
        if liveness < 2 * slowest / 1000.0:
            raise ConfigError(
                f"{where}.liveness_s: expected at least two periods of the heartbeat "
                f"({beat} ms)" + (f" and the estimates ({estimates} ms)" if cyclic else "")
                + f", {2 * slowest / 1000.0:g} s, or one late frame makes the motor OFFLINE; "
                f"got {liveness:g}")
        return values

    @property
    def firmware_family(self) -> Firmware:
        """:attr:`firmware` as a :class:`~drivers.odrive.enums.Firmware`."""
        return Firmware(self.firmware)
