"""A second commander on the bus: frames only this gateway should send, heard from another.

Two programs that command the same motors fight over them, each overwriting the other's set
points: the service and a ``wheelgate run`` started by hand on another socket, ``jog
--standalone`` beside a running daemon, a script with ``cansend``.  A node never receives
its own frames (SocketCAN delivers a socket's frames to the *other* sockets only, unless
``CAN_RAW_RECV_OWN_MSGS`` is set: Linux ``Documentation/networking/can.rst``, "RAW socket
option CAN_RAW_RECV_OWN_MSGS"; python-can's virtual bus likewise), so a frame that carries
one of this gateway's own identifiers came from someone else:

* a command of one of its motors (the identifiers of its drivers' cyclic command frames,
  :meth:`~gateway.drive.driveset.DriveSet.preview`; remote frames, a read-only request, are
  not commands), or
* a wheelgate's own report (``WG_Status``, ``WG_Odom_Pose``, ``WG_Odom_Velocity``,
  ``WG_Error`` at this configuration's identifiers): another gateway runs on this bus.

A command while the motors are enabled is a fault (``bus_error``) that names the frame and what
to do.  An enable is taken only once the gateway has listened for :data:`LISTEN_S` since its
first cycle, and is **withheld** while another sender has commanded these motors within that
time (:meth:`Commanders.may_enable`): a FAULT (``bus_error``) that releases the motors, so the
program that commanded first keeps them.  Until it arms them, the gateway sends the motors
nothing while it listens or hears the other (:meth:`Commanders.quiet`: no housekeeping, no stop
when it shuts down), so a second ``wheelgate run`` started beside a running one stops neither.
The automatic recovery retries as after any bus fault, and is withheld again while the other
keeps sending.  A command while the motors are not enabled, or a report, is a warning (at most
one line per 5 s): nothing of ours is overwritten yet, and a second gateway that drives other
motors is a configuration to fix (its own ``gateway.can_ids``), not a fight; should it drive
ours, its commands say so.  The identifiers are added to the kernel receive filters
(:func:`gateway.drive.ownership.gateway_filters`), so the other's frames reach the process.
``wheelgate spin`` makes the same judgement before it arms a motor
(:func:`gateway.apps.spin.plan.someone_else`).
"""

from __future__ import annotations

import functools
import logging
from typing import TYPE_CHECKING

from gateway.bus.health import LogThrottle
from gateway.core.types import ErrorCode, Frame, Twist
from gateway.drive.labels import OWN_MESSAGES, FrameLabeler

if TYPE_CHECKING:
    from collections.abc import Callable, Mapping

    from gateway.core.control import Supervisor
    from gateway.core.settings import GatewayConfig
    from gateway.drive.driveset import DriveSet

log = logging.getLogger(__name__)

Key = tuple[int, bool]

#: The shortest time between two warnings (s).
WARN_EVERY_S = 5.0
#: How long the gateway listens before it takes its first enable, and how recent another
#: sender's command must be to withhold one (s): the 250 ms that SAE J1939-81's address claim
#: waits for a contending claim before a node uses its address.  Another wheelgate commands
#: every cycle (50 Hz at the slowest), so it is heard a dozen times in that window.
LISTEN_S = 0.25
#: How :func:`own_frames` names a wheelgate's report (the end of its description).
REPORT = "of another wheelgate"


def own_frames(config: GatewayConfig, drives: DriveSet) -> dict[Key, str]:
    """The identifiers only this gateway sends, each with what it is (for messages).

    The motors' commands come from a preview at zero speed and neutral angles: the frames a
    cycle sends whatever the set points (a protocol's other frames -- enabling, configuring
    -- go out once and are not judged).
    """
    labeler = FrameLabeler(config)
    rest = config.model.ik(Twist())
    out: dict[Key, str] = {}
    for frame in drives.preview(rest.wheel_rad_s, rest.steer_rad):
        if not frame.is_remote_frame:
            key = (frame.arbitration_id, frame.is_extended_id)
            out.setdefault(key, f"a command: {labeler.label_id(*key).text}")
    for key, name in _reports(config).items():
        out.setdefault(key, f"{name} {REPORT}")
    return out


def _reports(config: GatewayConfig) -> dict[Key, str]:
    """The gateway's own reports by identifier (its twist input is meant to come from another
    node: not one of them)."""
    ids = config.loop.can_ids
    return {(getattr(ids, key), ids.extended): name for key, name in OWN_MESSAGES.items()
            if key != "twist"}


class Commanders:
    """What the cycle does with a frame only this gateway should send.

    :param config: the configuration (the bus's name in messages).
    :param own: :func:`own_frames`.
    :param supervisor: the supervisor, for the fault.
    :param report: the gateway's error report (``report_error(code, message, wheel=...)``).
    """

    def __init__(self, config: GatewayConfig, own: Mapping[Key, str], supervisor: Supervisor,
                 report: Callable[..., None]) -> None:
        self.bus = f"{config.bus.interface}:{config.bus.channel}"
        self.own = dict(own)
        self.supervisor = supervisor
        self.report = report
        self._reports = frozenset(_reports(config))
        self._warn = LogThrottle(WARN_EVERY_S)
        #: Frames heard from another sender, since start.
        self.heard = 0
        #: When listening began: the first time the watch was asked (:meth:`quiet`, every
        #: cycle until the motors are armed, so the gateway's first cycle).
        self.since_s: float | None = None
        #: The last command of ours heard from another sender: when, the frame, its key.
        self._last_command: tuple[float, Frame, Key] | None = None

    def _listening(self, now_s: float) -> bool:
        """Whether the watch is still in its first :data:`LISTEN_S` (it starts now when it
        had not)."""
        since = self.since_s
        if since is None:
            since = self.since_s = now_s
        return now_s - since < LISTEN_S

    def may_enable(self, now_s: float) -> bool:
        """Whether the loop may take the enable pending now.

        Not while listening (the first :data:`LISTEN_S` after the first cycle: the enable
        waits, nothing is armed).  After that, an enable comes too soon after another
        sender's command of these motors (within :data:`LISTEN_S`): it is withheld, a fault
        that releases the motors (:meth:`~gateway.core.control.Supervisor.yield_motors`),
        logged and reported.
        """
        if self._listening(now_s):
            self.supervisor.hold_enable(now_s)
            return False
        holder = self.holder(now_s)
        if holder is None:
            return True
        message = self.supervisor.yield_motors(
            f"{holder}: another program commands these motors (another wheelgate run, jog "
            f"--standalone, a script), and it keeps them; stop it, then enable")
        log.error("fault: %s", message)
        self.report(ErrorCode.BUS_ERROR, message)
        return False

    def holder(self, now_s: float) -> str | None:
        """What was heard of another sender commanding these motors now (a command of ours
        within :data:`LISTEN_S`), else ``None``."""
        last = self._last_command
        if last is None or now_s - last[0] > LISTEN_S:
            return None
        t, frame, key = last
        return f"{self._heard(frame, key)} {max(0.0, now_s - t):.3f} s ago"

    def quiet(self, now_s: float) -> bool:
        """Whether a gateway that has not armed its motors sends them nothing, not even its
        housekeeping (a CANopen SYNC, its heartbeat, SDO requests), nor a stop when it shuts
        down: while it listens at start, and while another sender commands them
        (:meth:`holder`).  Two SYNC producers on one CANopen network are an error (CiA 301),
        and our heartbeat would keep the other's drives from stopping when the other dies."""
        return self._listening(now_s) or self.holder(now_s) is not None

    def route(self, takers: Mapping[Key, Callable[[Frame], bool]]
              ) -> dict[Key, Callable[[Frame], bool]]:
        """``takers`` with each of :attr:`own`'s identifiers sent to :meth:`other` first (a
        driver that claims its node's whole range, ODrive's, keeps its remote frames)."""
        out = dict(takers)
        for key in self.own:
            out[key] = functools.partial(self._take, key, takers.get(key))
        return out

    def _take(self, key: Key, taker: Callable[[Frame], bool] | None, frame: Frame) -> bool:
        if frame.is_remote_frame:
            return taker(frame) if taker is not None else False
        self.other(frame, key)
        return True

    def other(self, frame: Frame, key: Key) -> None:
        """``frame`` came from another sender: a command is a fault while the motors are
        enabled; a report, or a command while they are not, a warning."""
        self.heard += 1
        report = key in self._reports
        if not report:
            self._last_command = (frame.timestamp_s, frame, key)
            sup = self.supervisor
            if not sup.enable_pending:  # (one not taken yet armed nothing: may_enable judges)
                message = self._message(frame, key, report)
                if sup.bus_fault(message) is not None:
                    log.error("fault: %s", message)
                    self.report(ErrorCode.BUS_ERROR, message)
                    return
        n = self._warn.note(frame.timestamp_s)
        if n is not None:
            log.warning("%s (%d such frames since the last line)",
                        self._message(frame, key, report), n)

    def _heard(self, frame: Frame, key: Key) -> str:
        return f"another sender on {self.bus}: heard {frame.to_cansend()} ({self.own[key]})"

    def _message(self, frame: Frame, key: Key, report: bool) -> str:
        """What hearing ``frame`` means: another wheelgate (a report), or a fight."""
        if report:  # a second gateway; its commands, if of our motors, tell
            return (f"{self._heard(frame, key)}: another wheelgate runs on this bus; if it "
                    f"drives these motors, stop it; if it drives others, give each its own "
                    f"gateway.can_ids")
        return (f"{self._heard(frame, key)}, which only this gateway sends: two programs "
                f"command these motors (another wheelgate run, jog --standalone, a script); "
                f"stop the other one")
