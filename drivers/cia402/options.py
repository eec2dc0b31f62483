"""Protocol keys of a CiA 402 motor block, declared once as a dataclass (:class:`Cia402Options`).

Units:

* ``velocity_factor``: device velocity units (0x60FF, 0x606C) = motor RPM x velocity_factor.
  1.0 for a drive that counts in RPM; 10.0 for 0.1 RPM units; ``counts_per_rev / 60`` for a
  drive in increments per second.
* ``counts_per_rev``: position units (0x6064 position actual value, 0x607A target position) per
  motor revolution (encoder increments on most drives).

Both act on the motor side; ``gear_ratio`` and ``invert`` of the motor block take the value to
the wheel, ``zero_rad`` (steering actuators) to the steering angle.

A drive motor runs in profile velocity mode (3), a steering actuator in cyclic synchronous
position mode (8), which takes its target at every SYNC: ``sync: false`` is refused for it
(:func:`check_steering`; :mod:`drivers.cia402.targets` gives the reasons for the mode).

Controller-side protection (:mod:`drivers.cia402.protection`): the gateway produces a heartbeat
as NMT node ``host_node_id`` every ``host_heartbeat_s``; each drive's heartbeat consumer
(CiA 301 object 0x1016) watches it with the consumer time ``controller_timeout_s``, and the
drive's abort connection option code (CiA 402 object 0x6007) says what it does when the
heartbeat stops: ``abort_connection_option`` 3 (quick stop) or 2 (disable voltage).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, TypeVar

from drivers.cia402.codec import PdoLayout
from gateway.core.errors import ConfigError
from gateway.drive.options import DriverOptions, option, spec_field

if TYPE_CHECKING:
    from collections.abc import Mapping

    from gateway.core.types import MotorConfig

OptT = TypeVar("OptT", bound="Cia402Options")

#: 2^31: the position objects (0x6064, 0x607A) are int32.
_INT32_LIMIT = float(1 << 31)

#: The gateway's own NMT node ID by default: the highest, which drives rarely take.
DEFAULT_HOST_NODE_ID = 127
#: The gateway's heartbeat period by default (s).
DEFAULT_HOST_HEARTBEAT_S = 0.05
#: Each drive's heartbeat consumer time by default (s): four host heartbeat periods.
DEFAULT_CONTROLLER_TIMEOUT_S = 0.2
#: Abort connection option codes (0x6007) the gateway writes: 2 disable voltage, 3 quick stop.
ABORT_CONNECTION_OPTIONS = (2, 3)
#: The consumer time must be at least this many host heartbeat periods (CiA 301 leaves the
#: margin to the integrator; a late heartbeat must not trip the drive).
MIN_TIMEOUT_PERIODS = 2.0

_RAD_S_PER_RPM = 2.0 * math.pi / 60.0
_RPM_PER_RAD_S = 60.0 / (2.0 * math.pi)


@dataclass(frozen=True, kw_only=True)
class Cia402Options(DriverOptions):
    """The protocol keys of one ``driver: cia402`` motor block, validated, with defaults."""

    velocity_factor: float = option(
        float, 1.0, above=0.0,
        help="device velocity units per motor RPM (units = motor RPM x factor)",
    )
    counts_per_rev: int = option(
        int, 4096, minimum=1,
        help="position units (0x6064, 0x607A) per motor revolution (encoder increments)",
    )
    sync: bool = option(
        bool, True, help="PDOs on SYNC, which the driver sends once per command cycle"
    )
    heartbeat_ms: int = option(
        int, 100, minimum=0, maximum=0xFFFF, help="producer heartbeat time written to 0x1017"
    )
    event_timer_ms: int = option(
        int, 10, minimum=1, maximum=0xFFFF,
        help="TPDO event timer when sync is false (0x18xx:05)",
    )
    liveness_s: float = spec_field(
        dataclasses.replace(
            DriverOptions.specs()["liveness_s"],
            help="silence (no heartbeat, PDO, EMCY or SDO) after which a node is OFFLINE",
        )
    )
    response_timeout_s: float = option(
        float, 0.5, minimum=0.01, maximum=60.0,
        help="how long the enable sequence waits for each answer of the drive (an SDO "
        "response, a read-back that must match, the statusword after NMT start and after each "
        "controlword) before it fails naming the step (s)",
    )
    rpdo: int = option(int, 4, minimum=1, maximum=4, help="RPDO number for the command")
    tpdo_position: int = option(
        int, 3, minimum=1, maximum=4, help="TPDO number for statusword + position"
    )
    tpdo_velocity: int = option(
        int, 4, minimum=1, maximum=4, help="TPDO number for statusword + velocity"
    )
    host_node_id: int = option(
        int, DEFAULT_HOST_NODE_ID, minimum=1, maximum=127,
        help="the gateway's own NMT node ID: it sends its heartbeat on 0x700 + this ID, which "
        "each drive's heartbeat consumer (0x1016) watches; no drive may use it",
    )
    host_heartbeat_s: float = option(
        float, DEFAULT_HOST_HEARTBEAT_S, minimum=0.001, maximum=10.0,
        help="period of the gateway's heartbeat (s), sent while its loop runs",
    )
    controller_timeout_s: float = option(
        float, DEFAULT_CONTROLLER_TIMEOUT_S, minimum=0.002, maximum=65.535,
        help="heartbeat consumer time written to the drive's 0x1016:01 (s, whole ms): without "
        "the gateway's heartbeat for this long the drive acts on abort_connection_option; at "
        "least twice host_heartbeat_s",
    )
    abort_connection_option: int = option(
        int, 3, choices=ABORT_CONNECTION_OPTIONS,
        help="abort connection option code written to 0x6007: 3 quick stop (the drive's quick "
        "stop option code 0x605A, by default a ramp to standstill), 2 disable voltage (the "
        "motor coasts)",
    )

    @classmethod
    def from_block(cls: type[OptT], raw: Mapping[str, object], where: str) -> OptT:
        """The options of a motor block, checked key by key and against each other.

        :raises ConfigError: for an unknown key, a bad value, both feedback TPDOs on one PDO
            number, a ``controller_timeout_s`` shorter than two ``host_heartbeat_s`` or not a
            whole number of milliseconds.
        """
        opts = super().from_block(raw, where)
        if opts.tpdo_position == opts.tpdo_velocity:
            raise ConfigError(
                f"{where}.tpdo_velocity: expected a TPDO other than tpdo_position "
                f"({opts.tpdo_position}), got {opts.tpdo_velocity}"
            )
        period, timeout = opts.host_heartbeat_s, opts.controller_timeout_s
        if timeout < MIN_TIMEOUT_PERIODS * period - 1e-12:
            raise ConfigError(
                f"{where}.controller_timeout_s: expected at least {MIN_TIMEOUT_PERIODS:g} x "
                f"host_heartbeat_s ({MIN_TIMEOUT_PERIODS * period:g} s), or one late heartbeat "
                f"of the gateway stops the drive; got {timeout:g}"
            )
        if abs(timeout * 1000.0 - round(timeout * 1000.0)) > 1e-6:
            raise ConfigError(
                f"{where}.controller_timeout_s: expected a whole number of milliseconds (0x1016 "
                f"counts in ms), got {timeout!r}"
            )
        return opts

    @property
    def layout(self) -> PdoLayout:
        """The PDO numbers of the command and the two feedback messages."""
        return PdoLayout(self.rpdo, self.tpdo_position, self.tpdo_velocity)

    @property
    def consumer_time_ms(self) -> int:
        """:attr:`controller_timeout_s` in whole milliseconds (0x1016 bits 15..0)."""
        return round(self.controller_timeout_s * 1000.0)

    def rpm_to_units(self, motor_rpm: float) -> float:
        """Device velocity units for a motor speed in RPM."""
        return motor_rpm * self.velocity_factor

    def units_to_rad_s(self, units: float) -> float:
        """Motor speed in rad/s for device velocity units."""
        return units / self.velocity_factor * _RAD_S_PER_RPM

    def rad_s_to_units(self, motor_rad_s: float) -> float:
        """Device velocity units (not rounded) for a motor speed in rad/s."""
        return motor_rad_s * _RPM_PER_RAD_S * self.velocity_factor

    def rad_to_counts(self, motor_rad: float) -> float:
        """Position units (not rounded, not wrapped) for a motor angle in rad."""
        return motor_rad * self.counts_per_rev / (2.0 * math.pi)


def check_steering(motor: MotorConfig, opts: Cia402Options) -> None:
    """The keys a steering actuator (cyclic synchronous position) needs beyond its block's.

    :raises ConfigError: for ``sync: false``, or a ``zero_rad`` outside the drive's int32
        position range.
    """
    where = f"motor {motor.wheel!r}"
    if not opts.sync:
        raise ConfigError(
            f"{where}.sync: expected true for a steering actuator (cyclic synchronous "
            f"position mode takes its target at every SYNC), got false"
        )
    limit = _INT32_LIMIT * 2.0 * math.pi / opts.counts_per_rev
    if not -limit <= motor.zero_rad < limit:
        raise ConfigError(
            f"{where}.zero_rad: expected a motor position within the drive's int32 "
            f"position range (-{limit:.6g} to {limit:.6g} rad at {opts.counts_per_rev} "
            f"counts per revolution), got {motor.zero_rad!r}"
        )
