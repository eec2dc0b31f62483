"""Who is on the bus: the identifiers heard, sorted into controllers by the protocols' probes.

Pure: the traffic heard (:class:`~gateway.drive.scan.Heard`) goes in, :class:`Classified`
comes out.  The gateway's own messages (the configuration's ``gateway.can_ids``) are taken
out first; then each probe, in :attr:`~gateway.drive.scan.ScanProbe.PRECEDENCE` order, finds
its controllers among what is left, and every identifier a controller found owns is offered to
no later probe.  An ODrive at node 12 and a CANopen node 1 both use 0x181 (the heartbeat of
the one, TPDO1 of the other): once the CANopen node is found by its heartbeat on 0x701, 0x181 is
its own, and no ODrive is made of it.  What no controller owns is listed as unknown.

With a configuration, the frames each configured motor's driver declares as that motor's
(:class:`~gateway.apps.scan.own.MotorClaims`) are the motor's: they are offered only to the
probe of the motor's own driver (an ODrive's heartbeat still shows the ODrive, and its
version is asked), and what that probe does not take is the motor's all the same
(:class:`Configured`; a DBC controller, which no probe knows, is found this way).  No other
protocol's controller is made of them.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from collections.abc import Iterable, Mapping, Sequence

    from gateway.apps.scan.own import MotorClaims
    from gateway.drive.scan import Found, Heard, ScanProbe


@dataclass(frozen=True, slots=True)
class Sighting:
    """One controller found: its probe, what showed it, and the identifiers it owns."""

    probe: ScanProbe
    found: Found
    heard: tuple[Heard, ...]


@dataclass(frozen=True, slots=True)
class Configured:
    """A configured motor heard on the identifiers its driver declares, with no probe's
    controller made of them."""

    claimed: MotorClaims
    heard: tuple[Heard, ...]


@dataclass(frozen=True, slots=True)
class Classified:
    """The identifiers heard, sorted.

    :param devices: the controllers found, in probe order, then by node.
    :param own: the gateway's own messages heard, ``(message name, traffic)``.
    :param unknown: everything else.
    :param configured: the configured motors heard only on their declared identifiers.
    """

    devices: tuple[Sighting, ...] = ()
    own: tuple[tuple[str, Heard], ...] = ()
    unknown: tuple[Heard, ...] = ()
    configured: tuple[Configured, ...] = ()

    def owner(self, arbitration_id: int, extended: bool) -> Sighting | None:
        """The controller found that owns this identifier (sends or takes it), if any."""
        for s in self.devices:
            if s.probe.owns(s.found, arbitration_id, extended):
                return s
        return None


def classify(probes: Sequence[ScanProbe], heard: Iterable[Heard],
             own_ids: Mapping[tuple[int, bool], str],
             answered: Iterable[tuple[ScanProbe, Found]] = (),
             claimed: Sequence[MotorClaims] = ()) -> Classified:
    """Sort the identifiers heard into controllers (see the module).

    :param probes: in precedence order.
    :param own_ids: ``(identifier, extended)`` -> message name of the gateway's own messages.
    :param answered: controllers that answered a discovery request (a VESC's PONG), with their
        probe: found even when they sent nothing else.
    :param claimed: the configured motors' declared identifiers (first claim wins).
    """
    left: list[Heard] = []
    own: list[tuple[str, Heard]] = []
    #: Per configured motor, the traffic on its identifiers.
    motors: list[list[Heard]] = [[] for _ in claimed]
    for h in sorted(heard, key=lambda h: (h.is_extended_id, h.arbitration_id)):
        name = own_ids.get((h.arbitration_id, h.is_extended_id))
        k = next((k for k, c in enumerate(claimed)
                  if c.owns(h.arbitration_id, h.is_extended_id)), None)
        if name is not None:
            own.append((name, h))
        elif k is not None:
            motors[k].append(h)
        else:
            left.append(h)
    extra = list(answered)
    devices: list[Sighting] = []
    for probe in probes:
        theirs = [h for c, hs in zip(claimed, motors, strict=True)
                  if c.motor.driver == probe.DRIVER for h in hs]
        offered = left + theirs
        found: dict[tuple[int, bool], Found] = {}
        for f in [*probe.find(offered), *(f for p, f in extra if p is probe)]:
            found.setdefault((f.node_id, f.extended), f)  # unasked traffic first
        for key in sorted(found):
            f = found[key]
            mine = tuple(h for h in offered
                         if probe.owns(f, h.arbitration_id, h.is_extended_id))
            devices.append(Sighting(probe, f, mine))
            taken = {id(h) for h in mine}
            offered = [h for h in offered if id(h) not in taken]
            left = [h for h in left if id(h) not in taken]
            motors = [[h for h in hs if id(h) not in taken] for hs in motors]
    configured = tuple(Configured(c, tuple(hs)) for c, hs in zip(claimed, motors, strict=True)
                       if hs)
    return Classified(tuple(devices), tuple(own), tuple(left), configured)
