"""What the CAN bus itself reports and does, kept apart from the frames it carries.

Pure and clock-free (times are passed in), so every rule here is tested on simulated time:

* :class:`ErrorFrame`: a SocketCAN error frame decoded by class.  The kernel reports the CAN
  controller's trouble as frames with ``CAN_ERR_FLAG`` set; the class bits sit in the
  identifier and the details in the data (Linux ``include/uapi/linux/can/error.h``; the
  kernel's ``Documentation/networking/can.rst``, section "Network Problem Notifications").
* :class:`BusErrors`: the counters by class and the controller's error state (active,
  warning, passive, bus-off), which moves on the frames' own transitions.
* :class:`BurstTracker`: which frames of a burst the bus did not take (a full transmit queue,
  ``ENOBUFS``), the order of the next burst (those frames first, so one frame cannot starve
  while the others go out), and how many bursts in a row each has missed.
* :class:`LogThrottle`: one log line per interval with the count since the last, instead of a
  line per failed burst (1,000 a second at 1 kHz).
"""

from __future__ import annotations

import enum
import errno
import re
from dataclasses import dataclass
from typing import TYPE_CHECKING

from gateway.core.status import BusErrorState

if TYPE_CHECKING:
    from collections.abc import Sequence

    from gateway.core.types import Frame


class ErrorClass(enum.IntFlag):
    """The error class bits of an error frame's identifier (``CAN_ERR_*`` in ``error.h``)."""

    TX_TIMEOUT = 0x001
    LOST_ARBITRATION = 0x002
    CONTROLLER = 0x004
    PROTOCOL = 0x008
    TRANSCEIVER = 0x010
    NO_ACK = 0x020
    BUS_OFF = 0x040
    BUS_ERROR = 0x080
    RESTARTED = 0x100
    COUNTERS = 0x200


class ControllerStatus(enum.IntFlag):
    """``data[1]`` of a ``CONTROLLER`` error frame (``CAN_ERR_CRTL_*``)."""

    RX_OVERFLOW = 0x01
    TX_OVERFLOW = 0x02
    RX_WARNING = 0x04
    TX_WARNING = 0x08
    RX_PASSIVE = 0x10
    TX_PASSIVE = 0x20
    ACTIVE = 0x40


#: Counter name of each error class (status, monitor).
CLASS_COUNTERS: dict[ErrorClass, str] = {
    ErrorClass.TX_TIMEOUT: "tx_timeout",
    ErrorClass.LOST_ARBITRATION: "lost_arbitration",
    ErrorClass.CONTROLLER: "controller",
    ErrorClass.PROTOCOL: "protocol_violation",
    ErrorClass.TRANSCEIVER: "transceiver",
    ErrorClass.NO_ACK: "no_ack",
    ErrorClass.BUS_OFF: "bus_off",
    ErrorClass.BUS_ERROR: "bus_error",
    ErrorClass.RESTARTED: "restarted",
}
_TEXT: dict[ErrorClass, str] = {
    ErrorClass.TX_TIMEOUT: "transmit timeout",
    ErrorClass.LOST_ARBITRATION: "lost arbitration",
    ErrorClass.CONTROLLER: "controller problem",
    ErrorClass.PROTOCOL: "protocol violation",
    ErrorClass.TRANSCEIVER: "transceiver problem",
    ErrorClass.NO_ACK: "no ACK (no other node on the bus, or none at this bitrate)",
    ErrorClass.BUS_OFF: "bus-off",
    ErrorClass.BUS_ERROR: "bus error",
    ErrorClass.RESTARTED: "controller restarted",
}


_NO_STATUS = ControllerStatus(0)


@dataclass(frozen=True, slots=True)
class ErrorFrame:
    """One error frame.

    :param classes: the class bits of its identifier.
    :param controller: the controller status of ``data[1]`` (``CONTROLLER`` frames).
    :param tx_errors: the transmit error counter (``data[6]``, ``COUNTERS`` frames), else -1.
    :param rx_errors: the receive error counter (``data[7]``), else -1.
    """

    classes: ErrorClass
    controller: ControllerStatus = _NO_STATUS
    tx_errors: int = -1
    rx_errors: int = -1

    @classmethod
    def decode(cls, can_id: int, data: bytes) -> ErrorFrame:
        """Decode an error frame's identifier (without ``CAN_ERR_FLAG``) and data.

        Unknown class bits are kept; short data reads as zeros (an error frame always has
        eight bytes on SocketCAN, but a replayed log may not).
        """
        raw = bytes(data).ljust(8, b"\0")
        classes = ErrorClass(can_id & 0x1FFFFFFF)
        controller = (ControllerStatus(raw[1] & 0x7F) if classes & ErrorClass.CONTROLLER
                      else _NO_STATUS)
        counters = bool(classes & ErrorClass.COUNTERS)
        return cls(classes, controller, raw[6] if counters else -1, raw[7] if counters else -1)

    def describe(self) -> str:
        """A short text, e.g. ``"bus-off"`` or ``"controller problem (TX_PASSIVE)"``."""
        parts = []
        for flag, text in _TEXT.items():
            if self.classes & flag:
                detail = (f" ({self.controller.name})"
                          if flag is ErrorClass.CONTROLLER and self.controller else "")
                parts.append(text + detail)
        if self.tx_errors >= 0:
            parts.append(f"error counters tx {self.tx_errors} rx {self.rx_errors}")
        return ", ".join(parts) or f"error frame of class 0x{int(self.classes):X}"

    def state(self) -> BusErrorState | None:
        """The controller state this frame reports, if it reports one."""
        if self.classes & ErrorClass.BUS_OFF:
            return BusErrorState.BUS_OFF
        if self.classes & ErrorClass.RESTARTED:
            return BusErrorState.ACTIVE
        c = self.controller
        if c & (ControllerStatus.RX_PASSIVE | ControllerStatus.TX_PASSIVE):
            return BusErrorState.PASSIVE
        if c & (ControllerStatus.RX_WARNING | ControllerStatus.TX_WARNING):
            return BusErrorState.WARNING
        if c & ControllerStatus.ACTIVE:
            return BusErrorState.ACTIVE
        return None


class BusErrors:
    """Error frames counted by class, and the controller's error state they report."""

    def __init__(self) -> None:
        #: Error frames seen, in all and by class (:data:`CLASS_COUNTERS`).
        self.counts: dict[str, int] = {"error_frames": 0, **dict.fromkeys(
            CLASS_COUNTERS.values(), 0)}
        self.state = BusErrorState.ACTIVE
        #: The description of the last error frame.
        self.last = ""

    def take(self, frame: ErrorFrame) -> BusErrorState | None:
        """Count one error frame; return the new state when it changes the state.

        Bus-off ends only with a restart (``RESTARTED``) or an explicit ``ACTIVE`` report:
        a passive or warning report while bus-off does not lift it.
        """
        counts = self.counts
        counts["error_frames"] += 1
        for flag, name in CLASS_COUNTERS.items():
            if frame.classes & flag:
                counts[name] += 1
        self.last = frame.describe()
        new = frame.state()
        if new is None or new is self.state:
            return None
        if self.state is BusErrorState.BUS_OFF and new in (
            BusErrorState.WARNING, BusErrorState.PASSIVE
        ):
            return None
        self.state = new
        return new


#: ``errno`` values of a send that found no room in the transmit queue: wait and retry.
NO_ROOM = frozenset({errno.ENOBUFS, errno.EAGAIN})
#: The same said in words, by interfaces whose vendor library gives python-can no ``errno``:
#: SocketCAN's send timeout ("Transmit buffer full", python-can's
#: ``can/interfaces/socketcan/socketcan.py``), PCAN-Basic's PCAN_ERROR_QXMTFULL and
#: PCAN_ERROR_XMTFULL ("Transmit queue is full", "Transmit buffer in CAN controller is full":
#: ``PCANBasic.h``; python-can's ``pcan.py`` raises "Failed to send: " and the library's text),
#: SYSTEC's ("Tx-buffer is full", "Transmit queue is full": ``systec/ucan.py``; "a CAN message
#: did not fit into the transmit buffer": ``systec/exceptions.py``) and Kvaser's
#: canERR_TXBUFOFL ("Transmit buffer overflow").  A queue or buffer (not SYSTEC's Rx-buffer)
#: and "full" within a few words: no other error text of python-can's interfaces reads so.
NO_ROOM_TEXT = re.compile(r"(?<!rx-)\b(?:queue|buffer)\b[\w\s-]{0,30}?\bfull\b"
                          r"|transmit buffer overflow|did not fit into the transmit buffer",
                          re.IGNORECASE)
#: ``errno`` values of an interface that is down or gone: reopen (with backoff).
GONE = frozenset({errno.ENETDOWN, errno.ENODEV, errno.ENXIO, errno.EBADF, errno.ENETUNREACH})


class BurstTracker:
    """What the bus did not take of the bursts, and what goes first in the next one.

    A burst the transmit queue cannot hold is cut where the queue refused; the frames left
    over go *first* in the next burst, the longest left out first (the burst's order among
    equals), so no command frame starves behind the others while the bus is slow: with room
    for ``k`` of ``n`` frames a cycle, each goes out at least every ``ceil(n / k)`` cycles.
    A frame key (identifier and type) that stays unsent for ``fault_after`` bursts in a row
    that contained it is reported by :meth:`after_send`.

    :param fault_after: bursts in a row after which an unsent frame is a fault.
    """

    def __init__(self, fault_after: int) -> None:
        self.fault_after = fault_after
        #: (identifier, extended) -> bursts in a row that left it unsent.
        self.missed: dict[tuple[int, bool], int] = {}

    def order(self, frames: list[Frame]) -> list[Frame]:
        """The burst with the frames left over last time first (stable)."""
        missed = self.missed
        if not missed:
            return frames
        first = [f for f in frames if (f.arbitration_id, f.is_extended_id) in missed]
        if not first:
            return frames
        # Longest left out first: in the burst's own order, a queue with room for one frame a
        # cycle would send the first two wheels' commands by turns and never the others'.
        first.sort(key=lambda f: -missed[f.arbitration_id, f.is_extended_id])
        return first + [f for f in frames if (f.arbitration_id, f.is_extended_id) not in missed]

    def after_send(self, frames: Sequence[Frame], sent: int) -> tuple[tuple[int, bool], int] | None:
        """Record that the first ``sent`` of ``frames`` went out (frames that were not in
        this burst keep their count: the periodic reports go out in bursts of their own).

        :return: the key that has now missed ``fault_after`` bursts in a row (the one that
            missed most when several have), with its count; ``None`` otherwise.
        """
        missed = self.missed
        for f in frames[:sent]:
            missed.pop((f.arbitration_id, f.is_extended_id), None)
        worst: tuple[tuple[int, bool], int] | None = None
        for f in frames[sent:]:
            key = (f.arbitration_id, f.is_extended_id)
            n = missed.get(key, 0) + 1
            missed[key] = n
            if n >= self.fault_after and (worst is None or n > worst[1]):
                worst = (key, n)
        return worst


def unsent_why(interface: str, channel: str, gone: str | None) -> str:
    """Why a command frame has not gone out, and what to check, for the fault's message.

    :param gone: the send error of an interface that is down or gone (``None``: the transmit
        queue stays full, which on CAN most often means that no other node acknowledges the
        frames, as the controller then retransmits each for ever).
    """
    if gone:
        check = (f"check that {channel} is up (ip link show {channel})" if interface == "socketcan"
                 else f"check that the {interface} interface {channel} is connected")
        return f"sending fails ({gone}): {check}"
    queue = ", the interface's txqueuelen" if interface == "socketcan" else ""
    return ("the CAN transmit queue stays full (no other node acknowledges the frames, or the "
            "bus is slower than the commands: check that the controllers are powered and "
            f"connected, the bitrate{queue} and the bus load)")


def bus_off_restart(interface: str, channel: str) -> str:
    """How the interface leaves bus-off, for the fault's message ('' where python-can's
    interface restarts itself or needs the bus reopened)."""
    return (f" (the kernel restarts it with 'ip link set {channel} type can restart-ms 100')"
            if interface == "socketcan" else "")


def since_last(count: int, what: str) -> str:
    """The tail of a throttled log line: `` (N <what> since the last such line)`` when more
    than this one occurred (:meth:`LogThrottle.note`'s count), else nothing."""
    return f" ({count} {what} since the last such line)" if count > 1 else ""


class LogThrottle:
    """At most one log line per ``interval_s`` for one kind of trouble, with the count.

    :param interval_s: the shortest time between two lines.
    """

    def __init__(self, interval_s: float) -> None:
        self.interval_s = interval_s
        self._next_s = -float("inf")
        self._since = 0
        #: Every occurrence, logged or not.
        self.total = 0

    def note(self, now_s: float) -> int | None:
        """Count one occurrence at ``now_s``.

        :return: how many occurred since the last line (this one included) when a line is
            due now, else ``None``.
        """
        self.total += 1
        self._since += 1
        if now_s < self._next_s:
            return None
        n, self._since = self._since, 0
        self._next_s = now_s + self.interval_s
        return n


class Backoff:
    """Exponential backoff for reopening a bus: ``first_s``, doubling up to ``max_s``.

    :param first_s: the first delay.
    :param max_s: the longest delay.
    """

    def __init__(self, first_s: float, max_s: float) -> None:
        self.first_s = first_s
        self.max_s = max_s
        self._delay_s = first_s
        self._next_s: float | None = None

    def due(self, now_s: float) -> bool:
        """Whether an attempt may be made at ``now_s`` (the first one at once)."""
        return self._next_s is None or now_s >= self._next_s

    def failed(self, now_s: float) -> float:
        """An attempt at ``now_s`` did not help: the next waits longer.

        :return: the delay until the next attempt.
        """
        delay = self._delay_s
        self._next_s = now_s + delay
        self._delay_s = min(delay * 2.0, self.max_s)
        return delay

    def reset(self) -> None:
        """The trouble is over: the next trouble starts with ``first_s`` again."""
        self._delay_s = self.first_s
        self._next_s = None
