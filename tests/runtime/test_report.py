"""The status the daemon reports (:mod:`gateway.runtime.report`): its reply is, byte for byte,
the one the daemon sent before the typed model, and reads back into the same model."""

from __future__ import annotations

import binascii
import dataclasses
import json
import math
from pathlib import Path
from typing import TYPE_CHECKING

import pytest

from gateway.bus.edge import EdgeCounts
from gateway.core.counts import SupervisorCounts
from gateway.core.types import DriveState, ErrorCode, GatewayState, Twist
from gateway.runtime.counts import LoopCounts
from gateway.runtime.report import build_status, event_counts
from gateway.sim.device import SimFault
from gateway.wire.socket import TwistRequest, reply_ok, reply_ok_data
from gateway.wire.socket.status import status_from_json, status_to_json
from tests.conftest import CONFIG_DIR
from tests.e2e_helpers import Rig, virtual_config

if TYPE_CHECKING:
    from gateway.core.status import GatewayStatus
    from gateway.runtime.daemon import Daemon

pytestmark = pytest.mark.timeout(60)


def _finite(value: float | None) -> float | None:
    return None if value is None or not math.isfinite(value) else value


#: The event counters in the order of the daemon's counter dictionaries before they were typed
#: (issue 15): the gateway's, the keys its bus edge added, the supervisor's.
LEGACY_EVENTS = (
    "cycles", "frames_sent", "frames_received", "send_failures", "bus_reopens", "can_twists",
    "can_duplicates", "can_lost", "bad_can_twists", "errors_reported", "odometry_errors",
    "receive_failures", "frames_unsent", "partial_bursts", "send_waits", "fd_frames_ignored",
    "infeasible", "projected", "rejected", "faults", "cmd_timeouts", "estops",
)
#: The event counters added since, after the legacy ones in the status.
ADDED_EVENTS = ("errors_not_sent", "position_jumps")


def legacy_counts(daemon: Daemon) -> dict[str, int]:
    """The event counters as the daemon's dictionaries held them, in their order (then the
    ones added since)."""
    gw = daemon.gateway
    owners = (gw.counts, gw.edge.counts, gw.supervisor.counts)
    return {name: next(getattr(o, name) for o in owners if hasattr(o, name))
            for name in LEGACY_EVENTS + ADDED_EVENTS}


def legacy_status(daemon: Daemon, now_s: float) -> dict[str, object]:
    """The status reply's payload exactly as the daemon built it before the typed model
    (``gateway/runtime/report.py`` of the commit before issue 15): the oracle of the wire form.
    Since the counters, the odometry and the last error were typed (issue 15 too), their
    dictionaries are rebuilt here as they were."""
    gw = daemon.gateway
    sup = gw.supervisor
    odom = gw.odometry.state
    error = gw.last_error
    protection: dict[str, object] = {}
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
        "odometry": {
            "x": odom.pose.x_m, "y": odom.pose.y_m, "theta": odom.pose.theta_rad,
            "vx": odom.twist.vx_m_s, "vy": odom.twist.vy_m_s, "wz": odom.twist.wz_rad_s,
            "slip": odom.slip_m_s, "distance": odom.distance_m, "t": odom.timestamp_s,
        },
        "counters": {**legacy_counts(daemon), "rejected_frames": rejected,
                     "commands_not_followed": not_followed},
        "socket": {"path": daemon.socket_path,
                   **dataclasses.asdict(daemon.server.counters)},
        "timing": timing,
        "last_error": None if error is None else {"code": error.code.name.lower(),
                                                  "message": error.message},
        "realtime": daemon.rt_notes,
        "bus": {
            "interface": gw.config.bus.interface,
            "channel": gw.config.bus.channel,
            "bitrate": gw.config.bus.bitrate,
            "healthy": gw.edge.bus_healthy,
            "error_state": gw.edge.bus_errors.state.value,
            "error_frames": dict(gw.edge.bus_errors.counts),
            "last_error_frame": gw.edge.bus_errors.last,
            "bits": gw.edge.bits,
            "time_s": now_s,
            "frames": [
                # The one change: int(can_id).  A frame ID that is an IntEnum member (CiA 402's
                # NMT and SYNC) went out as the member's name ("nmt"), which no reader took.
                {"id": int(can_id), "extended": ext, "direction": "tx" if sent else "rx",
                 "count": n}
                for (can_id, ext, sent), n in sorted(gw.edge.id_counts.items())
            ],
        },
        # The one key added since: the file the daemon runs (absolute) and its text's CRC-32.
        "config": {"path": gw.config.path, "fingerprint": gw.config.fingerprint},
    }


def _built(daemon: Daemon, now_s: float) -> GatewayStatus:
    return build_status(daemon.gateway, daemon.scheduler.timer.snapshot(), daemon.socket_path,
                        daemon.server.counters, daemon.rt_notes, now_s)


def _check(daemon: Daemon, now_s: float) -> GatewayStatus:
    """The reply built from the model is the legacy one, and reads back to the same model."""
    status = _built(daemon, now_s)
    line = reply_ok_data(7, status_to_json(status))
    assert line == reply_ok(7, legacy_status(daemon, now_s))
    reply = json.loads(line)
    assert status_from_json(reply) == status
    payload = {k: v for k, v in reply.items() if k not in ("ok", "id")}
    assert json.dumps(status_to_json(status_from_json(reply))) == json.dumps(payload)
    return status


@pytest.mark.parametrize("name", ["turtlebot3_burger.yaml", "swerve.yaml", "ackermann.yaml",
                                  "differential_tub.yaml", "mecanum.yaml", "tricycle.yaml",
                                  "example_dbc.yaml"])
def test_the_reply_is_the_one_the_daemon_sent_before(name: str, channel: str,
                                                      sock_path: str) -> None:
    with Rig(virtual_config(CONFIG_DIR / name, channel), sock_path) as rig:
        daemon = rig.daemon
        assert daemon is not None
        daemon.rt_notes = ["gc: 1 start-up object frozen"]
        _check(daemon, rig.t)  # before anything answered: no feedback, no odometry
        rig.enable()
        daemon.handle(1, TwistRequest(Twist(0.1, 0.0, 0.1)), rig.t)
        rig.advance(0.3)
        running = _check(daemon, rig.t)
        assert running.state is GatewayState.RUNNING
        assert all(m.state is DriveState.ENABLED for m in running.motors)
        rig.drive_sims[0].inject(SimFault.SILENT)
        rig.drive_sims[-1].inject(SimFault.FAULT)
        rig.advance(1.5)
        faulted = _check(daemon, rig.t)
        assert faulted.state is GatewayState.FAULT and faulted.reason
        assert faulted.last_error is not None
        assert faulted.last_error.code in (ErrorCode.FEEDBACK_TIMEOUT, ErrorCode.MOTOR_FAULT)


def test_every_event_counter_is_reported_under_its_name_in_the_legacy_order() -> None:
    loop, edge, sup = LoopCounts(), EdgeCounts(), SupervisorCounts()
    expected: dict[str, int] = {}
    for n, (record, field) in enumerate(
            (r, f.name) for r in (loop, edge, sup) for f in dataclasses.fields(r)):
        setattr(record, field, 1000 + n)  # every counter a value of its own
        expected[field] = 1000 + n
    events = event_counts(loop, edge, sup)
    assert dict(events) == expected
    assert tuple(events) == LEGACY_EVENTS + ADDED_EVENTS


def test_the_status_names_the_file_by_its_absolute_path_and_its_bytes_crc(
        channel: str, sock_path: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A daemon started with a relative -c path names its file absolutely (a client runs
    elsewhere), with the CRC-32 of the bytes it read."""
    (tmp_path / "robot.yaml").write_bytes((CONFIG_DIR / "turtlebot3_burger.yaml").read_bytes())
    monkeypatch.chdir(tmp_path)
    with Rig(virtual_config(Path("robot.yaml"), channel), sock_path) as rig:
        daemon = rig.daemon
        assert daemon is not None
        config = _built(daemon, rig.t).config
    assert config is not None
    assert config.path == str(tmp_path / "robot.yaml")
    assert config.fingerprint == f"{binascii.crc32((tmp_path / 'robot.yaml').read_bytes()):08x}"
