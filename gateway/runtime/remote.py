"""What the daemon shows and takes beyond its socket: the Zenoh bridge and the live view.

:class:`Remote` owns them for the daemon: it drains the bridge's requests between cycles into a
:class:`~gateway.runtime.requests.RequestHandler` of their own (the socket's logic; twists go
through exactly the socket's path: newest valid wins, the limits, ``cmd_timeout_s``), acts on
a lost commander (:mod:`gateway.runtime.bridge.deadman`), and posts the loop's news -- a
:class:`~gateway.runtime.mailbox.Snapshot` at the odometry rate, the state, every error -- to
each worker's mailbox, and the whole status once a second and at a change of state to the
live view's and, with ROS 2 diagnostics, to the bridge's (:mod:`gateway.runtime.diagnostics`).
The modules behind it (and Zenoh, the Foxglove SDK) are imported only when the configuration
asks for them.
"""

from __future__ import annotations

import logging
import math
import time
from typing import TYPE_CHECKING, Any

from gateway.core.bridge_settings import DeadmanAction, FoxgloveSettings
from gateway.core.events import OdometryEvent, StatusEvent
from gateway.core.status import LastError
from gateway.core.supervision import Source
from gateway.core.types import ErrorCode
from gateway.runtime.bridge.inbox import CommanderEvent, Inbound
from gateway.runtime.mailbox import Snapshot, SteerSample, WheelSample
from gateway.runtime.requests import RequestHandler

if TYPE_CHECKING:
    from collections.abc import Callable, Sequence

    from gateway.core.events import OutboxEvent
    from gateway.core.status import GatewayStatus
    from gateway.core.types import GatewayState
    from gateway.runtime.bridge.bridge import Bridge
    from gateway.runtime.latch import EstopLatch
    from gateway.runtime.loop import Gateway
    from gateway.runtime.mailbox import Mailbox

log = logging.getLogger(__name__)

__all__ = ["POLL_MAX", "SERVE_SHARE", "Remote", "snapshot_of"]

#: Inbox items (queries, token events) the loop takes per cycle, at most.
POLL_MAX = 64
#: The share of the cycle's period the loop gives them (a status query builds the whole
#: status): what is left waits for the next cycle.
SERVE_SHARE = 0.2
#: The shortest time between two diagnostics reports when the state keeps changing (s).
REPORT_MIN_S = 0.1
#: How often the diagnostics go out (s): ``diagnostic_updater``'s default period.
DIAGNOSTICS_PERIOD_S = 1.0


class Remote:
    """The daemon's bridge and live view (either may be absent).

    :param gateway: the gateway whose cycle the daemon runs.
    :param latch: the e-stop latch (a bridge ``estop`` sets it, as the socket's).
    :param status: everything a ``status`` request returns, now.
    :param pending_twists: the daemon's list of accepted twists' arrival times (latency).
    :param record_mcap: record the live view's channels to this file ('' for none).
    :raises GatewayError: when a configured bridge or view cannot start (naming why).
    """

    def __init__(self, gateway: Gateway, latch: EstopLatch,
                 status: Callable[[], GatewayStatus], pending_twists: list[float],
                 record_mcap: str = "") -> None:
        config = gateway.config
        self.gateway = gateway
        self.latch = latch
        self._status = status
        #: When the next diagnostics report is due and the state the last one showed, and
        #: the mailboxes that take one (the live view's; the bridge's with ROS 2 diagnostics).
        self._report_due_s = -math.inf
        self._report_state: GatewayState | None = None
        self._report_boxes: list[Mailbox[Any]] = []
        self.bridge: Bridge | None = None
        self.view: Any = None
        self._mailboxes: list[Mailbox[Any]] = []
        view = config.foxglove is not None or bool(record_mcap)
        try:
            if config.bridge is not None or view:
                # Each motor's hardware id, for the diagnostics of both workers.
                from gateway.runtime.diagnostics import hardware_ids  # noqa: PLC0415

                hardware = hardware_ids(config)
            if config.bridge is not None:
                # Imported only with a bridge: block (and Zenoh only by the bridge).
                from gateway.runtime.bridge.bridge import Bridge  # noqa: PLC0415
                from gateway.runtime.bridge.deadman import Deadman  # noqa: PLC0415

                self.bridge = Bridge(config.bridge, hardware)
                if config.bridge.ros2 and config.bridge.ros2.diagnostics:
                    self._report_boxes.append(self.bridge.mailbox)
                self._mailboxes.append(self.bridge.mailbox)
                self.requests = RequestHandler(gateway, self.bridge, latch, status,
                                               Source.BRIDGE, "the Zenoh bridge")
                self.requests.pending_twists = pending_twists
                self.deadman = Deadman()
            if view:
                from gateway.runtime.liveview import LiveView  # noqa: PLC0415 - optional

                wheel_names = tuple(m.wheel for m in config.motors if m is not None)
                steer_names = tuple(a.wheel for a in config.steering)
                self.view = LiveView(config.foxglove or FoxgloveSettings(), config.name,
                                     wheel_names, steer_names, record_mcap=record_mcap,
                                     serve=config.foxglove is not None,
                                     hardware=hardware)
                self.view.start()
                self._mailboxes.append(self.view.mailbox)
                self._report_boxes.append(self.view.mailbox)
        except BaseException:
            self.close()
            raise

    @property
    def active(self) -> bool:
        """Whether there is anything to serve or post to."""
        return bool(self._mailboxes)

    # ----------------------------------------------------------------- requests

    def serve(self, now_s: float) -> None:
        """Handle what came in over the bridge since the last call (loop thread): the newest
        published twist of each source first (sent before anything still waiting in the inbox
        was taken), then queries and token events in order, at most :data:`POLL_MAX` and for at
        most :data:`SERVE_SHARE` of the cycle's period (the rest waits for the next cycle)."""
        bridge = self.bridge
        if bridge is None:
            return
        self._take_twists(bridge, now_s)
        item = bridge.take()
        if item is None:  # (the common case: no clock read)
            return
        end = time.perf_counter() + SERVE_SHARE * self.gateway.period_s
        for left in range(POLL_MAX - 1, -1, -1):
            if isinstance(item, CommanderEvent):
                if not item.alive:
                    # What the commander published before its token went is in the rings by
                    # now (Zenoh delivers its samples in order): taken before the loss.
                    self._take_twists(bridge, now_s)
                self._commander(item.commander, item.alive, now_s)
            else:
                self._request(item, now_s)
            # (Nothing taken past the limit: a taken item must be handled.)
            if not left or time.perf_counter() > end or (item := bridge.take()) is None:
                return

    def _take_twists(self, bridge: Bridge, now_s: float) -> None:
        for twist in bridge.take_twists():
            self._request(twist, now_s)

    def _request(self, item: Inbound, now_s: float) -> None:
        self.requests.handle_safely(item.client, item.request, now_s)  # never out of the loop
        accepted = self.requests.last_accepted
        if item.commander is not None and accepted is not None:
            self.deadman.accepted(item.commander, accepted)

    def _commander(self, name: str, alive: bool, now_s: float) -> None:
        if alive:
            log.info("bridge: commander %s is alive", name)
            return
        gw = self.gateway
        sup = gw.supervisor
        if not self.deadman.lost(name, sup.target):
            log.info("bridge: commander %s is gone (the robot was not following it)", name)
            return
        assert self.bridge is not None
        action = self.bridge.settings.deadman
        if action is DeadmanAction.ESTOP:
            sup.estop(f"commander {name} disappeared (deadman: estop)")
            gw.stop_now(now_s)  # (before the latch's disk write, and any enable)
            self.latch.set(sup.reason)
            gw.report_error(ErrorCode.ESTOP, sup.reason)
        else:
            sup.stop(now_s)
            gw.report_error(ErrorCode.COMMAND_TIMEOUT, f"commander {name} disappeared (its "
                            f"liveliness token is gone): stopping")
        log.warning("bridge: commander %s disappeared while the robot followed it: %s", name,
                    action.value)

    # ----------------------------------------------------------------- news

    def post(self, outbox: Sequence[OutboxEvent], now_s: float) -> None:
        """Hand this cycle's news to the workers (loop thread; never waits for them).

        :param now_s: the cycle's time (monotonic), for the diagnostics' period.
        """
        if self._report_boxes and (now_s >= self._report_due_s
                              or self.gateway.state is not self._report_state):
            self._report(now_s)
        if not self._mailboxes or not outbox:
            return
        snapshot = None
        status = None
        errors = []
        for news in outbox:
            if isinstance(news, OdometryEvent):
                snapshot = snapshot_of(self.gateway, news)
            elif isinstance(news, StatusEvent):
                status = news
            elif isinstance(news, LastError):
                errors.append(news)
        for box in self._mailboxes:
            box.post(snapshot, status, tuple(errors))

    def _report(self, now_s: float) -> None:
        """The whole status for the diagnostics: due once a :data:`DIAGNOSTICS_PERIOD_S`, or
        at a change of state at most every :data:`REPORT_MIN_S` after the last report."""
        if now_s < self._report_due_s - DIAGNOSTICS_PERIOD_S + REPORT_MIN_S:
            return  # (a change of state right after a report: the next cycle looks again)
        self._report_state = self.gateway.state
        self._report_due_s = now_s + DIAGNOSTICS_PERIOD_S
        report = self._status()
        for box in self._report_boxes:
            box.post(report=report)

    def close(self) -> None:
        """Stop the workers and close the session (the gateway's token disappears)."""
        if self.bridge is not None:
            self.bridge.close()
        if self.view is not None:
            self.view.close()


def snapshot_of(gw: Gateway, odometry: OdometryEvent) -> Snapshot:
    """What the loop shows the world now (see :class:`~gateway.runtime.mailbox.Snapshot`)."""
    config = gw.config
    feedback = gw.drives.motor_feedback()
    commanded = gw.prev.wheel_rad_s
    wheels = []
    k = 0
    for i, motor in enumerate(config.motors):
        if motor is None:
            continue
        fb = feedback[k]
        k += 1
        wheels.append(WheelSample(
            motor.wheel, commanded[i], None if fb is None else fb.velocity_rad_s,
            None if fb is None else fb.position_rad,
        ))
    steering = []
    if config.steering:
        angles = gw.drives.steer_setpoints(gw.prev.steer_rad)
        for j, actuator in enumerate(config.steering):
            fb = feedback[k + j]
            steering.append(SteerSample(actuator.wheel, angles[j],
                                        None if fb is None else fb.position_rad))
    sup = gw.supervisor
    return Snapshot(time.time_ns(), odometry.state, sup.state, sup.reason, tuple(wheels),
                    tuple(steering))
