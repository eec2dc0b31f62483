"""The gateway's side of the bus: one burst out, everything waiting in, counted and recorded.

:class:`BusEdge` is the part of :class:`gateway.loop.Gateway` that touches python-can: a burst
that fails is counted and retried by the next cycle, :data:`REOPEN_AFTER` failed bursts in a row
reopen a bus the gateway opened itself, and every frame is tallied by ID and nominal bits (for
bus load) and handed to the recorder.
"""

from __future__ import annotations

import logging
import time
from typing import TYPE_CHECKING

import can

from gateway.bus import drain, open_bus, to_message
from gateway.busload import frame_bits
from gateway.errors import BusError

if TYPE_CHECKING:
    import collections

    from gateway.config import GatewayConfig
    from gateway.types import Frame

log = logging.getLogger("gateway.loop")

#: Consecutive failed bursts after which the bus is reopened.
REOPEN_AFTER = 20
#: Nominal bits of a standard / extended frame by data length 0..8 (busload.frame_bits).
_STD_BITS = tuple(frame_bits(n, False) for n in range(9))
_EXT_BITS = tuple(frame_bits(n, True) for n in range(9))


class BusEdge:
    """Sending, receiving, tallying and reopening, for :class:`gateway.loop.Gateway`.

    The gateway's constructor sets every attribute declared here.
    """

    config: GatewayConfig
    bus: can.BusABC
    record: can.Listener | None
    stamp_with_cycle_time: bool
    counts: dict[str, int]
    #: Frames seen per (arbitration ID, extended, transmitted), for monitors.
    id_counts: collections.Counter[tuple[int, bool, bool]]
    #: Nominal bits of every frame sent and received (bus load = rate / bitrate).
    bits: int
    _own_bus: bool
    _bus_failures: int
    _since_reopen: int

    def _open(self) -> can.BusABC:
        bus = self.config.bus
        return open_bus(bus.interface, bus.channel)

    def _reopen(self) -> None:
        if not self._own_bus:
            return
        self.counts["bus_reopens"] += 1
        log.warning("reopening the CAN bus after %d failed bursts", self._bus_failures)
        try:
            self.bus.shutdown()
            self.bus = self._open()
            self._since_reopen = 0  # the failure streak itself ends only when a burst goes out
        except BusError as err:
            log.error("reopening the CAN bus failed: %s", err)

    def send(self, frames: list[Frame]) -> bool:
        """Send one burst; a failure is counted and the next cycle tries again."""
        if not frames:
            return True
        msgs = [to_message(f) for f in frames]
        send = self.bus.send
        try:
            for msg in msgs:
                send(msg)
        except (can.CanError, OSError) as err:
            self.counts["send_failures"] += 1
            self._bus_failures += 1
            self._since_reopen += 1
            log.warning("CAN send failed (%d in a row): %s", self._bus_failures, err)
            if self._since_reopen >= REOPEN_AFTER:
                self._reopen()
            return False
        self._bus_failures = 0
        self._since_reopen = 0
        self.counts["frames_sent"] += len(msgs)
        self._tally(frames, True)
        if self.record is not None:
            stamp = time.time()
            for msg in msgs:
                msg.timestamp, msg.is_rx, msg.channel = stamp, False, self.config.bus.channel
                self.record.on_message_received(msg)
        return True

    def receive(self, now_s: float) -> list[Frame]:
        """Everything waiting on the bus, stamped with its receive time (monotonic)."""
        try:
            frames = drain(self.bus, timestamp_s=now_s if self.stamp_with_cycle_time else None)
        except BusError as err:
            self.counts["send_failures"] += 1
            log.warning("CAN receive failed: %s", err)
            return []
        if not frames:
            return frames
        self.counts["frames_received"] += len(frames)
        self._tally(frames, False)
        if self.record is not None:
            stamp = time.time()
            for f in frames:
                msg = to_message(f)
                msg.timestamp, msg.is_rx, msg.channel = stamp, True, self.config.bus.channel
                self.record.on_message_received(msg)
        return frames

    def _tally(self, frames: list[Frame], sent: bool) -> None:
        counts = self.id_counts
        get = counts.get
        bits = self.bits
        # Every frame sent and received: one tuple unpack (Frame is a NamedTuple) instead of
        # five attribute reads.
        for arb, _, extended, remote, dlc, _ in frames:
            key = (arb, extended, sent)
            counts[key] = get(key, 0) + 1
            n = 0 if remote else dlc
            if 0 <= n <= 8:
                bits += (_EXT_BITS if extended else _STD_BITS)[n]
            else:
                bits += frame_bits(n, extended)
        self.bits = bits

    @property
    def bus_healthy(self) -> bool:
        """Whether the last bursts went out (fewer failures in a row than reopen needs)."""
        return self._bus_failures < REOPEN_AFTER

    def close(self) -> None:
        """Close the bus if this gateway opened it (safe to call twice)."""
        if self._own_bus and self.bus is not None:
            self.bus.shutdown()
            self._own_bus = False
