"""Who is on the bus: the identifiers heard, sorted into controllers by the protocols' probes.

Pure: the traffic heard (:class:`~gateway.drive.scan.Heard`) goes in, :class:`Classified`
comes out.  The gateway's own messages (the configuration's ``gateway.can_ids``) are taken
out first; then each probe, in :attr:`~gateway.drive.scan.ScanProbe.PRECEDENCE` order, finds
its controllers among what is left, and every identifier a controller found owns is offered to
no later probe.  An ODrive at node 12 and a CANopen node 1 both use 0x181 (the heartbeat of
the one, TPDO1 of the other): once the CANopen node is found by its heartbeat on 0x701, 0x181 is
its own, and no ODrive is made of it.  What no controller owns is listed as unknown.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from collections.abc import Iterable, Mapping, Sequence

    from gateway.drive.scan import Found, Heard, ScanProbe


@dataclass(frozen=True, slots=True)
class Sighting:
    """One controller found: its probe, what showed it, and the identifiers it owns."""

    probe: ScanProbe
    found: Found
    heard: tuple[Heard, ...]


@dataclass(frozen=True, slots=True)
class Classified:
    """The identifiers heard, sorted.

    :param devices: the controllers found, in probe order, then by node.
    :param own: the gateway's own messages heard, ``(message name, traffic)``.
    :param unknown: everything else.
    """

    devices: tuple[Sighting, ...] = ()
    own: tuple[tuple[str, Heard], ...] = ()
    unknown: tuple[Heard, ...] = ()

    def owner(self, arbitration_id: int, extended: bool) -> Sighting | None:
        """The controller found that owns this identifier (sends or takes it), if any."""
        for s in self.devices:
            if s.probe.owns(s.found, arbitration_id, extended):
                return s
        return None


def classify(probes: Sequence[ScanProbe], heard: Iterable[Heard],
             own_ids: Mapping[tuple[int, bool], str],
             answered: Iterable[tuple[ScanProbe, Found]] = ()) -> Classified:
    """Sort the identifiers heard into controllers (see the module).

    :param probes: in precedence order.
    :param own_ids: ``(identifier, extended)`` -> message name of the gateway's own messages.
    :param answered: controllers that answered a discovery request (a VESC's PONG), with their
        probe: found even when they sent nothing else.
    """
    left: list[Heard] = []
    own: list[tuple[str, Heard]] = []
    for h in sorted(heard, key=lambda h: (h.is_extended_id, h.arbitration_id)):
        name = own_ids.get((h.arbitration_id, h.is_extended_id))
        if name is None:
            left.append(h)
        else:
            own.append((name, h))
    extra = list(answered)
    devices: list[Sighting] = []
    for probe in probes:
        found: dict[tuple[int, bool], Found] = {}
        for f in [*probe.find(left), *(f for p, f in extra if p is probe)]:
            found.setdefault((f.node_id, f.extended), f)  # unasked traffic first
        for key in sorted(found):
            f = found[key]
            mine = tuple(h for h in left if probe.owns(f, h.arbitration_id, h.is_extended_id))
            devices.append(Sighting(probe, f, mine))
            taken = {id(h) for h in mine}
            left = [h for h in left if id(h) not in taken]
    return Classified(tuple(devices), tuple(own), tuple(left))
