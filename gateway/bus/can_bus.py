"""The only module that touches ``can.Bus`` and ``can.Message``.

It converts between python-can messages and wheelgate's frozen :class:`~gateway.core.types.Frame`,
and wraps python-can errors into :class:`~gateway.core.errors.BusError`.
"""

from __future__ import annotations

import errno
import inspect
import logging
import math
import sys
import time
from typing import TYPE_CHECKING, Any

import can

from gateway.core.errors import BusError
from gateway.core.types import Frame, frame_of

if TYPE_CHECKING:
    from collections.abc import Iterable

log = logging.getLogger(__name__)


#: ``can.Message``'s leading parameters, in order; positional arguments cost about half of
#: keywords, and every frame of every cycle goes through :func:`to_message`.
_MESSAGE_PARAMS = ("timestamp", "arbitration_id", "is_extended_id", "is_remote_frame",
                   "is_error_frame", "channel", "dlc", "data")
_POSITIONAL = tuple(inspect.signature(can.Message).parameters)[:8] == _MESSAGE_PARAMS


def to_message(frame: Frame) -> can.Message:
    """A python-can message for ``frame``."""
    if _POSITIONAL:
        return can.Message(0.0, frame.arbitration_id, frame.is_extended_id,
                           frame.is_remote_frame, False, None, frame.dlc, frame.data)
    return can.Message(  # pragma: no cover - a python-can with another parameter order
        arbitration_id=frame.arbitration_id,
        data=frame.data,
        is_extended_id=frame.is_extended_id,
        is_remote_frame=frame.is_remote_frame,
        dlc=frame.dlc,
    )


class MessagePool:
    """One ``can.Message`` per identifier, refilled for every send instead of built anew.

    A command goes out every cycle on the same few identifiers, and building a
    ``can.Message`` costs more than filling one: the pool keeps one message per identifier
    and copies the frame's payload into it.  This relies on python-can's interfaces taking
    the message's content during ``send()`` (``virtual`` deep-copies it, ``socketcan`` packs it
    into a ``struct can_frame``: ``can/interfaces/virtual.py`` and ``socketcan/socketcan.py``,
    ``send``), so a message handed to ``send()`` may be refilled once it returns.  Whoever
    keeps a message beyond the call (a recorder) gets its own (:func:`to_message`).
    """

    __slots__ = ("_pool",)

    def __init__(self) -> None:
        self._pool: dict[int, can.Message] = {}

    def messages(self, frames: Iterable[Frame]) -> list[can.Message]:
        """The pool's messages filled with ``frames``, in order.

        Two frames of one burst on the same identifier get two messages (the second one a
        new object), so a burst never sends one message twice; a remote frame gets a message
        of its own.
        """
        pool = self._pool
        out = []
        for f in frames:
            msg = pool.get(f.arbitration_id)
            if f.is_remote_frame:  # (rare: a request) built as it is, not pooled
                msg = to_message(f)
            elif msg is None or msg.is_extended_id is not f.is_extended_id or msg in out:
                msg = pool[f.arbitration_id] = to_message(f)
            else:
                msg.data[:] = f.data
                msg.dlc = f.dlc
            out.append(msg)
        return out


def to_frame(msg: can.Message, timestamp_s: float | None = None) -> Frame:
    """A frame for a python-can message.

    :param timestamp_s: receive time to record; the message's own stamp when omitted.
    """
    remote = msg.is_remote_frame
    # Past Frame.__new__ (frame_of): more than half the cost of converting a message.
    return frame_of((
        msg.arbitration_id,
        b"" if remote else bytes(msg.data),
        msg.is_extended_id,
        remote,
        msg.dlc,
        msg.timestamp if timestamp_s is None else timestamp_s,
    ))


def open_bus(interface: str, channel: str, bitrate: int | None = None,
             check_link: bool = True, **kwargs: Any) -> can.BusABC:
    """Open a python-can bus.

    :param bitrate: the bus's bitrate (bit/s), ``None`` when nobody stated one.  An adapter
        that python-can drives itself (``pcan``, ``kvaser``, ``slcan``, ``gs_usb`` ...) is set
        to it: python-can's own default (500 kbit/s for most) would leave a 1 Mbit/s robot
        deaf.  A SocketCAN interface's bitrate is the kernel's, so it is checked instead
        (:mod:`gateway.bus.link`): one that states another is refused, one that is down is
        warned about with the command that brings it up.
    :param check_link: whether to check a SocketCAN interface (not at a reopen: the loop's
        thread runs no ``ip``, and the reopens say enough about an interface that is down).
    :raises BusError: if python-can cannot open it, or the interface runs at another bitrate.
    """
    if bitrate is not None:
        if interface == "socketcan":
            if check_link:
                _check_link(channel, bitrate)
        else:  # (python-can's virtual and network interfaces take it and ignore it)
            kwargs["bitrate"] = bitrate
    try:
        return can.Bus(interface=interface, channel=channel, **kwargs)
    except (can.CanError, OSError, ValueError, ImportError) as err:
        if interface == "socketcan":
            hint = _socketcan_hint(err, channel)
        else:
            hint = _adapter_hint(interface, channel, bitrate)
        raise BusError(f"Cannot open CAN bus {interface}:{channel}: {err}{hint}") from err


def _socketcan_hint(err: BaseException, channel: str) -> str:
    """What to do about the two errors a first SocketCAN bus meets (errno from the socket or
    its cause): no CAN in the kernel, no such interface."""
    codes = {getattr(e, "errno", None) for e in (err, err.__cause__, err.__context__)}
    if errno.EAFNOSUPPORT in codes:
        return ("; this kernel has no SocketCAN: load it (modprobe can_raw, and the adapter's "
                "driver); to try wheelgate without hardware: wheelgate run --sim")
    if errno.ENODEV in codes:
        return (f"; there is no network interface {channel!r} (ip -details link show lists "
                f"them; a test bus: modprobe vcan; ip link add dev vcan0 type vcan; ip link set "
                f"vcan0 up)")
    return ""


def _check_link(channel: str, bitrate: int) -> None:
    from gateway.bus.link import judge_link  # noqa: PLC0415 - a real bus only

    refusal, warning = judge_link(channel, bitrate)
    if refusal is not None:
        raise BusError(f"Cannot use CAN bus socketcan:{channel}: {refusal}")
    if warning is not None:
        log.warning("%s", warning)


#: python-can interfaces whose adapters Linux also drives as SocketCAN interfaces: the kernel
#: driver, and what python-can's interface needs installed.
_ADAPTERS: dict[str, tuple[str, str]] = {
    "slcan": ("slcan", "pyserial: pip install 'python-can[serial]'"),
    "gs_usb": ("gs_usb (candleLight firmware)",
               "pyusb and gs_usb: pip install 'python-can[gs-usb]'"),
    "pcan": ("peak_usb", "PEAK-System's PCAN-Basic library"),
    "kvaser": ("kvaser_usb", "Kvaser's CANlib"),
}

#: slcand's ``-s`` codes (the LAWICEL ``S0`` .. ``S8`` commands; can-utils ``slcand.c``), by
#: bitrate.
_SLCAN_SPEEDS = {10_000: 0, 20_000: 1, 50_000: 2, 100_000: 3, 125_000: 4, 250_000: 5,
                 500_000: 6, 800_000: 7, 1_000_000: 8}


def _adapter_hint(interface: str, channel: str, bitrate: int | None) -> str:
    """What python-can's interface needs installed (the usual reason it cannot open), and on
    Linux the SocketCAN way to the same adapter, the usual one there."""
    kernel, needs = _ADAPTERS.get(interface, ("", ""))
    if not kernel:
        return ""
    hint = f"; python-can's {interface} interface needs {needs}"
    if sys.platform.startswith("linux"):
        rate = "" if bitrate is None else f" bitrate {bitrate}"
        if interface == "slcan":
            speed = _SLCAN_SPEEDS.get(bitrate or 0)
            tty = channel.split("@", maxsplit=1)[0]  # (python-can's slcan channel may end in @baud)
            up = (f"sudo slcand -o{'' if speed is None else f' -s{speed}'} {tty} can0 && "
                  f"sudo ip link set can0 up")
        else:
            up = f"sudo ip link set can0 up type can{rate}"
        hint += (f"; on Linux the kernel's {kernel} driver makes this adapter a SocketCAN "
                 f"interface, the usual way there: {up}, then --interface socketcan "
                 f"--channel can0 (ip -details link show names it)")
    return hint


def send_frames(bus: can.BusABC, frames: Iterable[Frame], timestamp_s: float = 0.0) -> int:
    """Send frames in order, their messages stamped ``timestamp_s`` (what a virtual bus with
    ``preserve_timestamps`` passes on: a simulated device's send time).

    :return: how many were sent.
    :raises BusError: on the first frame that python-can refuses.
    """
    sent = 0
    for frame in frames:
        msg = to_message(frame)
        msg.timestamp = timestamp_s
        try:
            bus.send(msg)
        except (can.CanError, OSError) as err:
            raise BusError(f"Sending {frame.to_cansend()} failed: {err}") from err
        sent += 1
    return sent


#: A message stamp further than this from the wall clock is not trusted (s).
_PLAUSIBLE_S = 1.0


def arrival(stamp_s: float, wall_s: float, now_s: float, since_s: float,
            max_age_s: float = _PLAUSIBLE_S) -> float:
    """When a message arrived, on the caller's monotonic clock: ``now_s`` less its age by its
    own stamp (python-can stamps with the wall clock; on socketcan the kernel's receive time),
    ``wall_s`` being the wall clock at ``now_s``.  Not before ``since_s`` (when the previous
    read began: nothing waiting now came earlier; a wall clock that stepped since would say
    so).  A stamp older than ``max_age_s`` (an interface's own epoch) or in the future is not
    trusted: the arrival is then ``now_s``.  (:func:`drain` applies this rule written out,
    with the default bound: the per-frame cost of receiving.)

    >>> arrival(99.5, 100.0, 7.0, 6.0), arrival(99.5, 100.0, 7.0, 6.8)
    (6.5, 6.8)
    >>> arrival(95.0, 100.0, 7.0, 0.0), arrival(95.0, 100.0, 7.0, 0.0, max_age_s=60.0)
    (7.0, 2.0)
    """
    age = wall_s - stamp_s
    if not 0.0 <= age <= max_age_s:
        return now_s
    return max(now_s - age, since_s)


def drain(
    bus: can.BusABC,
    limit: int = 10_000,
    timestamp_s: float | None = None,
    odd: list[can.Message] | None = None,
    since_s: float = -math.inf,
) -> list[Frame]:
    """Every frame waiting in ``bus``'s receive queue.

    Error frames and CAN FD frames are not returned (they carry nothing for the drivers,
    which speak classic CAN); they go to ``odd`` when given, for the bus's health.

    :param timestamp_s: the receive time on the caller's clock (simulated time in tests): a
        frame keeps a stamp of its own on that clock (a simulated device's send time, on a
        virtual bus that keeps stamps) when it lies after ``since_s`` and at most this; every
        other frame gets this time.  When omitted, each frame keeps the time python-can
        stamped on it (the kernel's receive time on socketcan), moved from the wall clock onto
        ``time.monotonic()`` so it compares with the loop's clock; a stamp more than a second
        away from the wall clock (an interface with its own epoch) is replaced by the time of
        receipt.
    :param since_s: when the previous drain began (monotonic): no frame waiting now arrived
        before it, nor after now.  A stamp moved onto the monotonic clock outside that span is
        put at its edge: the wall clock stepped (NTP) between the kernel's stamp and this
        drain, which would make a fresh frame look as old as the step, or as new.

    :raises BusError: if receiving fails.
    """
    out: list[Frame] = []
    if limit <= 0:
        return out
    try:
        msg = bus.recv(0.0)
        if msg is None:
            return out  # the common case at a high loop rate: nothing waiting
        wall, mono = time.time(), time.monotonic()
        offset = mono - wall
        make, recv = frame_of, bus.recv
        for k in range(limit):
            if k:
                msg = recv(0.0)
                if msg is None:
                    break
            if msg.is_error_frame or msg.is_fd:
                if odd is not None:
                    odd.append(msg)
                continue
            if timestamp_s is not None:
                stamp = msg.timestamp
                if not since_s < stamp <= timestamp_s:
                    stamp = timestamp_s
            elif abs(msg.timestamp - wall) <= _PLAUSIBLE_S:  # arrival(), written out
                stamp = msg.timestamp + offset
                if stamp < since_s:
                    stamp = since_s
                elif stamp > mono:
                    stamp = mono
            else:
                stamp = time.monotonic()
            # to_frame, inlined (the per-frame cost of receiving).
            remote = msg.is_remote_frame
            out.append(make((
                msg.arbitration_id, b"" if remote else bytes(msg.data), msg.is_extended_id,
                remote, msg.dlc, stamp,
            )))
    except (can.CanError, OSError) as err:
        raise BusError(f"Receiving failed: {err}") from err
    return out
