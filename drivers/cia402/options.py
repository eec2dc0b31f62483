"""Protocol keys of a CiA 402 motor block, described once, and their parsed form.

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
(:mod:`drivers.cia402.driver` gives the reasons for the mode).

Controller-side protection (:mod:`drivers.cia402.protection`): the gateway produces a heartbeat
as NMT node ``host_node_id`` every ``host_heartbeat_s``; each drive's heartbeat consumer
(CiA 301 object 0x1016) watches it with the consumer time ``controller_timeout_s``, and the
drive's abort connection option code (CiA 402 object 0x6007) says what it does when the
heartbeat stops: ``abort_connection_option`` 3 (quick stop) or 2 (disable voltage).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from drivers.cia402.codec import PdoLayout
from drivers.cia402.enums import OperationMode
from gateway.core.errors import ConfigError
from gateway.drive.driver import MotorDriver, OptionSpec

if TYPE_CHECKING:
    from gateway.core.types import MotorConfig

#: 2^31: the position objects (0x6064, 0x607A) are int32.
_INT32_LIMIT = float(1 << 31)

#: Default liveness timeout (s): feedback TPDOs run at the loop rate, heartbeats every 100 ms.
DEFAULT_LIVENESS_S = 0.25

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

#: Every protocol key of a ``driver: cia402`` motor block.
OPTIONS: dict[str, OptionSpec] = {
    "velocity_factor": OptionSpec(
        float, 1.0, minimum=1e-9,
        help="device velocity units per motor RPM (units = motor RPM x factor)",
    ),
    "counts_per_rev": OptionSpec(
        int, 4096, minimum=1,
        help="position units (0x6064, 0x607A) per motor revolution (encoder increments)",
    ),
    "sync": OptionSpec(
        bool, True, help="PDOs on SYNC, which the driver sends once per command cycle"
    ),
    "heartbeat_ms": OptionSpec(
        int, 100, minimum=0, maximum=0xFFFF, help="producer heartbeat time written to 0x1017"
    ),
    "event_timer_ms": OptionSpec(
        int, 10, minimum=1, maximum=0xFFFF,
        help="TPDO event timer when sync is false (0x18xx:05)",
    ),
    "liveness_s": OptionSpec(
        float, DEFAULT_LIVENESS_S, minimum=1e-3,
        help="silence (no heartbeat, PDO, EMCY or SDO) after which a node is OFFLINE",
    ),
    "rpdo": OptionSpec(int, 4, minimum=1, maximum=4, help="RPDO number for the command"),
    "tpdo_position": OptionSpec(
        int, 3, minimum=1, maximum=4, help="TPDO number for statusword + position"
    ),
    "tpdo_velocity": OptionSpec(
        int, 4, minimum=1, maximum=4, help="TPDO number for statusword + velocity"
    ),
    "host_node_id": OptionSpec(
        int, DEFAULT_HOST_NODE_ID, minimum=1, maximum=127,
        help="the gateway's own NMT node ID: it sends its heartbeat on 0x700 + this ID, which "
        "each drive's heartbeat consumer (0x1016) watches; no drive may use it",
    ),
    "host_heartbeat_s": OptionSpec(
        float, DEFAULT_HOST_HEARTBEAT_S, minimum=0.001, maximum=10.0,
        help="period of the gateway's heartbeat (s), sent while its loop runs",
    ),
    "controller_timeout_s": OptionSpec(
        float, DEFAULT_CONTROLLER_TIMEOUT_S, minimum=0.002, maximum=65.535,
        help="heartbeat consumer time written to the drive's 0x1016:01 (s, whole ms): without "
        "the gateway's heartbeat for this long the drive acts on abort_connection_option; at "
        "least twice host_heartbeat_s",
    ),
    "abort_connection_option": OptionSpec(
        int, 3, choices=ABORT_CONNECTION_OPTIONS,
        help="abort connection option code written to 0x6007: 3 quick stop (the drive's quick "
        "stop option code 0x605A, by default a ramp to standstill), 2 disable voltage (the "
        "motor coasts)",
    ),
}


class _Options(MotorDriver):
    """Only borrows :meth:`MotorDriver.validate_options` with our :data:`OPTIONS`."""

    OPTIONS = OPTIONS


@dataclass(frozen=True, slots=True)
class NodeOptions:
    """The protocol keys of one motor block, validated, with defaults filled in."""

    velocity_factor: float = 1.0
    counts_per_rev: int = 4096
    sync: bool = True
    heartbeat_ms: int = 100
    event_timer_ms: int = 10
    liveness_s: float = DEFAULT_LIVENESS_S
    layout: PdoLayout = field(default_factory=PdoLayout)
    #: Mode of operation written to 0x6060: profile velocity for a drive motor, cyclic
    #: synchronous position for a steering actuator.
    mode: OperationMode = OperationMode.PROFILE_VELOCITY
    #: The gateway's own NMT node ID (its heartbeat: 0x700 + this).
    host_node_id: int = DEFAULT_HOST_NODE_ID
    #: The gateway's heartbeat period (s).
    host_heartbeat_s: float = DEFAULT_HOST_HEARTBEAT_S
    #: The heartbeat consumer time written to 0x1016:01 (s, a whole number of ms).
    controller_timeout_s: float = DEFAULT_CONTROLLER_TIMEOUT_S
    #: The abort connection option code written to 0x6007.
    abort_connection_option: int = 3

    @property
    def consumer_time_ms(self) -> int:
        """:attr:`controller_timeout_s` in whole milliseconds (0x1016 bits 15..0)."""
        return round(self.controller_timeout_s * 1000.0)

    @property
    def position_mode(self) -> bool:
        """Whether the node runs in cyclic synchronous position mode (a steering actuator)."""
        return self.mode is OperationMode.CYCLIC_SYNCHRONOUS_POSITION

    @classmethod
    def from_motor(cls, motor: MotorConfig) -> NodeOptions:
        """Validate ``motor.options`` (and, for a steering actuator, ``zero_rad``).

        :raises ConfigError: for an unknown key, a bad value, both feedback TPDOs on one PDO
            number, a ``controller_timeout_s`` shorter than two ``host_heartbeat_s`` or not a
            whole number of milliseconds, or a steering actuator with ``sync: false`` or a
            ``zero_rad`` outside the drive's int32 position range.
        """
        where = f"wheel {motor.wheel!r} (node {motor.node_id})"
        opts = _Options.validate_options(motor.options, where)
        layout = PdoLayout(
            rpdo=int(opts["rpdo"]),  # type: ignore[call-overload]
            tpdo_position=int(opts["tpdo_position"]),  # type: ignore[call-overload]
            tpdo_velocity=int(opts["tpdo_velocity"]),  # type: ignore[call-overload]
        )
        if layout.tpdo_position == layout.tpdo_velocity:
            raise ConfigError(
                f"{where}.tpdo_velocity: expected a TPDO other than tpdo_position "
                f"({layout.tpdo_position}), got {layout.tpdo_velocity}"
            )
        counts_per_rev = int(opts["counts_per_rev"])  # type: ignore[call-overload]
        period = float(opts["host_heartbeat_s"])  # type: ignore[arg-type]
        timeout = float(opts["controller_timeout_s"])  # type: ignore[arg-type]
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
        mode = OperationMode.PROFILE_VELOCITY
        if motor.steering:
            mode = OperationMode.CYCLIC_SYNCHRONOUS_POSITION
            if not opts["sync"]:
                raise ConfigError(
                    f"{where}.sync: expected true for a steering actuator (cyclic synchronous "
                    f"position mode takes its target at every SYNC), got false"
                )
            limit = _INT32_LIMIT * 2.0 * math.pi / counts_per_rev
            if not -limit <= motor.zero_rad < limit:
                raise ConfigError(
                    f"{where}.zero_rad: expected a motor position within the drive's int32 "
                    f"position range (-{limit:.6g} to {limit:.6g} rad at {counts_per_rev} "
                    f"counts per revolution), got {motor.zero_rad!r}"
                )
        return cls(
            velocity_factor=float(opts["velocity_factor"]),  # type: ignore[arg-type]
            counts_per_rev=counts_per_rev,
            sync=bool(opts["sync"]),
            heartbeat_ms=int(opts["heartbeat_ms"]),  # type: ignore[call-overload]
            event_timer_ms=int(opts["event_timer_ms"]),  # type: ignore[call-overload]
            liveness_s=float(opts["liveness_s"]),  # type: ignore[arg-type]
            layout=layout,
            mode=mode,
            host_node_id=int(opts["host_node_id"]),  # type: ignore[call-overload]
            host_heartbeat_s=period,
            controller_timeout_s=timeout,
            abort_connection_option=int(opts["abort_connection_option"]),  # type: ignore[call-overload]
        )

    def rpm_to_units(self, motor_rpm: float) -> float:
        """Device velocity units for a motor speed in RPM."""
        return motor_rpm * self.velocity_factor

    def units_to_rad_s(self, units: float) -> float:
        """Motor speed in rad/s for device velocity units."""
        return units / self.velocity_factor * (2.0 * math.pi / 60.0)

    def rad_s_to_units(self, motor_rad_s: float) -> float:
        """Device velocity units (not rounded) for a motor speed in rad/s."""
        return motor_rad_s * (60.0 / (2.0 * math.pi)) * self.velocity_factor

    def counts_to_rad(self, counts: int) -> float:
        """Motor angle in rad for position units."""
        return counts * (2.0 * math.pi) / self.counts_per_rev

    def rad_to_counts(self, motor_rad: float) -> float:
        """Position units (not rounded, not wrapped) for a motor angle in rad."""
        return motor_rad * self.counts_per_rev / (2.0 * math.pi)
