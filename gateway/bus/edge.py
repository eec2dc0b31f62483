"""The gateway's side of the bus: one burst out, everything waiting in, counted and recorded.

:class:`BusEdge` is the object through which the gateway's loop touches python-can: it holds
the bus (and reopens it), sends, receives, tallies and records.

Sending keeps the promise of one burst per cycle as far as the bus allows.  A transmit queue
that is full (``ENOBUFS`` from a SocketCAN interface whose controller is slower than the
host, or the words of an interface without an ``errno``, PCAN's "Transmit queue is full":
:data:`~gateway.bus.health.NO_ROOM_TEXT`) is waited for, in steps of
:data:`ROOM_POLL_S`, within :data:`SEND_BUDGET` of the cycle's period; what still does not
fit is left out of this cycle and goes *first* in the next burst
(:class:`~gateway.bus.health.BurstTracker`), and a frame left out :data:`UNSENT_FAULT_CYCLES`
bursts in a row is reported in :attr:`BusEdge.starved` (the loop makes it a fault that names
the motor).  An interface that is down or gone (``ENETDOWN``, ``ENODEV``, a closed socket),
or :data:`REOPEN_AFTER` failed bursts in a row, reopens a bus the gateway opened itself,
with exponential backoff (:data:`REOPEN_FIRST_S` doubling to :data:`REOPEN_MAX_S`).

Receiving drains the queue; error frames are decoded by class into :attr:`BusEdge.bus_errors`
(a state change, bus-off above all, is left in :attr:`BusEdge.bus_state_change` for the loop),
CAN FD frames are counted and ignored, and receive errors are counted apart from send
failures.  Every kind of trouble logs at most one line per :data:`LOG_EVERY_S`, with the count
since the last.  Every frame is tallied by ID and nominal bits (for bus load) and handed to
the recorder.  The tally counts each frame's (ID, extended, remote, DLC) in C
(``Counter.update`` over ``operator.itemgetter``); :attr:`BusEdge.id_counts` and
:attr:`BusEdge.bits` are summed from those counts when read (at status rate).
"""

from __future__ import annotations

import collections
import logging
import math
import operator
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import can

from gateway.bus.can_bus import MessagePool, drain, open_bus, to_message
from gateway.bus.health import (
    GONE,
    NO_ROOM,
    NO_ROOM_TEXT,
    Backoff,
    BurstTracker,
    BusErrors,
    ErrorFrame,
    LogThrottle,
)
from gateway.core.errors import BusError
from gateway.core.status import BusErrorState
from gateway.wire.busload import frame_bits

if TYPE_CHECKING:
    from gateway.core.settings import GatewayConfig
    from gateway.core.types import Frame

log = logging.getLogger("gateway.runtime.loop")

#: Consecutive failed bursts after which the bus is reopened.
REOPEN_AFTER = 20
#: The first delay between reopen attempts, and the longest (s).
REOPEN_FIRST_S = 0.1
REOPEN_MAX_S = 5.0
#: The share of the cycle's period a burst may wait for room in a full transmit queue.
SEND_BUDGET = 0.3
#: How long to wait between two tries while the transmit queue is full (s).
ROOM_POLL_S = 0.0002
#: Bursts in a row that may leave one frame unsent before it is a fault.
UNSENT_FAULT_CYCLES = 10
#: The shortest time between two log lines about one kind of bus trouble (s).
LOG_EVERY_S = 5.0
#: A frame's (arbitration ID, extended, remote, DLC): what its tally and its bits depend on
#: (``Frame`` is a NamedTuple: arbitration_id, data, is_extended_id, is_remote_frame, dlc, ...).
_SHAPE = operator.itemgetter(0, 2, 3, 4)


def bus_options(interface: str, filters: list[dict[str, Any]] | None) -> dict[str, Any]:
    """The keyword arguments the gateway opens its bus with.

    On ``socketcan``: CAN FD frames are received (``fd``) so that they can be counted and
    ignored instead of vanishing in the kernel, and ``filters``, when given, become the
    socket's kernel receive filters (``CAN_RAW_FILTER``), so foreign traffic never wakes the
    loop.  Other interfaces get neither: python-can filters ``virtual`` in software, and its
    ``recv(0)`` then returns ``None`` at the first frame that does not match, which would end
    the drain early.
    """
    if interface != "socketcan":
        return {}
    out: dict[str, Any] = {"fd": True}
    if filters is not None:
        out["can_filters"] = filters
    return out


def _errno(err: BaseException) -> int | None:
    code = getattr(err, "error_code", None)
    if not isinstance(code, int):
        code = getattr(err, "errno", None)
    return code if isinstance(code, int) else None


def _no_room(err: BaseException) -> bool:
    """Whether a send failed for want of room in the transmit queue (worth a short wait)."""
    return _errno(err) in NO_ROOM or NO_ROOM_TEXT.search(str(err)) is not None


def _gone(err: BaseException) -> bool:
    """Whether a send failed because the interface is down, gone or closed."""
    return _errno(err) in GONE or "closed bus" in str(err)


@dataclass(slots=True)
class EdgeCounts:
    """What the bus edge counted since start (in the status's ``counters``)."""

    #: Frames that went out.
    frames_sent: int = 0
    #: Classical frames received (error frames and CAN FD frames not included).
    frames_received: int = 0
    #: Bursts cut short: a frame refused after the wait for room.
    send_failures: int = 0
    #: Times the bus was closed and opened again.
    bus_reopens: int = 0
    #: Drains of the bus that failed.
    receive_failures: int = 0
    #: Frames left out of their burst.
    frames_unsent: int = 0
    #: Bursts that went out in part.
    partial_bursts: int = 0
    #: Waits for room in a full transmit queue.
    send_waits: int = 0
    #: CAN FD frames received (and ignored).
    fd_frames_ignored: int = 0


class BusEdge:
    """Sending, receiving, tallying and reopening, for the gateway's loop.

    :param config: the configuration (the bus section, for reopening and messages).
    :param bus: an open python-can bus; opened from the config (with ``bus_kwargs``) when
        ``None``, and then closed by :meth:`close` and reopened after failures.
    :param period_s: the loop period (the time a burst may wait for room is a share of it).
    :param bus_kwargs: keyword arguments of every (re)open (:func:`bus_options`).
    :param record: a python-can writer that gets every frame sent and received.
    :param stamp_with_cycle_time: stamp received frames with the time :meth:`receive` is
        given (simulated time in tests) instead of their own receive time.
    """

    def __init__(
        self,
        config: GatewayConfig,
        bus: can.BusABC | None,
        period_s: float,
        bus_kwargs: dict[str, Any],
        record: can.Listener | None = None,
        stamp_with_cycle_time: bool = False,
    ) -> None:
        self.config = config
        #: Frames, failures and reopens since start.
        self.counts = EdgeCounts()
        self.period_s = period_s
        #: Keyword arguments of every (re)open: kernel receive filters, FD frames.
        self.bus_kwargs = bus_kwargs
        #: A python-can writer that gets every frame sent and received.
        self.record = record
        #: Stamp received frames with the cycle's time instead of their receive time.
        self.stamp_with_cycle_time = stamp_with_cycle_time
        #: Error frames by class and the controller's error state.
        self.bus_errors = BusErrors()
        #: The error state the last error frames moved to, until the loop takes it.
        self.bus_state_change: BusErrorState | None = None
        #: (identifier, extended, bursts) of a frame that missed :data:`UNSENT_FAULT_CYCLES`
        #: bursts in a row, until the loop takes it.
        self.starved: tuple[int, bool, int] | None = None
        self.bursts = BurstTracker(UNSENT_FAULT_CYCLES)
        self._backoff = Backoff(REOPEN_FIRST_S, REOPEN_MAX_S)
        self._send_log = LogThrottle(LOG_EVERY_S)
        self._recv_log = LogThrottle(LOG_EVERY_S)
        self._reopen_log = LogThrottle(LOG_EVERY_S)
        self._error_log = LogThrottle(LOG_EVERY_S)
        self._odd: list[can.Message] = []
        self._drained_s = -math.inf  # the last receive's time: drain's since_s
        self._messages = MessagePool()
        self._last_send_error = ""
        #: The last failed burst's error when it was not a full transmit queue (an interface
        #: down or gone), ``None`` when it was: what a starved command's fault says.
        self.send_gone: str | None = None
        self._bus_failures = 0
        self._since_reopen = 0
        # Frames by _SHAPE: received ([0]) and sent ([1]).
        self._shapes: tuple[collections.Counter[tuple[int, bool, bool, int]], ...] = (
            collections.Counter(), collections.Counter())
        self._own_bus = bus is None
        #: The python-can bus (a new object after a reopen).
        self.bus: can.BusABC = bus if bus is not None else self._open(check_link=True)

    def _open(self, check_link: bool = False) -> can.BusABC:
        bus = self.config.bus
        return open_bus(bus.interface, bus.channel, bus.bitrate, check_link, **self.bus_kwargs)

    def _reopen(self, now_s: float) -> None:
        if not self._own_bus or not self._backoff.due(now_s):
            return
        self.counts.bus_reopens += 1
        delay = self._backoff.failed(now_s)  # reset once a burst goes out again
        note = self._reopen_log.note(now_s)
        if note is not None:
            log.warning("reopening the CAN bus %s:%s (%d reopens since the last report, next "
                        "try in %.1f s unless frames go out): %s", self.config.bus.interface,
                        self.config.bus.channel, note, delay, self._last_send_error)
        try:
            self.bus.shutdown()
        except (can.CanError, OSError) as err:
            log.debug("closing the failed bus: %s", err)
        try:
            self.bus = self._open()
            self._since_reopen = 0  # the failure streak itself ends only when a burst goes out
        except BusError as err:
            if note is not None:
                log.error("reopening the CAN bus failed: %s", err)

    def send(self, frames: list[Frame], now_s: float | None = None, tracked: bool = True) -> bool:
        """Send one burst (see the module's doc for what happens when the bus cannot).

        :param now_s: the cycle's time, for the reopen backoff and log throttles
            (``time.monotonic()`` when omitted).
        :param tracked: the frames are commands: ones left out go first next time and are a
            fault after :data:`UNSENT_FAULT_CYCLES` bursts (the gateway's own periodic
            reports are not: the next one replaces a lost one).
        :return: whether every frame went out.
        """
        if not frames:
            return True
        bursts = self.bursts
        if tracked and bursts.missed:
            frames = bursts.order(frames)
        msgs = self._messages.messages(frames)
        send = self.bus.send
        sent = 0
        try:
            for msg in msgs:
                send(msg)
                sent += 1
        except (can.CanError, OSError) as err:
            sent = self._send_rest(msgs, sent, err, time.monotonic() if now_s is None else now_s)
        n = len(msgs)
        if sent < n:
            self.counts.frames_unsent += n - sent
            if sent:
                self.counts.partial_bursts += 1
        if tracked and (sent < n or bursts.missed):
            worst = bursts.after_send(frames, sent)
            if worst is not None:
                (can_id, extended), misses = worst
                self.starved = (can_id, extended, misses)
        if sent and self._bus_failures:
            self._bus_failures = 0
            self._since_reopen = 0
            self._backoff.reset()
        if not sent:
            return False
        self.counts.frames_sent += sent
        if sent < n:
            frames = frames[:sent]
        self._tally(frames, True)
        if self.record is not None:
            stamp = time.time()
            for f in frames:  # the writer may keep them: not the pool's
                msg = to_message(f)
                msg.timestamp, msg.is_rx, msg.channel = stamp, False, self.config.bus.channel
                self.record.on_message_received(msg)
        return sent == n

    def _send_rest(self, msgs: list[can.Message], sent: int, err: BaseException,
                   now_s: float) -> int:
        """The rest of a burst after a refused frame: wait for room within the budget.

        :return: how many of ``msgs`` have gone out in all.
        """
        end = time.perf_counter() + SEND_BUDGET * self.period_s
        while _no_room(err) and time.perf_counter() < end:
            self.counts.send_waits += 1
            time.sleep(ROOM_POLL_S)
            try:
                for msg in msgs[sent:]:
                    self.bus.send(msg)
                    sent += 1
                return sent
            except (can.CanError, OSError) as again:
                err = again
        self.counts.send_failures += 1
        if not sent:  # a slow bus that takes part of each burst is not mended by a reopen
            self._bus_failures += 1
            self._since_reopen += 1
        self._last_send_error = str(err)
        self.send_gone = None if _no_room(err) else str(err)
        note = self._send_log.note(now_s)
        if note is not None:
            log.warning("CAN send failed: %d bursts cut short since the last report (%d in a "
                        "row with nothing sent, %d frames left out in all): %s", note,
                        self._bus_failures, self.counts.frames_unsent + len(msgs) - sent, err)
        if _gone(err) or self._since_reopen >= REOPEN_AFTER:
            self._reopen(now_s)
        return sent

    def receive(self, now_s: float) -> list[Frame]:
        """Everything waiting on the bus, stamped with its receive time (monotonic)."""
        odd = self._odd
        try:
            since, self._drained_s = self._drained_s, now_s
            frames = drain(self.bus, timestamp_s=now_s if self.stamp_with_cycle_time else None,
                           odd=odd, since_s=since)
        except BusError as err:
            self.counts.receive_failures += 1
            note = self._recv_log.note(now_s)
            if note is not None:
                log.warning("CAN receive failed %d times since the last report: %s", note, err)
            return []
        if odd:
            self._take_odd(odd, now_s)
        if not frames:
            return frames
        self.counts.frames_received += len(frames)
        self._tally(frames, False)
        if self.record is not None:
            stamp = time.time()
            for f in frames:
                msg = to_message(f)
                msg.timestamp, msg.is_rx, msg.channel = stamp, True, self.config.bus.channel
                self.record.on_message_received(msg)
        return frames

    def _take_odd(self, odd: list[can.Message], now_s: float) -> None:
        """Error frames and CAN FD frames the drain put aside."""
        errors = self.bus_errors
        for msg in odd:
            if not msg.is_error_frame:
                self.counts.fd_frames_ignored += 1
                if self.counts.fd_frames_ignored == 1:
                    log.warning("a CAN FD frame (ID 0x%X) on %s: ignored and counted (the "
                                "drivers speak classic CAN)", msg.arbitration_id,
                                self.config.bus.channel)
                continue
            change = errors.take(ErrorFrame.decode(msg.arbitration_id, bytes(msg.data)))
            if change is not None:
                self.bus_state_change = change
                log.warning("CAN controller of %s is now %s: %s", self.config.bus.channel,
                            change.value.replace("_", "-"), errors.last)
            elif self._error_log.note(now_s) is not None:
                log.warning("CAN error frames on %s (%d in all): %s", self.config.bus.channel,
                            errors.counts["error_frames"], errors.last)
        odd.clear()

    def _tally(self, frames: list[Frame], sent: bool) -> None:
        self._shapes[sent].update(map(_SHAPE, frames))

    @property
    def id_counts(self) -> collections.Counter[tuple[int, bool, bool]]:
        """Frames seen per (arbitration ID, extended, transmitted), for monitors (a new
        counter on every read)."""
        out: collections.Counter[tuple[int, bool, bool]] = collections.Counter()
        for sent, shapes in enumerate(self._shapes):
            for (can_id, extended, _, _), n in shapes.items():
                out[can_id, extended, bool(sent)] += n
        return out

    @property
    def bits(self) -> int:
        """Nominal bits of every frame sent and received (bus load = rate / bitrate)."""
        return sum(n * frame_bits(0 if remote else dlc, extended)
                   for shapes in self._shapes
                   for (_, extended, remote, dlc), n in shapes.items())

    @property
    def errors_recent(self) -> bool:
        """Whether the last burst failed or the controller is not error-active (the status's
        BUS_ERRORS_RECENT flag)."""
        return bool(self._bus_failures) or self.bus_errors.state is not BusErrorState.ACTIVE

    @property
    def bus_healthy(self) -> bool:
        """Whether frames go out (fewer failed bursts in a row than reopen needs) and the
        controller is not bus-off."""
        return (self._bus_failures < REOPEN_AFTER
                and self.bus_errors.state is not BusErrorState.BUS_OFF)

    def close(self) -> None:
        """Close the bus if this gateway opened it (safe to call twice)."""
        if self._own_bus and self.bus is not None:
            self.bus.shutdown()
            self._own_bus = False
