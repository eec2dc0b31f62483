"""Controller-side protection of CiA 402 drives: the gateway's heartbeat, and what each drive
does when it stops.

Without it a CiA 402 drive in OPERATION ENABLED keeps its last target velocity for ever: the
profile has no command timeout of its own, and a drive at factory settings watches nobody
(CiA 301 object 0x1016 "consumer heartbeat time": every entry 0, "not used").  So:

* the gateway is a heartbeat producer (CiA 301 "Heartbeat protocol"): from the driver's
  :meth:`~drivers.cia402.driver.Cia402Driver.poll`, every ``host_heartbeat_s``, it sends the
  one-byte heartbeat of NMT node ``host_node_id`` (COB-ID 0x700 + ID, state 0x05
  OPERATIONAL).  It comes from the loop itself, so it stops when the loop stops: a killed,
  frozen or starved gateway falls silent on the bus;
* each drive's heartbeat consumer watches it: 0x1016 sub 1 = ``host_node_id << 16 |
  consumer time in ms`` (bits 23..16 the producer's node ID, bits 15..0 the time, CiA 301).
  The consumer starts with the first heartbeat after the entry is written (CANopenNode
  ``301/CO_HBconsumer.h``: "Monitoring starts after the reception of the first HeartBeat");
  a heartbeat missing for longer than the time is a heartbeat event (EMCY 0x8130);
* the drive's abort connection option code (CiA 402 object 0x6007: 0 no action, 1 fault
  signal, 2 disable voltage, 3 quick stop; negative values manufacturer-specific) says what a
  connection abort, the heartbeat event among them, does to the drive.  The gateway writes 3
  (quick stop: what the drive's quick stop option code 0x605A says, which the gateway reads
  and reports, :mod:`drivers.cia402.quick_stop`; usually a ramp to standstill, then SWITCH ON
  DISABLED) or 2 (disable voltage: the power stage switches off and the motor coasts);
* the heartbeat event is also a communication error, after which the drive's NMT state is
  what its error behaviour says (CiA 301 object 0x1029 sub 1: 0 PRE-OPERATIONAL if
  OPERATIONAL, the CiA 301 default; 1 no state change; 2 STOPPED).  The gateway writes 0: the
  drive's PDOs stop with the heartbeat (no TPDO, and no RPDO, a late one of a gateway that
  comes back included, acts) until the enable sequence's NMT start; a drive left at 1 by its
  saved configuration would go on taking RPDOs, and with a quick stop option code 5 to 8
  (staying in QUICK STOP ACTIVE) their ENABLE OPERATION would start the motor again.  The
  object is optional: a drive without it (SDO abort 0x06020000 or 0x06090011) has the CiA 301
  default, and its read-back is skipped.

The three objects are written by expedited SDO while enabling, before NMT start and so before
any controlword, and read back; only then is the protection confirmed and the drive enabled
(:mod:`drivers.cia402.sequence`).  The consumer time is at least two producer periods
(:data:`~drivers.cia402.options.MIN_TIMEOUT_PERIODS`): CiA 301 leaves the margin to the
integrator, and a consumer time of 1.5 to 3 producer periods is the usual choice.

The heartbeat's COB-ID is declared the way every frame the gateway sends is: it is one of the
driver's claims (:meth:`~drivers.cia402.driver.Cia402Driver.claims`, sent, of no motor), and a
fresh driver's :meth:`~drivers.cia402.driver.Cia402Driver.poll` returns it, so
:func:`gateway.drive.ownership.own_id_collisions` checks it against ``gateway.can_ids``; a drive
with the same node ID (whose own heartbeat has that COB-ID) is refused here.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from drivers.cia402.codec import make_heartbeat
from drivers.cia402.enums import CobBase, NmtState
from drivers.cia402.options import DEFAULT_HOST_HEARTBEAT_S, DEFAULT_HOST_NODE_ID
from drivers.cia402.quick_stop import ABORT_QUICK_STOP, quick_stop_action
from gateway.core.cadence import next_due
from gateway.core.errors import ConfigError
from gateway.core.protection import Guard, Protection

if TYPE_CHECKING:
    from collections.abc import Sequence

    from drivers.cia402.options import Cia402Options
    from gateway.core.types import Frame, MotorConfig

#: What the drive does when the heartbeat stops with abort connection option code 2 (0x6007);
#: for 3 (quick stop), :func:`~drivers.cia402.quick_stop.quick_stop_action`.
DISABLE_VOLTAGE = "disable voltage (the power stage switches off: the motor coasts)"

#: What to do when a drive does not take the protection.
FIX = (
    "use a drive with a heartbeat consumer (CiA 301 object 0x1016), the abort connection "
    "option code (CiA 402 object 0x6007) and, if it has the error behaviour object 0x1029, "
    "its value 0 (PRE-OPERATIONAL) in 0x1029:01, see its EDS file; or set a command timeout "
    "with the vendor's tool and gateway.controller_watchdog: warn"
)


@dataclass(frozen=True, slots=True)
class HostSettings:
    """The gateway's heartbeat on one bus.

    :param node_id: the gateway's own NMT node ID (its heartbeat is 0x700 + it).
    :param period_s: the heartbeat period (s).
    """

    node_id: int
    period_s: float


def host_settings(motors: Sequence[MotorConfig], opts: Sequence[Cia402Options]) -> HostSettings:
    """The one heartbeat of a bus, from its motors' ``host_node_id`` and ``host_heartbeat_s``
    (keys every motor of the bus shares: the driver's ``BUS_WIDE``).

    :raises ConfigError: if a drive has the gateway's node ID.
    """
    if not motors:
        return HostSettings(DEFAULT_HOST_NODE_ID, DEFAULT_HOST_HEARTBEAT_S)
    host = opts[0].host_node_id
    for m in motors:
        if m.node_id == host:
            raise ConfigError(
                f"motor {m.wheel!r}.host_node_id: expected a node ID that no drive on the bus "
                f"uses (the gateway's heartbeat goes out on 0x{CobBase.HEARTBEAT + host:03X}), "
                f"got {host}, the node ID of wheel {m.wheel!r}"
            )
    return HostSettings(host, opts[0].host_heartbeat_s)


class HostHeartbeat:
    """The gateway's heartbeat producer: NMT state OPERATIONAL every :attr:`period_s`.

    The periods are kept on a fixed grid (a late cycle does not push the next heartbeat out),
    and a gap of more than a period is not made up with a burst.
    """

    def __init__(self, settings: HostSettings) -> None:
        self.node_id = settings.node_id
        self.period_s = settings.period_s
        #: The heartbeat frame (0x700 + node, ``05``).
        self.frame: Frame = make_heartbeat(settings.node_id, NmtState.OPERATIONAL)
        self._due: float | None = None

    def poll(self, now_s: float) -> list[Frame]:
        """``[heartbeat]`` when one is due at ``now_s``, else ``[]``."""
        due = self._due
        if due is not None and now_s < due - 1e-9:
            return []
        self._due = next_due(due, now_s, self.period_s)
        return [self.frame]


def describe(opts: Cia402Options,
             quick_stop: tuple[int | None, int | None] = (None, None)) -> Protection:
    """A drive's protection as the gateway configures it (:attr:`Guard.CONFIGURED`).

    :param quick_stop: the drive's quick stop option code 0x605A as read while enabling: the
        value, or ``None`` and the SDO abort code (``(None, None)``: not read yet).
    """
    option = opts.abort_connection_option
    action = (quick_stop_action(*quick_stop)[0] if option == ABORT_QUICK_STOP
              else DISABLE_VOLTAGE)
    return Protection(
        Guard.CONFIGURED,
        opts.controller_timeout_s,
        action,
        f"heartbeat consumer 0x1016 watching node {opts.host_node_id} every "
        f"{opts.consumer_time_ms} ms, abort connection option 0x6007 = {option} and error "
        "behaviour 0x1029:01 = 0 (NMT PRE-OPERATIONAL, where the drive has the object), "
        "written by SDO and read back",
        FIX,
    )
