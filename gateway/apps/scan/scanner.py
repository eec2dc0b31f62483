"""The thin edge of ``wheelgate scan``: opens the bus, listens, sends the protocol-defined
requests the session asks for, and hands back its report.

**What goes on the bus**, all of it read-only (each probe's module says why in detail):

* ODrive: Get_Version (RTR, command 0x00) to each axis whose heartbeat was heard
  (:mod:`drivers.odrive.scan`): a read that firmware 0.6 answers and 0.5 ignores;
* VESC: PING to each controller ID 0..254 (:mod:`drivers.vesc.scan`): the firmware's own way
  of finding controllers, answered with PONG; it moves nothing and feeds no timeout;
* CANopen: expedited SDO uploads (reads) of 0x1000 and 0x1018:01..04 from each node whose
  boot-up or heartbeat was heard (:mod:`drivers.cia402.scan`): reads of objects every CiA 301
  device has; no NMT command, no SDO download, no SYNC;
* DJI: nothing (the ESCs answer no request; their feedback comes unasked).

No command, no state change, no configuration write: nothing can move a motor or disturb a
gateway that runs beside the scan (which sees the answers as foreign frames).  Requests go out
one at a time, 2 ms apart at the least, never on an identifier of another protocol's
controller found on the bus (:mod:`gateway.apps.scan.session`).
"""

from __future__ import annotations

import dataclasses
import logging
import time
from typing import TYPE_CHECKING

import can

from gateway.apps.scan.registry import load_probes
from gateway.apps.scan.session import ScanSession, ScanTiming
from gateway.bus.can_bus import arrival, open_bus, to_frame, to_message
from gateway.bus.edge import bus_options
from gateway.core.errors import BusError

if TYPE_CHECKING:
    from collections.abc import Callable, Mapping, Sequence

    from gateway.apps.scan.own import MotorClaims
    from gateway.apps.scan.report import ScanReport
    from gateway.core.types import MotorConfig
    from gateway.drive.scan import ScanProbe

log = logging.getLogger(__name__)

#: The most frames taken in one pass (the rest wait for the next: a flood starves no request).
MAX_FRAMES_PER_PASS = 1000
#: The oldest a message's own stamp may be and still be taken as its arrival (s; see
#: :func:`~gateway.bus.can_bus.arrival`): a slow host may read a busy bus's answers seconds
#: late, which the loop's one-second bound would take for an interface's own epoch.
MAX_AGE_S = 60.0


def scan_bus(bus: can.BusABC, timing: ScanTiming, bus_name: str,
             probes: Sequence[ScanProbe] | None = None,
             own_ids: Mapping[tuple[int, bool], str] | None = None,
             known: Sequence[MotorConfig] = (),
             clock: Callable[[], float] = time.monotonic,
             claimed: Sequence[MotorClaims] = ()) -> ScanReport:
    """Scan an open bus for ``timing.timeout_s`` seconds (the bus stays open).

    :param bus_name: ``interface:channel``, for the report.
    :param probes: the protocols' probes (default: every registered one).
    :param own_ids: the gateway's own messages, ``(identifier, extended)`` -> name.
    :param known: the configuration's motors, to name the controllers found.
    :param claimed: the configured motors' declared identifiers, theirs whatever they look
        like (:mod:`gateway.apps.scan.classify`).
    :raises BusError: if receiving fails.
    """
    start = since = clock()
    session = ScanSession(load_probes() if probes is None else probes, timing, start, own_ids,
                          known, claimed)
    failed: list[str] = []
    wait = 0.0
    try:
        while True:
            # Every frame waiting first, each at its arrival, before an unanswered request
            # expires: on a busy bus a slow host reads answers that came in time late.
            msg = bus.recv(wait)
            now, wall = clock(), time.time()
            for _ in range(MAX_FRAMES_PER_PASS):
                if msg is None:
                    break
                if not (msg.is_error_frame or msg.is_fd):
                    t = arrival(msg.timestamp, wall, now, since, MAX_AGE_S)
                    session.on_frame(to_frame(msg, t), t)
                msg = bus.recv(0.0)
            since = now
            if session.finished(now):
                break
            for frame in session.poll(now):
                try:
                    bus.send(to_message(frame))
                except (can.CanError, OSError) as err:
                    failed.append(f"{frame.to_cansend()}: {err}")
            wait = max(min(timing.spacing_s, start + timing.timeout_s - now), 0.0)
    except (can.CanError, OSError) as err:
        raise BusError(f"Receiving from {bus_name} failed: {err}") from err
    report = session.report(clock(), bus_name)
    if failed:
        log.warning("scan: %d request(s) not sent, the first: %s", len(failed), failed[0])
        note = f"{len(failed)} request(s) could not be sent, the first {failed[0]}"
        report = dataclasses.replace(report, notes=(*report.notes, note))
    return report


def scan(interface: str, channel: str, timeout_s: float,
         own_ids: Mapping[tuple[int, bool], str] | None = None,
         known: Sequence[MotorConfig] = (),
         claimed: Sequence[MotorClaims] = (), bitrate: int | None = None) -> ScanReport:
    """Open the bus, scan it for ``timeout_s`` seconds, close it.

    :param bitrate: the bus's bitrate when one was stated (:func:`~gateway.bus.can_bus.open_bus`).

    :raises BusError: if the bus cannot be opened or receiving fails.
    :raises DriverNotFoundError: if a built-in probe fails to load.
    """
    probes = load_probes()
    bus = open_bus(interface, channel, bitrate, **bus_options(interface, None))
    log.info("scan: listening on %s:%s for %g s", interface, channel, timeout_s)
    try:
        return scan_bus(bus, ScanTiming.for_timeout(timeout_s), f"{interface}:{channel}",
                        probes, own_ids, known, claimed=claimed)
    finally:
        bus.shutdown()
