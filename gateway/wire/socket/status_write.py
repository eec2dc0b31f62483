"""Writing the gateway's status as JSON: :func:`status_to_json` (the ``status`` reply's
payload) and :func:`odometry_to_json` (the odometry as the status, the ``reset_odometry`` reply
and the odometry events write it).  The format, key by key, is :mod:`gateway.wire.socket.status`;
:mod:`gateway.wire.socket.status_read` reads it back.  Pure: no I/O, no clock.
"""

from __future__ import annotations

import dataclasses
import math
from typing import TYPE_CHECKING

from gateway.core.status import ServerCounters, fault_names, state_name

if TYPE_CHECKING:
    from gateway.core.kinematics.odometry import OdometryState
    from gateway.core.status import BusReport, GatewayStatus, MotorReport, TimingReport
    from gateway.core.types import Twist

__all__ = ["odometry_to_json", "status_to_json"]

_SERVER_COUNTERS = tuple(f.name for f in dataclasses.fields(ServerCounters))


def _f(value: float | None) -> float | None:
    """A number as the protocol writes it: ``None`` for a float that is not finite."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def _twist(t: Twist) -> dict[str, object]:
    return {"vx_m_s": _f(t.vx_m_s), "vy_m_s": _f(t.vy_m_s), "wz_rad_s": _f(t.wz_rad_s)}


def odometry_to_json(state: OdometryState) -> dict[str, object]:
    """The odometry as the status, the ``reset_odometry`` reply and the events write it."""
    p, v = state.pose, state.twist
    return {"x": _f(p.x_m), "y": _f(p.y_m), "theta": _f(p.theta_rad), "vx": _f(v.vx_m_s),
            "vy": _f(v.vy_m_s), "wz": _f(v.wz_rad_s), "slip": _f(state.slip_m_s),
            "distance": _f(state.distance_m), "t": _f(state.timestamp_s)}


def _motor(m: MotorReport) -> dict[str, object]:
    stop = m.controller_stop
    return {
        "name": m.name, "node_id": m.node_id, "state": state_name(m.state),
        "faults": list(fault_names(m.faults)), "detail": m.detail,
        "feedback_age_s": _f(m.feedback_age_s), "position_rad": _f(m.position_rad),
        "velocity_rad_s": _f(m.velocity_rad_s),
        "controller_stop": None if stop is None else {
            "guard": stop.guard.value, "timeout_s": _f(stop.timeout_s),
            "state": stop.state.value},
    }


def _timing(t: TimingReport) -> dict[str, object]:
    out: dict[str, object] = {
        f.name: _f(getattr(t, f.name)) for f in dataclasses.fields(t)
        if f.name != "burst_gap_max_ms"
    }
    if t.burst_gap_max_ms is not None:
        out["burst_gap_max_ms"] = _f(t.burst_gap_max_ms)
    return out


def _bus(b: BusReport) -> dict[str, object]:
    out: dict[str, object] = {"interface": b.interface, "channel": b.channel,
                              "bitrate": b.bitrate}
    h = b.health
    if h is not None:
        out.update(healthy=h.healthy, error_state=h.error_state.value,
                   error_frames=dict(h.error_frames), last_error_frame=h.last_error_frame)
    out.update(bits=b.bits, time_s=_f(b.time_s), frames=[
        {"id": f.can_id, "extended": f.extended, "direction": f.direction.value, "count": f.count}
        for f in b.frames])
    return out


def status_to_json(status: GatewayStatus) -> dict[str, object]:
    """The status as JSON data (``dict``, ``list``, ``str``, numbers, ``bool``, ``None``)."""
    s, cmd, tr = status, status.command, status.tracking
    counters = s.counters
    out: dict[str, object] = {
        "robot": s.robot, "state": state_name(s.state), "reason": s.reason,
        "command": {"target": _twist(cmd.target), "applied": _twist(cmd.applied),
                    "cmd_timeout_active": cmd.cmd_timeout_active,
                    "speed_scale": _f(cmd.speed_scale), "accel_scale": _f(cmd.accel_scale)},
        "motors": [_motor(m) for m in s.motors],
    }
    if tr is not None:
        lim = tr.limits
        out["tracking"] = {
            "tolerance_rad_s": _f(lim.tolerance_rad_s), "tolerance_ratio": _f(lim.tolerance_ratio),
            "time_s": _f(lim.time_s), "steer_tolerance_rad": _f(lim.steer_tolerance_rad),
            "worst_ratio": _f(tr.worst_ratio), "steer_worst_ratio": _f(tr.steer_worst_ratio)}
    out.update({
        "odometry": odometry_to_json(s.odometry),
        "counters": {
            **counters.events,
            "rejected_frames": {k: dict(v) for k, v in counters.rejected_frames.items()},
            "commands_not_followed": {k: dict(v)
                                      for k, v in counters.commands_not_followed.items()}},
        "socket": {"path": s.socket.path,
                   **{name: getattr(s.socket.counters, name) for name in _SERVER_COUNTERS}},
        "timing": _timing(s.timing),
        "last_error": None if s.last_error is None else {
            "code": state_name(s.last_error.code), "message": s.last_error.message},
        "realtime": list(s.realtime),
        "bus": _bus(s.bus),
    })
    if s.config is not None:
        out["config"] = {"path": s.config.path, "fingerprint": s.config.fingerprint}
    return out
