"""The bus-load budget: what a configuration puts on the bus, known before power-on.

A CAN bus carries at most ``bitrate`` bits a second, and python-can's virtual bus none of that
limit (it has no bitrate and no arbitration), so a loop rate or a feedback rate the real bus
cannot carry passes every simulated test.  Each driver declares its frames as
:class:`Stream` s (:meth:`gateway.drive.driver.MotorDriver.traffic`): the commands it sends
every cycle (from :meth:`~gateway.drive.driver.MotorDriver.preview_command`), its other
periodic frames, and the frames its controllers send on their own, at the rates they are
configured to (by the gateway, or stated in the motor block) or at the firmware's factory
defaults, each stream saying which.  :class:`BusBudget` adds them up against the bitrate:

* frame lengths from :func:`gateway.wire.busload.frame_bits`: nominal, and with the worst
  case of bit stuffing;
* frames that need 100 % of the bitrate or more without a single stuff bit cannot all go out:
  ``check`` and ``run`` refuse the configuration (:data:`FULL_PERCENT`);
* everything declared above :data:`HIGH_PERCENT` with worst-case stuffing: a warning, since
  the frames of the highest identifiers then wait for arbitration, and a fault's error frames
  and retransmissions have no room left (a common design rule keeps a bus at 50-70 %).

Frames sent on events (an enable, a fault, an SDO exchange) are not counted: they are
occasional.  What a driver cannot know (a VESC's status rate not stated) is listed as
:attr:`BusBudget.unknown`, not guessed.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass
from typing import TYPE_CHECKING

from gateway.core.types import hex_id
from gateway.wire.busload import bus_load, frame_bits

if TYPE_CHECKING:
    from collections.abc import Callable, Iterable, Sequence

    from gateway.core.types import Frame

__all__ = ["FULL_PERCENT", "HIGH_PERCENT", "BusBudget", "Sender", "Stream", "Traffic",
           "frame_streams"]

#: Frames that need this share of the bitrate or more (nominal) cannot all be sent (%).
FULL_PERCENT = 100.0
#: Above this share of the bitrate (worst-case stuffing, every declared stream) ``check``
#: and ``run`` warn (%).
HIGH_PERCENT = 70.0


class Sender(enum.Enum):
    """Who puts a stream on the bus."""

    GATEWAY = "gateway"
    CONTROLLERS = "controllers"


@dataclass(frozen=True, slots=True)
class Stream:
    """Frames of one kind at one rate.

    :param name: the message (``Set_Input_Vel``, ``SYNC``), for the budget's lines.
    :param sender: who sends them.
    :param per_s: frames a second, of every motor together.
    :param dlc: data length code (a remote frame: the requested length; it carries none).
    :param extended: 29-bit identifiers.
    :param basis: where the rate comes from (``every cycle``, ``heartbeat_ms 100 written to
        0x1017``, a firmware's factory default).
    :param remote: remote frames (no data on the wire).
    """

    name: str
    sender: Sender
    per_s: float
    dlc: int
    extended: bool
    basis: str
    remote: bool = False

    def bits_per_s(self, worst_case: bool = False) -> float:
        """The stream's bits a second (``worst_case``: with the most stuff bits)."""
        return self.per_s * frame_bits(0 if self.remote else self.dlc, self.extended, worst_case)


@dataclass(frozen=True, slots=True)
class Traffic:
    """A driver's declaration: its streams, and what it cannot know (one line each)."""

    streams: tuple[Stream, ...]
    unknown: tuple[str, ...] = ()


def frame_streams(frames: Iterable[Frame], per_s: float,
                  name: Callable[[int, bool], str | None], sender: Sender,
                  basis: str) -> list[Stream]:
    """The streams of ``frames`` sent ``per_s`` times a second each, grouped by message
    (``name(arbitration_id, is_extended_id)``: the protocol's name, else the identifier) and
    shape, in order."""
    counts: dict[tuple[str, int, bool, bool], int] = {}
    for f in frames:
        ext = f.is_extended_id
        label = name(f.arbitration_id, ext) or hex_id(f.arbitration_id, ext)
        key = (label, f.dlc, f.is_extended_id, f.is_remote_frame)
        counts[key] = counts.get(key, 0) + 1
    return [Stream(label, sender, n * per_s, dlc, ext, basis, remote)
            for (label, dlc, ext, remote), n in counts.items()]


@dataclass(frozen=True, slots=True)
class BusBudget:
    """Every declared stream of one bus against its bitrate (see the module docstring).

    :param streams: every driver's streams.
    :param bitrate: the bus's bit rate (bit/s).
    :param unknown: what is not counted, one line each (a driver's unknown rates; a driver
        that declares nothing).
    """

    streams: tuple[Stream, ...]
    bitrate: int
    unknown: tuple[str, ...] = ()

    def per_s(self, sender: Sender | None = None) -> float:
        """Frames a second (of ``sender`` only, when given)."""
        return sum(s.per_s for s in self._of(sender))

    def load(self, worst_case: bool = False, sender: Sender | None = None) -> float:
        """The bus load (% of the bitrate) of every stream (of ``sender`` only, when given)."""
        return bus_load(sum(s.bits_per_s(worst_case) for s in self._of(sender)), self.bitrate)

    def _of(self, sender: Sender | None) -> Sequence[Stream]:
        return self.streams if sender is None else [s for s in self.streams
                                                    if s.sender is sender]

    def full(self) -> bool:
        """Whether the declared streams need the whole bus even without stuff bits."""
        return self.load() >= FULL_PERCENT

    def high(self) -> bool:
        """Whether everything declared needs more than :data:`HIGH_PERCENT` (worst case)."""
        return self.load(worst_case=True) > HIGH_PERCENT

    def summary(self) -> str:
        """One line: the load, nominal to worst case, and the frames a second."""
        return (f"{self.load():.1f}-{self.load(worst_case=True):.1f} % of "
                f"{self.bitrate / 1000:g} kbit/s ({self.per_s():.0f} frames/s: gateway "
                f"{self.per_s(Sender.GATEWAY):.0f}, controllers "
                f"{self.per_s(Sender.CONTROLLERS):.0f})")

    def brief(self) -> str:
        """Every stream in a few words, the largest first (``2000/s Set_Input_Vel``)."""
        return ", ".join(f"{s.per_s:.0f}/s {s.name}" for s in sorted(
            self.streams, key=lambda s: s.bits_per_s(), reverse=True))

    def lines(self) -> list[str]:
        """One line per stream (sender, frames a second, name and shape, basis), then each
        unknown."""
        out = []
        for s in self.streams:
            shape = "RTR" if s.remote else f"{s.dlc} B"
            idt = ", 29-bit" if s.extended else ""
            out.append(f"{s.sender.value:<11} {s.per_s:>7.1f}/s  {s.name} ({shape}{idt}): "
                       f"{s.basis}")
        out.extend(f"not counted: {u}" for u in self.unknown)
        return out
