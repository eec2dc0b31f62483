"""The gateway's status as a JSON-able mapping (socket ``status`` and ``wheelgate status``)."""

from __future__ import annotations

import dataclasses
import math
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from gateway.runtime.daemon import Daemon


def _finite(value: float | None) -> float | None:
    return None if value is None or not math.isfinite(value) else value


def status_dict(daemon: Daemon, now_s: float) -> dict[str, object]:
    """Everything a status request returns: state, motors, odometry, counters, timing."""
    gw = daemon.gateway
    sup = gw.supervisor
    protection = {}
    for drv, _ in gw.drives.groups:
        for i, m in enumerate(drv.motors):
            prot = drv.protection(i)
            protection[m.wheel] = {"guard": prot.guard.value, "timeout_s": prot.timeout_s,
                                   "state": drv.protection_state(i).value}
    motors = []
    for st in gw.drives.status(now_s):
        fb = st.feedback
        motors.append({
            "name": st.name,
            "node_id": st.node_id,
            "state": st.state,
            "faults": st.faults,
            "detail": st.detail,
            "feedback_age_s": _finite(st.feedback_age_s),
            "position_rad": None if fb is None else fb.position_rad,
            "velocity_rad_s": None if fb is None else fb.velocity_rad_s,
            "controller_stop": protection.get(st.name),
        })
    rejected = {
        type(drv).__name__: dict(drv.rejected) for drv, _ in gw.drives.groups if drv.rejected
    }
    not_followed = {
        type(drv).__name__: dict(drv.command_counts)
        for drv, _ in gw.drives.groups
        if drv.command_counts
    }
    limit = gw.limit_report
    timing = {**dataclasses.asdict(daemon.scheduler.timer.snapshot()),
              "burst_gap_max_ms": gw.burst_gap_max_s * 1000.0}
    return {
        "robot": gw.config.name,
        "state": sup.state,
        "reason": sup.reason,
        "command": {
            "target": sup.target,
            "applied": gw.prev.twist,
            "cmd_timeout_active": sup.cmd_timeout_active,
            "speed_scale": 1.0 if limit is None else limit.speed_scale,
            "accel_scale": 1.0 if limit is None else limit.accel_scale,
        },
        "motors": motors,
        "tracking": {
            **dataclasses.asdict(sup.tracking.limits),
            "worst_ratio": sup.tracking.worst_ratio,
            "steer_worst_ratio": sup.steer_tracking.worst_ratio,
        },
        "odometry": gw.odometry_dict(),
        "counters": {**gw.counts, **sup.counts, "rejected_frames": rejected,
                     "commands_not_followed": not_followed},
        "socket": {"path": daemon.socket_path,
                   **dataclasses.asdict(daemon.server.counters)},
        "timing": timing,
        "last_error": gw.last_error,
        "realtime": daemon.rt_notes,
        "bus": {
            "interface": gw.config.bus.interface,
            "channel": gw.config.bus.channel,
            "bitrate": gw.config.bus.bitrate,
            "healthy": gw.bus_healthy,
            "error_state": gw.bus_errors.state.value,
            "error_frames": dict(gw.bus_errors.counts),
            "last_error_frame": gw.bus_errors.last,
            "bits": gw.bits,
            "time_s": now_s,
            "frames": [
                {"id": can_id, "extended": ext, "direction": "tx" if sent else "rx", "count": n}
                for (can_id, ext, sent), n in sorted(gw.id_counts.items())
            ],
        },
    }
