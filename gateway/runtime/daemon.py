"""The daemon: the real-time loop around :class:`~gateway.runtime.loop.Gateway`.

It runs the cycle at absolute deadlines (sleep, then spin for the last ``spin_us``), waits for
the control socket while it sleeps so a twist is applied at the next cycle, speaks sd_notify
(READY=1 at start, once the bus is open and the socket listens -- the drives may still be
enabling, STATUS= says so --, WATCHDOG=1 from the loop while the bus takes frames, STATUS=
on every state change, STOPPING=1), and on SIGTERM or SIGINT sends zero and disarm frames
before it exits 0.  With ``--sim`` every motor gets its device simulator on the same virtual
bus in the same process.  The requests are answered by :mod:`gateway.runtime.requests`, the
events go to the subscribers in their JSON form (:mod:`gateway.wire.socket.events`).
"""

from __future__ import annotations

import dataclasses
import faulthandler
import logging
import math
import select
import signal
import threading
import time
from typing import TYPE_CHECKING, Any

import can

from gateway.config import default_socket_path
from gateway.core.errors import GatewayError
from gateway.core.types import GatewayState
from gateway.runtime.latch import EstopLatch, latch_path
from gateway.runtime.loop import Gateway
from gateway.runtime.remote import Remote
from gateway.runtime.report import announcement, build_status, status_text
from gateway.runtime.requests import RequestHandler
from gateway.runtime.sdnotify import SystemdNotifier
from gateway.runtime.server import ControlServer
from gateway.runtime.stopping import stop_motors
from gateway.runtime.timing import MissProbe, Scheduler, realtime_setup
from gateway.sim.bus import SimulatedControllers
from gateway.sim.registry import simulators_for
from gateway.wire.socket.events import event_line, event_topic

if TYPE_CHECKING:
    from collections.abc import Callable
    from types import FrameType

    from gateway.core.settings import GatewayConfig
    from gateway.core.status import GatewayStatus
    from gateway.wire.socket import ProtocolError, Request

log = logging.getLogger(__name__)

#: Every signal whose default action ends the process and that Python can catch: each one
#: stops the daemon the way SIGTERM does (zero, disarm, socket file removed, exit 0).  SIGHUP
#: included: wheelgate has no reload (a changed configuration means a restart, which re-checks
#: the controllers); SIGABRT included: systemd's watchdog sends it to a stalled loop, and once
#: the loop moves again the motors get their zero.  SIGPIPE stays ignored (Python's default:
#: a client that went away is an error on its socket, not a signal).  SIGKILL cannot be caught:
#: the controllers' own command timeouts stop the motors then.
STOP_SIGNALS: tuple[signal.Signals, ...] = tuple(
    getattr(signal, name) for name in (
        "SIGTERM", "SIGINT", "SIGHUP", "SIGQUIT", "SIGABRT", "SIGUSR1", "SIGUSR2", "SIGALRM",
        "SIGVTALRM", "SIGPROF", "SIGXCPU", "SIGXFSZ", "SIGIO", "SIGPWR", "SIGSTKFLT",
    ) if hasattr(signal, name)
)


class Daemon:
    """The running gateway: bus, optional simulators, socket, recorder, notifier.

    :param config: the configuration.
    :param sim: run every motor's device simulator on a virtual bus in this process.
    :param record: candump-format log of every frame sent and received.
    :param socket_path: the control socket; the config's, or the default, when omitted.
    :param notifier: sd_notify client; from the environment when omitted.
    :param record_mcap: record the live view's channels to this MCAP file ('' for none).
    """

    def __init__(
        self,
        config: GatewayConfig,
        sim: bool = False,
        record: str | None = None,
        socket_path: str | None = None,
        notifier: SystemdNotifier | None = None,
        record_mcap: str = "",
    ) -> None:
        if sim and config.bus.interface != "virtual":
            log.info("--sim: using the virtual bus instead of %s", config.bus.interface)
            config = dataclasses.replace(
                config, bus=dataclasses.replace(config.bus, interface="virtual")
            )
        self.config = config
        self.notifier = notifier if notifier is not None else SystemdNotifier.from_env()
        self.announce: Callable[[str], None] | None = None  #: lines for the person (run)
        self._announced_running = False
        self._stop = False
        #: The name of the signal that stopped the daemon, if one did; whether the shutdown's
        #: zero and disarm went out (every motor's, and the bus took every frame of it).
        self.stop_signal, self.stop_sent = "", False
        #: Why the shutdown sent the motors nothing ('': it sent the zero and disarm).
        self.left_to = ""
        self._closers: list[Any] = []
        self.writer: can.Listener | None = None
        try:
            if record:
                self.writer = can.CanutilsLogWriter(record)
                self._closers.append(self.writer.stop)
            self.scheduler = Scheduler(config.loop.rate_hz, spin_s=config.loop.spin_us * 1e-6)
            self.gateway = Gateway(config, record=self.writer, timer=self.scheduler.timer)
            self._closers.append(self.gateway.close)
            self.sim: SimulatedControllers | None = None
            if sim:
                # Started by run(), after realtime_setup (see there).
                self.sim = SimulatedControllers(simulators_for(self.gateway.drives.all_motors()),
                                                config.bus.channel)
                self._closers.append(self.sim.shutdown)
            path = socket_path or config.loop.socket or default_socket_path()
            self.server = ControlServer(
                path,
                mode=config.loop.socket_mode,
                allowed_uids=frozenset(config.loop.socket_uids) or None,
            )
            self._closers.append(self.server.close)
        except BaseException:
            self.close()
            raise
        self.socket_path = path
        #: The e-stop latch on disk (see :mod:`gateway.runtime.latch`).
        self.latch = EstopLatch(latch_path(config.loop.state_file, config.name))
        self._closers.append(self.latch.wait_durable)  # (its fsyncs run in the background)
        self._ready = False
        self._state = GatewayState.DISABLED
        #: The state last said is ENABLING while listening for another commander.
        self._listening = False
        #: Answers the socket's requests (:mod:`gateway.runtime.requests`).
        self.requests = RequestHandler(self.gateway, self.server, self.latch, self.status)
        # When each twist accepted since the last cycle arrived (the latency's start).
        self._pending_twists = self.requests.pending_twists
        # The Zenoh bridge and the live view, when configured; started here, before
        # realtime_setup, so that their threads (Zenoh's own too) never run SCHED_FIFO.
        try:
            self.remote = Remote(self.gateway, self.latch, self.status, self._pending_twists,
                                 record_mcap)
        except BaseException:
            self.close()
            raise
        self._closers.append(self.remote.close)
        self._watchdog_s = self.notifier.watchdog_period_s
        self._next_watchdog = 0.0
        self.rt_notes: list[str] = []
        #: Classifies the loop's late starts; made by :meth:`run` in the loop's thread.
        self.miss_probe: MissProbe | None = None
        # The server's selector descriptor, readable when a request or a connection waits:
        # lets the loop wait for requests with microsecond resolution (see _wait).
        fileno = getattr(self.server, "fileno", None)
        self._server_fd: int | None = fileno() if callable(fileno) else None

    # ----------------------------------------------------------------- requests

    def handle(self, client: int, request: Request | ProtocolError, now_s: float) -> None:
        """Answer one socket request (:meth:`.RequestHandler.handle`)."""
        self.requests.handle(client, request, now_s)

    def handle_safely(self, client: int, request: Request | ProtocolError, now_s: float) -> None:
        """:meth:`handle`, but a reply that cannot be built becomes an error reply
        (:meth:`.RequestHandler.handle_safely`)."""
        self.requests.handle_safely(client, request, now_s)

    def status(self) -> GatewayStatus:
        """Everything a ``status`` request returns, now."""
        return build_status(self.gateway, self.scheduler.timer.snapshot(), self.socket_path,
                            self.server.counters, self.rt_notes, time.monotonic())

    # ----------------------------------------------------------------- loop

    def request_stop(self, signum: int = 0, frame: FrameType | None = None) -> None:
        """Ask the loop to stop (signal handler: every signal of :data:`STOP_SIGNALS`)."""
        if signum and not self._stop:
            self.stop_signal = signal.Signals(signum).name
            if signum == signal.SIGABRT:
                # systemd's watchdog sends SIGABRT to a stalled loop: where every thread was
                # is the first thing to know (run by Python between bytecodes, GIL held).
                faulthandler.dump_traceback(all_threads=True)
        self._stop = True

    def run(self, max_cycles: int | None = None) -> int:
        """Run until a signal of :data:`STOP_SIGNALS` (or ``max_cycles``); return the exit
        status."""
        main_thread = threading.current_thread() is threading.main_thread()
        signals = STOP_SIGNALS if main_thread else ()
        old = {s: signal.signal(s, self.request_stop) for s in signals}
        if main_thread and not faulthandler.is_enabled():
            # A crash in C writes every thread's traceback.  SIGABRT is taken back: there
            # faulthandler walks running threads' frames and can crash the process (seen:
            # exit -11, no zero sent); request_stop writes them safely, with the GIL held.
            faulthandler.enable(all_threads=True)
            self._closers.append(faulthandler.disable)
            if signal.SIGABRT in old:
                signal.signal(signal.SIGABRT, self.request_stop)
        try:
            self.rt_notes = realtime_setup(
                self.config.loop.rt_priority or None,
                None if self.config.loop.rt_cpu < 0 else self.config.loop.rt_cpu,
                self.config.loop.lock_memory,
            )
            # Classifies late starts from this thread's scheduler statistics (opened here,
            # in the loop's thread).
            self.miss_probe = MissProbe(self.scheduler)
            self._closers.append(self.miss_probe.close)
            if self.sim is not None:
                # Started after realtime_setup, the simulators' thread inherits SCHED_FIFO when
                # the loop has it: a SCHED_OTHER thread preempted while it holds the GIL would
                # stall the FIFO loop thread for as long as the scheduler keeps it waiting.
                self.sim.start()
            latched = self.latch.read()
            if latched is not None:
                # Never out of an e-stop by a restart: only an explicit enable releases it.
                self.gateway.supervisor.estop(latched)
                self._state, self.latch.counted = GatewayState.ESTOP, 1  # (the file holds it)
                log.warning("starting e-stopped: %s; send enable to release it (%s)", latched,
                            self.latch.path)
            elif self.config.loop.enable_on_start:
                self.gateway.supervisor.enable(time.monotonic())
            # Ready once the bus and the socket are up, whatever the motors do: with their
            # power off at boot, the drives enable when they answer (STATUS= says so), and
            # `systemctl start` does not wait for them.
            self._mark_ready()
            cycles = 0
            while not self._stop and (max_cycles is None or cycles < max_cycles):
                self.step(time.monotonic())
                cycles += 1
                self._wait()
        finally:
            if self.stop_signal:
                log.info("%s: stopping (zero and disarm for every motor)", self.stop_signal)
            self.shutdown()
            for s, handler in old.items():
                signal.signal(s, handler)
        return 0

    def step(self, now_s: float) -> None:
        """One cycle plus its bookkeeping (also used by tests on simulated time)."""
        gw = self.gateway
        start = time.perf_counter()
        gw.cycle(now_s)
        sent = gw.burst_sent_s
        for arrived in self._pending_twists:
            self.scheduler.timer.record_latency(sent - arrived)
        self._pending_twists.clear()
        server = self.server
        for news in gw.outbox:
            topic = event_topic(news)
            if server.has_subscribers(topic):
                server.publish(topic, event_line(news))
        self.remote.post(gw.outbox, now_s)
        gw.outbox.clear()
        sup = gw.supervisor
        self.latch.track(sup.counts.estops, sup.reason if gw.state is GatewayState.ESTOP else None)
        if gw.state is not self._state:
            if self._state is GatewayState.ESTOP:
                self.latch.clear()  # only an explicit enable leaves ESTOP
            before, self._state = self._state, gw.state
            self._say_state()
            if self.announce is not None:
                line = announcement(self.config, before, gw.state, self._announced_running,
                                    self.sim is not None, self.socket_path,
                                    gw.supervisor.yielded)
                self._announced_running |= gw.state is GatewayState.RUNNING
                if line:
                    try:
                        self.announce(line)
                    except OSError as err:  # best effort, as logging is: stderr may be gone
                        log.debug("announcement not written: %s", err)
        elif self._listening and not sup.enable_pending:  # (listened: the enable is taken)
            self._say_state()
        if gw.state is GatewayState.RUNNING and not self._ready:
            self._mark_ready()
        if self._watchdog_s is not None and now_s >= self._next_watchdog and self._healthy():
            self.notifier.watchdog()
            self._next_watchdog = now_s + self._watchdog_s
        self.scheduler.timer.record_cost(time.perf_counter() - start)

    def _say_state(self) -> None:
        """The state, with what the daemon waits for, to systemd's ``STATUS=`` and the log."""
        gw = self.gateway
        self._listening = gw.state is GatewayState.ENABLING and gw.supervisor.enable_pending
        text = status_text(gw)
        self.notifier.status(text)
        log.info("state %s", text)

    def _healthy(self) -> bool:
        """Whether to feed the systemd watchdog: the loop runs (we are in it) and the bus
        takes frames; a wedged bus ends in a restart instead of a zombie daemon."""
        return self.gateway.edge.bus_healthy

    def _mark_ready(self) -> None:
        self._ready = True
        self.notifier.ready(f"{status_text(self.gateway)}; socket {self.socket_path}")

    def _wait(self) -> None:
        """Serve the socket until the next deadline: poll while whole milliseconds remain
        before the spin phase, wait out the rest, spin, then serve once more.

        The socket poll (epoll) waits in whole milliseconds, rounded up: asked for 0.7 ms it
        sleeps 1 ms.  So it is asked only for the whole milliseconds that end before the spin
        phase (``k - 0.5`` ms, which rounds up to ``k``); otherwise every cycle could start up
        to a millisecond late.  The sub-millisecond rest (all of the wait at 1 kHz) is a
        ``select`` on the server's descriptor, which wakes for a request at once, where the
        server offers one (``fileno()``), else a plain sleep.  The last pass, at the deadline,
        hands this cycle every request that arrived meanwhile.

        Every poll until the next cycle's draws on one budget, begun here where the server
        offers one (:meth:`ControlServer.begin_cycle`): however fast clients send, this wait
        serves at most one cycle's share of requests, and the rest waits, unread, for later
        cycles.
        """
        sched = self.scheduler
        spin = sched.spin_s
        begin_cycle = getattr(self.server, "begin_cycle", None)
        if begin_cycle is not None:
            begin_cycle(sched.period_s)
        probe = self.miss_probe
        if probe is not None:
            probe.before_wait()
        while True:
            whole_ms = math.floor((sched.remaining_s() - spin) * 1000.0)
            if whole_ms < 1:
                break
            self._serve(self.server.poll((whole_ms - 0.5) * 1e-3))
        woke = sched.wait_next(self._wait_fine)
        if probe is not None:
            probe.after_wait(woke)
            text = probe.report(woke)
            if text is not None:
                # With simulated controllers in this process (--sim), late starts are the
                # simulators' GIL share on a desktop, not news: INFO, not a WARNING every 10 s.
                log.log(logging.INFO if self.sim is not None else logging.WARNING,
                        "control loop: %s", text)
        self._serve(self.server.poll(0.0))

    def _wait_fine(self, timeout_s: float) -> None:
        """Wait up to ``timeout_s`` (under a millisecond), serving requests as they come."""
        fd = self._server_fd
        if fd is not None:
            try:
                ready, _, _ = select.select([fd], [], [], timeout_s)
            except (OSError, ValueError):  # closed, or beyond FD_SETSIZE: sleep instead
                self._server_fd = None
            else:
                if ready:
                    self._serve(self.server.poll(0.0))
                return
        time.sleep(timeout_s)

    def _serve(self, events: list[tuple[int, Request | ProtocolError]]) -> None:
        if events:
            now = time.monotonic()
            for client, request in events:
                self.handle_safely(client, request, now)
        if self.remote.active:
            self.remote.serve(time.monotonic())

    def shutdown(self, now_s: float | None = None) -> None:
        """Zero and disarm every motor, then close everything (safe to call twice).

        Not a motor that another program commands while this gateway has not armed them
        (:meth:`.Commanders.quiet`): then nothing is sent, and :attr:`left_to` says why.

        :param now_s: the time of the loop's clock (simulated time in tests); now when omitted.
        """
        if not self._closers:
            return
        gw = self.gateway
        self.notifier.stopping("sending zero and disarm")
        try:
            gw.supervisor.shutdown()
            stopped = stop_motors(gw, time.monotonic() if now_s is None else now_s)
            self.stop_sent, self.left_to = stopped.sent, stopped.left_to
        except GatewayError as err:  # (DriveSet.disable sends every stop it can build)
            log.error("shutdown: %s", err)
        finally:
            self.close()

    def close(self) -> None:
        """Release every resource (reverse order of creation)."""
        while self._closers:
            closer = self._closers.pop()
            try:
                closer()
            except Exception as err:  # closing must go on whatever one part does
                log.warning("closing %r failed: %s", closer, err)
