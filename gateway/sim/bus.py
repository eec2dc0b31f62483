"""Puts device simulators on a python-can bus (the edge around :mod:`gateway.sim.device`).

:class:`SimulatedControllers` opens its own connection to a (normally ``virtual``) channel,
answers every frame the gateway sends through the matching simulators and emits their periodic
frames.  It runs either in a background thread (``start()``, used by ``--sim`` and end-to-end
tests) or stepped by hand (``step(now_s)``, for deterministic tests).
"""

from __future__ import annotations

import logging
import threading
import time
from typing import TYPE_CHECKING, Any

from gateway.bus.can_bus import drain, open_bus, send_frames
from gateway.core.errors import BusError
from gateway.core.lifecycle import Closing

if TYPE_CHECKING:
    from collections.abc import Callable, Sequence

    from gateway.sim.device import DeviceSimulator

log = logging.getLogger(__name__)


class SimulatedControllers(Closing):
    """Simulated motor controllers on one bus.

    :param simulators: the device simulators, one per motor.
    :param channel: the bus channel to join.
    :param interface: python-can interface (``virtual`` unless testing something else).
    :param rate_hz: how often the background thread steps the simulators.
    """

    def __init__(
        self,
        simulators: Sequence[DeviceSimulator],
        channel: str,
        interface: str = "virtual",
        rate_hz: float = 1000.0,
        **bus_kwargs: Any,
    ) -> None:
        self.simulators = tuple(simulators)
        self.period_s = 1.0 / rate_hz
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._lock = threading.Lock()
        #: Errors the background thread met (it keeps running).
        self.errors = 0
        #: Steps the background thread made, and how many of them started a period or more
        #: late (the simulators then ran on, their motors integrated over the longer step).
        self.steps = 0
        self.late_steps = 0
        #: Called with the step's time after every step, under the lock (ground truth).
        self.on_step: Callable[[float], None] | None = None
        #: What ended the background thread, if anything but :meth:`shutdown` did.
        self.failure: BaseException | None = None
        self.bus = open_bus(interface, channel, **bus_kwargs)
        self._open = True
        self._stepped_s = float("-inf")  # the last real-time step's time (drain's since_s)

    def step(self, now_s: float, real_time: bool = False) -> int:
        """Handle every waiting frame, tick every simulator, send what they emit.

        :param real_time: ``now_s`` is ``time.monotonic()`` (the background thread): each
            frame is handled at its own receive time, the motors advanced to it first, as a
            real controller answers a frame when it comes (a CiA 402 drive's TPDO holds its
            position at the SYNC).  Handled all at ``now_s`` instead, the frames that waited
            while this process was starved (a loaded machine) were answered with the position
            of before the wait, and the next answer stepped by the whole wait at once.
            Otherwise (stepped by hand on simulated time) every frame is handled at ``now_s``.
        :return: the number of frames sent.
        """
        with self._lock:
            out = []
            if real_time:
                frames = drain(self.bus, since_s=self._stepped_s)  # monotonic receive times
                self._stepped_s = now_s
            else:
                frames = drain(self.bus)
            for frame in frames:
                t = min(frame.timestamp_s, now_s) if real_time else now_s
                for sim in self.simulators:
                    if real_time:
                        sim.advance(t)
                    out.extend(sim.handle(frame, t))
            for sim in self.simulators:
                out.extend(sim.tick(now_s))
            if self.on_step is not None:
                self.on_step(now_s)
            return send_frames(self.bus, out, now_s)

    def start(self) -> SimulatedControllers:
        """Run :meth:`step` in a daemon thread until :meth:`shutdown`."""
        if self._thread is None:
            self._thread = threading.Thread(target=self._run, name="wheelgate-sim", daemon=True)
            self._thread.start()
        return self

    def snapshot(self, read: Callable[[], Any]) -> Any:
        """``read()`` under the lock: a consistent view of the simulators from another thread."""
        with self._lock:
            return read()

    def _run(self) -> None:
        try:
            self._loop()
        except BaseException as err:
            self.failure = err
            raise

    def _loop(self) -> None:
        deadline = time.monotonic()
        while not self._stop.is_set():
            now = time.monotonic()
            self.steps += 1
            if now - deadline >= self.period_s:
                self.late_steps += 1
            try:
                self.step(now, real_time=True)
            except BusError as err:
                self.errors += 1
                log.warning("simulated controllers: %s", err)
            deadline += self.period_s
            delay = deadline - time.monotonic()
            if delay < -10 * self.period_s:
                deadline = time.monotonic()
            self._stop.wait(max(delay, 0.0))

    def is_alive(self) -> bool:
        """Whether the background thread runs (see :attr:`failure` when it stopped by
        itself)."""
        return self._thread is not None and self._thread.is_alive()

    def close(self) -> None:
        """The same as :meth:`shutdown`."""
        self.shutdown()

    def shutdown(self) -> None:
        """Stop the thread and close the bus (safe to call twice)."""
        if not self._open:
            return
        self._open = False
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
        self.bus.shutdown()

    def __del__(self) -> None:
        if getattr(self, "_open", False):
            log.warning("SimulatedControllers was not shut down")
