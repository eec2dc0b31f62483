"""The gateway's status (:class:`gateway.core.status.GatewayStatus`), built from the running
parts: the cycle's :class:`~gateway.runtime.loop.Gateway`, the loop's timing and the control
server's counters.

:func:`build_status` is a pure function of what it is given (the daemon passes the clock's
time); the daemon answers a ``status`` request with its JSON form
(:func:`gateway.wire.socket.status.status_to_json`).
"""

from __future__ import annotations

import dataclasses
import math
import time
from types import MappingProxyType
from typing import TYPE_CHECKING

from gateway.core.settings import FeedbackRecovery
from gateway.core.status import (
    BusHealth,
    BusReport,
    CommandReport,
    ConfigReport,
    ControllerStop,
    Counters,
    Direction,
    FrameCount,
    GatewayStatus,
    MotorReport,
    SocketReport,
    TimingReport,
    TrackingReport,
)
from gateway.core.types import DriveState, GatewayState
from gateway.runtime.commanders import LISTEN_S

if TYPE_CHECKING:
    from collections.abc import Mapping, Sequence

    from gateway.bus.edge import EdgeCounts
    from gateway.core.counts import SupervisorCounts
    from gateway.core.settings import GatewayConfig
    from gateway.core.status import ServerCounters
    from gateway.core.types import MotorStatus
    from gateway.runtime.counts import LoopCounts
    from gateway.runtime.loop import Gateway

__all__ = ["build_status", "event_counts", "status_text", "timing_report"]


def _finite(value: float | None) -> float | None:
    return None if value is None or not math.isfinite(value) else value


def timing_report(stats: TimingReport, burst_gap_max_s: float) -> TimingReport:
    """The loop's timing statistics and the longest gap between two bursts, as reported."""
    return dataclasses.replace(stats, burst_gap_max_ms=burst_gap_max_s * 1000.0)


def _motor(st: MotorStatus, stops: Mapping[str, ControllerStop]) -> MotorReport:
    fb = st.feedback
    return MotorReport(
        st.name, int(st.node_id), st.state, st.faults, st.detail, _finite(st.feedback_age_s),
        None if fb is None else _finite(fb.position_rad),
        None if fb is None else _finite(fb.velocity_rad_s),
        stops.get(st.name),
    )


def _by_driver(counts: Sequence[tuple[str, Mapping[str, int]]]) -> Mapping[str, Mapping[str, int]]:
    return MappingProxyType({name: MappingProxyType(dict(n)) for name, n in counts if n})


def event_counts(loop: LoopCounts, edge: EdgeCounts, sup: SupervisorCounts
                 ) -> Mapping[str, int]:
    """The event counters by name, in the status's order (public: the socket protocol's
    ``counters``; every field of the three records, under its own name)."""
    return MappingProxyType({
        "cycles": loop.cycles,
        "frames_sent": edge.frames_sent,
        "frames_received": edge.frames_received,
        "send_failures": edge.send_failures,
        "bus_reopens": edge.bus_reopens,
        "can_twists": loop.can_twists,
        "can_duplicates": loop.can_duplicates,
        "can_lost": loop.can_lost,
        "bad_can_twists": loop.bad_can_twists,
        "errors_reported": loop.errors_reported,
        "odometry_errors": loop.odometry_errors,
        "receive_failures": edge.receive_failures,
        "frames_unsent": edge.frames_unsent,
        "partial_bursts": edge.partial_bursts,
        "send_waits": edge.send_waits,
        "fd_frames_ignored": edge.fd_frames_ignored,
        "infeasible": sup.infeasible,
        "projected": sup.projected,
        "rejected": sup.rejected,
        "faults": sup.faults,
        "cmd_timeouts": sup.cmd_timeouts,
        "estops": sup.estops,
        "errors_not_sent": loop.errors_not_sent,
        "position_jumps": loop.position_jumps,
    })


def build_status(
    gw: Gateway,
    timing: TimingReport,
    socket_path: str,
    server: ServerCounters,
    realtime: Sequence[str],
    now_s: float,
) -> GatewayStatus:
    """Everything a status request returns: state, motors, odometry, counters, timing.

    :param gw: the gateway whose cycle runs.
    :param timing: the loop's timing statistics (:meth:`LoopTimer.snapshot
        <gateway.runtime.timing.LoopTimer.snapshot>`).
    :param socket_path: the control socket's path.
    :param server: the control server's counters.
    :param realtime: what the real-time set-up did.
    :param now_s: the monotonic clock, s.
    """
    sup = gw.supervisor
    stops: dict[str, ControllerStop] = {}
    for drv, _ in gw.drives.groups:
        for i, m in enumerate(drv.motors):
            prot = drv.protection(i)
            stops[m.wheel] = ControllerStop(prot.guard, prot.timeout_s, drv.protection_state(i))
    limit = gw.limit_report
    errors = gw.edge.bus_errors
    cfg = gw.config
    return GatewayStatus(
        robot=cfg.name,
        state=sup.state,
        reason=sup.reason,
        command=CommandReport(
            target=sup.target,
            applied=gw.prev.twist,
            cmd_timeout_active=sup.cmd_timeout_active,
            speed_scale=1.0 if limit is None else limit.speed_scale,
            accel_scale=1.0 if limit is None else limit.accel_scale,
        ),
        motors=tuple(_motor(st, stops) for st in gw.drives.status(now_s)),
        tracking=TrackingReport(sup.tracking.limits, sup.tracking.worst_ratio,
                                sup.steer_tracking.worst_ratio),
        odometry=gw.odometry.state,
        counters=Counters(
            events=event_counts(gw.counts, gw.edge.counts, sup.counts),
            rejected_frames=_by_driver(
                [(type(drv).__name__, drv.rejected) for drv, _ in gw.drives.groups]),
            commands_not_followed=_by_driver(
                [(type(drv).__name__, drv.command_counts) for drv, _ in gw.drives.groups]),
        ),
        socket=SocketReport(socket_path, server),
        timing=timing_report(timing, gw.burst_gap_max_s),
        last_error=gw.last_error,
        realtime=tuple(realtime),
        bus=BusReport(
            interface=cfg.bus.interface,
            channel=cfg.bus.channel,
            bitrate=cfg.bus.bitrate,
            health=BusHealth(gw.edge.bus_healthy, errors.state,
                             MappingProxyType(dict(errors.counts)), errors.last),
            bits=gw.edge.bits,
            time_s=now_s,
            frames=tuple(
                # int(): a driver's ID may be an IntEnum member (CiA 402's NMT, SYNC)
                FrameCount(int(can_id), ext, Direction.TX if sent else Direction.RX, n)
                for (can_id, ext, sent), n in sorted(gw.edge.id_counts.items())
            ),
        ),
        config=ConfigReport(cfg.path or cfg.source, cfg.fingerprint),
    )


def status_text(gw: Gateway) -> str:
    """The state for systemd's ``STATUS=`` and the log, with what the daemon waits for."""
    sup = gw.supervisor
    text = gw.state.name + (f": {sup.reason}" if sup.reason else "")
    if gw.state is GatewayState.ENABLING:
        if sup.enable_pending:  # (held while the gateway listens: commanders.may_enable)
            return text + (f": listening {LISTEN_S:g} s for another program commanding these "
                           f"motors before enabling them")
        return text + ": waiting for the motors to enable"
    if (gw.state is GatewayState.FAULT
            and gw.config.loop.feedback_recovery is FeedbackRecovery.AUTO):
        offline = [s.name for s in gw.drives.status(time.monotonic())
                   if s.state is DriveState.OFFLINE]
        if offline:
            text += (f" (waiting for motors: {', '.join(offline)} silent; the drives are "
                     f"enabled again once every motor answers)")
    return text


def motors_text(config: GatewayConfig) -> str:
    """``"4 motors"``, ``"4 motors and 4 steering actuators"``: what the daemon enables."""
    drives = sum(m is not None for m in config.motors)
    steer = len(config.steering)
    return (f"{drives} motor{'s' * (drives != 1)}"
            + (f" and {steer} steering actuator{'s' * (steer != 1)}" if steer else ""))


def announcement(config: GatewayConfig, before: GatewayState, now: GatewayState,
                 announced_running: bool, simulated: bool, socket_path: str,
                 yielded: bool = False) -> str:
    """The line for the person who started the daemon on a state change ('' for none): the
    first time the motors run, and a start that failed (the fault's own log line says why;
    this one adds what to do on a virtual bus with no simulator).

    :param yielded: the enable was withheld: another program commands the motors.
    """
    where = f"{config.bus.interface} {config.bus.channel}"
    if now is GatewayState.RUNNING and not announced_running:
        return (f"wheelgate: running on {where}: {motors_text(config)} enabled; control "
                f"socket {socket_path}")
    if now is GatewayState.FAULT and yielded:
        return ("wheelgate: not enabled: another program commands these motors, and nothing "
                "is sent to them while it does (the fault logged above says what was heard)")
    if now is GatewayState.FAULT and before is GatewayState.ENABLING:
        line = "wheelgate: the motors did not enable (the fault logged above says why)"
        if config.bus.interface == "virtual" and not simulated:
            line += (f". This is python-can's virtual bus {config.bus.channel!r}, where only "
                     f"simulated controllers answer: run `wheelgate run --sim`, or give the "
                     f"robot's bus (bus: {{interface: socketcan, channel: can0}} in the "
                     f"configuration, or --interface/--channel)")
        return line
    return ""
