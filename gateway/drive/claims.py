"""Which frames a driver owns, declared once: dispatch, receive filters and labels come from it.

A driver states the identifiers of its protocol's frames as :class:`FrameClaim` s (an
identifier and a mask, as a kernel receive filter has them, and the motor they belong to).
From that one declaration

* the gateway dispatches a received frame by a dictionary lookup (:class:`FrameRouter`), not
  by asking every driver in turn;
* the bus is opened with kernel receive filters (:meth:`FrameClaim.as_filter`, Linux
  ``Documentation/networking/can.rst``, "RAW Protocol Sockets with can_filters"), so foreign
  traffic never reaches the process;
* ``wheelgate monitor`` names every frame (:mod:`gateway.drive.labels`).

A frame matches a claim when ``(can_id ^ arbitration_id) & mask == 0`` and the identifier
types agree.  Claims of frames the driver only sends (its commands: ``receive=False``) serve
the labels alone.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Generic, TypeVar

from gateway.drive.filters import EXT_MASK, STD_MASK, CanFilter

if TYPE_CHECKING:
    from collections.abc import Iterable

__all__ = ["MAX_EXPANDED_IDS", "FrameClaim", "FrameRouter"]

T = TypeVar("T")

#: A claim whose mask leaves at most this many identifiers open is expanded into the router's
#: dictionary; wider claims are checked one by one after the lookup misses.
MAX_EXPANDED_IDS = 4096


@dataclass(frozen=True, slots=True)
class FrameClaim:
    """Frames of one driver, by identifier.

    :param can_id: the identifier bits to match.
    :param mask: which bits of the identifier must match (all: one identifier).
    :param extended: the identifier type (29-bit when true).
    :param motor: the index of the motor (in the driver's ``motors``) the frames belong to;
        ``None`` for frames of several motors (a DJI command for four ESCs, a CANopen SYNC).
    :param receive: whether the driver takes these frames (``False``: it only sends them).
    """

    can_id: int
    mask: int
    extended: bool
    motor: int | None = None
    receive: bool = True

    @classmethod
    def exact(
        cls, can_id: int, extended: bool, motor: int | None = None, receive: bool = True
    ) -> FrameClaim:
        """A claim of exactly one identifier."""
        return cls(can_id, EXT_MASK if extended else STD_MASK, extended, motor, receive)

    def matches(self, arbitration_id: int, is_extended_id: bool) -> bool:
        """Whether a frame with this identifier and identifier type is claimed."""
        return is_extended_id == self.extended and not (self.can_id ^ arbitration_id) & self.mask

    def overlaps(self, other: FrameClaim) -> bool:
        """Whether some identifier (of the same type) is claimed by both."""
        return self.extended == other.extended and not (
            (self.can_id ^ other.can_id) & self.mask & other.mask)

    def as_filter(self) -> CanFilter:
        """The kernel receive filter that passes the claimed frames."""
        return CanFilter(self.can_id, self.mask, self.extended)

    def identifiers(self) -> list[int] | None:
        """Every identifier claimed, or ``None`` when more than :data:`MAX_EXPANDED_IDS`."""
        full = EXT_MASK if self.extended else STD_MASK
        free = [b for b in range(full.bit_length()) if not (self.mask >> b) & 1]
        if len(free) > MAX_EXPANDED_IDS.bit_length() - 1:
            return None
        base = self.can_id & self.mask & full
        out = []
        for k in range(1 << len(free)):
            ident = base
            for j, bit in enumerate(free):
                if (k >> j) & 1:
                    ident |= 1 << bit
            out.append(ident)
        return out


class FrameRouter(Generic[T]):
    """Who owns a received frame: a lookup over the owners' claims.

    :param owners: ``(owner, claims)`` pairs in priority order: when two owners claim one
        identifier, the first wins (the configuration refuses such overlaps between the
        gateway's own messages and the drivers').
    """

    def __init__(self, owners: Iterable[tuple[T, Iterable[FrameClaim]]]) -> None:
        self._exact: dict[tuple[int, bool], T] = {}
        self._wide: list[tuple[FrameClaim, T]] = []
        self._claims: list[tuple[FrameClaim, T]] = []
        for owner, claims in owners:
            for claim in claims:
                if not claim.receive:
                    continue
                self._claims.append((claim, owner))
                ids = claim.identifiers()
                if ids is None:
                    self._wide.append((claim, owner))
                    continue
                for ident in ids:
                    self._exact.setdefault((ident, claim.extended), owner)

    def owner(self, arbitration_id: int, is_extended_id: bool) -> T | None:
        """The owner of a frame with this identifier, or ``None``."""
        found = self._exact.get((arbitration_id, is_extended_id))
        if found is not None or not self._wide:
            return found
        for claim, owner in self._wide:
            if claim.matches(arbitration_id, is_extended_id):
                return owner
        return None

    def exact(self) -> dict[tuple[int, bool], T]:
        """``(identifier, extended)`` -> owner of every identifier the lookup holds (a copy);
        the identifiers of wide claims are not in it."""
        return dict(self._exact)

    def filters(self) -> tuple[CanFilter, ...]:
        """The receive filters of every claim, without repeats, in declaration order."""
        return tuple(dict.fromkeys(c.as_filter() for c, _ in self._claims))
