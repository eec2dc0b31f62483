"""Twist commands from the bus: ``WG_Twist_Cmd`` frames checked and handed to the supervisor.

:class:`CanTwists` decodes each frame (:mod:`gateway.wire.can`), checks its rolling counter
(a repeated frame is a duplicate, a gap counts lost frames; a sender silent for longer than
the command timeout starts a new sequence) and acts on its flags: ESTOP (even from a
duplicate: an e-stop only ever stops), ENABLE (refused while an e-stop is latched that only
the control socket may release), STOP, or else the twist.  Errors go back as ``WG_Error``.
A frame is timed from its arrival, not from the cycle that reads it.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from gateway.core.control import Rejection, Source
from gateway.core.errors import DecodeError
from gateway.core.settings import EstopRelease
from gateway.core.types import ErrorCode, GatewayState
from gateway.wire.can import NO_TWIST_COUNTER, CounterKind, CounterTracker, TwistFlags

if TYPE_CHECKING:
    from collections.abc import Callable

    from gateway.core.control import Accepted, Supervisor
    from gateway.core.settings import LoopConfig
    from gateway.core.types import Frame, Twist
    from gateway.runtime.counts import LoopCounts
    from gateway.wire.can import WgCodec

    #: ``Gateway.twist``: a twist from a source, checked and followed.
    TwistSink = Callable[[Twist, float, Source], Accepted | Rejection]
    #: ``Gateway.report_error``: (code, message, rejection, twist counter).
    ErrorSink = Callable[[ErrorCode, str, Rejection | None, int], None]


class CanTwists:
    """The gateway's CAN command input.

    :param wg: the codec of the gateway's own frames.
    :param loop: the ``gateway:`` settings (command timeout, who releases an e-stop).
    :param supervisor: the state machine the commands go to.
    :param counts: the gateway's event counters (this input counts ``can_twists``,
        ``can_duplicates``, ``can_lost`` and ``bad_can_twists``).
    :param twist: where a twist goes (checked, logged and remembered by the gateway).
    :param report: how an error is answered (``WG_Error`` and the outbox).
    """

    def __init__(self, wg: WgCodec, loop: LoopConfig, supervisor: Supervisor,
                 counts: LoopCounts, twist: TwistSink, report: ErrorSink) -> None:
        self.wg = wg
        self.loop = loop
        self.supervisor = supervisor
        self.counts = counts
        self._twist = twist
        self._report = report
        #: The rolling counter of the sender's frames.
        self.counter = CounterTracker()
        self._last_s: float | None = None

    def handle(self, frame: Frame, now_s: float) -> None:
        """A WG_Twist_Cmd from the bus (counter checked; errors answered with WG_Error, with
        the cycle's reports)."""
        try:
            cmd = self.wg.decode_twist(frame)
        except DecodeError as err:
            self.counts.bad_can_twists += 1
            self._report(ErrorCode.BAD_COMMAND, str(err), None, NO_TWIST_COUNTER)
            return
        if cmd is None:
            return
        # The frame's time is its arrival (the kernel's receive time on SocketCAN), not this
        # read: after a stalled loop, a frame that waited longer than the command timeout in
        # the receive queue is already stale, and drives nothing.
        at = min(frame.timestamp_s, now_s)
        # A sender silent for longer than the command timeout is gone: its next frame starts
        # a new sequence, even if it repeats the counter it stopped at (a restarted sender).
        last, self._last_s = self._last_s, at
        timeout = self.loop.cmd_timeout_s
        if last is not None and timeout > 0.0 and at - last > timeout:
            self.counter.reset()
        kind, lost = self.counter.feed(cmd.counter)
        counts = self.counts
        counts.can_lost += lost
        duplicate = kind is CounterKind.DUPLICATE
        if duplicate:
            counts.can_duplicates += 1
        else:
            counts.can_twists += 1
        sup = self.supervisor
        if cmd.flags & TwistFlags.ESTOP:
            # Taken even from a repeated frame: an e-stop only ever stops.
            sup.estop("e-stop requested on CAN")
            return
        if duplicate:
            return
        if cmd.flags & TwistFlags.ENABLE:
            if sup.state is GatewayState.ESTOP and self.loop.estop_release is EstopRelease.SOCKET:
                self._report(
                    ErrorCode.ESTOP, "an e-stop is released only by an enable on the control "
                    "socket (gateway.estop_release: socket); the CAN ENABLE flag was ignored",
                    None, cmd.counter)
                return
            sup.enable(now_s)
            return
        if cmd.flags & TwistFlags.STOP:
            sup.stop(at)
            return
        result = self._twist(cmd.twist, at, Source.CAN)
        if isinstance(result, Rejection):
            self._report(result.code, result.message, result, cmd.counter)
