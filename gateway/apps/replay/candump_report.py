"""What ``wheelgate odom LOG`` says about a replayed candump log: text, JSON, warnings.

Beside the replay's own lines (what was read, the final pose, the distance, where the steering
angles came from) it judges the replay by what else the log holds:

* the gateway's own odometry (``WG_Odom_Pose`` frames of a ``wheelgate run --record`` log,
  :mod:`gateway.apps.replay.gateway_pose`): the ``gateway`` line gives the difference at the end
  and the largest on the way; a difference above :data:`POSE_TOLERANCE_M` (or
  :data:`POSE_TOLERANCE_RATIO` of the distance) is a warning, since both come from the same
  encoder frames;
* the controllers the log shows that the configuration does not name (found by the protocols'
  scan probes, :mod:`gateway.apps.scan.classify`, among the frames no driver took): when they
  send :data:`FOREIGN_SHARE` of the controllers' frames or more, the log is probably another
  robot's (a mecanum log replayed with a two-wheeled configuration takes two of its four
  wheels and reports a path that never was).

What the replay went on without is counted in the summary and named in the warnings, as the
unreadable lines are: the lines out of time and the breaks in the log's time
(:mod:`gateway.apps.replay.timeline`), and the motors' frames their drivers rejected
(:mod:`gateway.drive.rejections`; what they carried is missing from the odometry).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from gateway.apps.replay.mcap_report import pose_text
from gateway.core.numfmt import fixed, short
from gateway.core.odom_feed import jumps_warning
from gateway.core.steer_log import SteeringSource

if TYPE_CHECKING:
    from gateway.apps.replay.replay import Replay, ReplaySummary
    from gateway.core.settings import GatewayConfig

#: Corrupt lines reported one by one; the rest are counted.
MAX_REPORTED = 20
#: A replay further than this from the gateway's own pose frames is warned about (m) ...
POSE_TOLERANCE_M = 0.05
#: ... or further than this share of the distance, whichever is larger.
POSE_TOLERANCE_RATIO = 0.02
#: The share of the controllers' frames, from controllers the configuration does not name,
#: above which the log is said to be probably another robot's.
FOREIGN_SHARE = 0.25


def _many(n: int, thing: str) -> str:
    return f"{n:,} {thing}{'' if n == 1 else 's'}"


def _factor(s: ReplaySummary, wall_s: float) -> float | None:
    return s.duration_s / wall_s if wall_s > 0 and s.duration_s > 0 else None


def summary_lines(cfg: GatewayConfig, log_path: str, s: ReplaySummary, wall_s: float,
                  min_interval_s: float) -> list[str]:
    """The summary, line by line."""
    factor = _factor(s, wall_s)
    rejected = s.rejected_frames
    lines = [
        f"robot: {cfg.name} ({cfg.drive}, {cfg.model.n} wheels); log: {log_path}",
        f"frames: {s.entries:,} read ({s.received:,} received, {s.entries - s.received:,} "
        f"sent), {s.motor_frames:,} of the motors"
        + (f" ({rejected:,} rejected by their drivers)" if rejected else "")
        + f"; {s.corrupt_lines:,} unreadable lines skipped"
        + (f", {_many(s.out_of_time_lines, 'line')} out of time skipped"
           if s.out_of_time_lines else ""),
        f"time: {s.duration_s:.3f} s of log replayed in {wall_s:.3f} s"
        + (f" ({factor:.1f}x real time)" if factor is not None else "")
        + (f"; {_many(s.breaks, 'break')} in the log's time" if s.breaks else "")
        + (f" ({fixed(s.gap_s, 3)} s of gaps left out)" if s.gap_s else ""),
        f"odometry: {s.updates:,} updates, at most one per {short(min_interval_s * 1e3, 3)} ms "
        f"of log time",
        f"final pose: {pose_text(s.pose)}",
        f"distance: {fixed(s.distance_m, 3)} m",
        f"steering: {s.steering.value}",
    ]
    check = s.pose_check
    if check is not None:
        lines.append(
            f"gateway: {check.frames:,} WG_Odom_Pose frames in the log; the replay ends "
            f"{fixed(check.position_error_m, 3)} m and "
            f"{fixed(abs(check.heading_error_rad), 4)} rad from the gateway's own odometry "
            f"(at most {fixed(check.max_position_error_m, 3)} m and "
            f"{fixed(check.max_heading_error_rad, 4)} rad on the way)")
    return lines


def summary_json(cfg: GatewayConfig, log_path: str, s: ReplaySummary, wall_s: float,
                 replay: Replay) -> dict[str, object]:
    """The summary as ``--json`` prints it (full precision)."""
    check = s.pose_check
    return {
        "robot": cfg.name,
        "log": log_path,
        "pose": {"x": s.pose.x_m, "y": s.pose.y_m, "theta": s.pose.theta_rad},
        "distance_m": s.distance_m,
        "frames": {"read": s.entries, "received": s.received, "motors": s.motor_frames},
        "unreadable_lines": s.corrupt_lines,
        "unreadable": [{"line": e.line_number, "message": str(e)}
                       for e in replay.errors[:MAX_REPORTED]],
        "out_of_time_lines": s.out_of_time_lines,
        "out_of_time": [{"line": e.line_number, "time_s": e.time_s, "previous_s": e.previous_s,
                         "message": str(e)} for e in replay.timeline.bad[:MAX_REPORTED]],
        "time_breaks": s.breaks,
        "breaks": [{"line": b.line_number, "time_s": b.time_s, "previous_s": b.previous_s,
                    "message": str(b)} for b in replay.timeline.breaks[:MAX_REPORTED]],
        "gap_s": s.gap_s,
        "rejected_frames": s.rejected_frames,
        "rejected": [{"driver": r.driver, "reason": r.reason, "frames": r.frames,
                      "last": r.last} for r in s.rejections],
        "updates": s.updates,
        "skipped_updates": s.skipped_updates,
        "position_jumps": s.position_jumps,
        "min_interval_s": replay.min_interval_s,
        "start_s": s.start_s,
        "duration_s": s.duration_s,
        "replay_s": wall_s,
        "speed_factor": _factor(s, wall_s),
        "steering": s.steering.name.lower(),
        "silent_wheels": list(s.silent_wheels),
        "gateway": None if check is None else {
            "frames": check.frames,
            "position_error_m": check.position_error_m,
            "heading_error_rad": check.heading_error_rad,
            "max_position_error_m": check.max_position_error_m,
            "max_heading_error_rad": check.max_heading_error_rad,
        },
    }


@dataclass(frozen=True, slots=True)
class Foreign:
    """Controllers in a log that the configuration does not name.

    :param devices: ``(protocol title, node ID, frames)`` each.
    :param share: their frames over all the controllers' frames (theirs and the robot's).
    """

    devices: tuple[tuple[str, int, int], ...]
    share: float


def foreign_controllers(cfg: GatewayConfig, replay: Replay,
                        motor_frames: int) -> Foreign | None:
    """The controllers the scan probes find among the frames no driver took (the gateway's
    own messages aside), ``None`` when there are none."""
    from gateway.apps.scan.classify import classify  # noqa: PLC0415 - only with such frames
    from gateway.apps.scan.own import own_messages  # noqa: PLC0415
    from gateway.apps.scan.registry import load_probes  # noqa: PLC0415
    from gateway.drive.scan import Heard  # noqa: PLC0415

    # The frames this robot's drivers send (their commands) are its own, not a controller's
    # (a DBC robot's command on 0x201 looked like a DJI ESC's feedback).
    sent = [c for drv, _ in replay.drives.groups for c in drv.claims() if not c.receive]
    unclaimed = {key: v for key, v in replay.unclaimed.items()
                 if not any(c.matches(*key) for c in sent)}
    if not unclaimed:
        return None
    duration = max(replay.summary().duration_s, 1e-9)
    heard = [Heard(i, ext, n, n / duration, last) for (i, ext), (n, last) in unclaimed.items()]
    found = classify(load_probes(), heard, own_messages(cfg, drivers=False)).devices
    if not found:
        return None
    devices = tuple((s.probe.TITLE or s.probe.PROTOCOL, s.found.node_id,
                     sum(h.count for h in s.heard)) for s in found)
    theirs = sum(n for _, _, n in devices)
    return Foreign(devices, theirs / (theirs + motor_frames))


def warnings(cfg: GatewayConfig, s: ReplaySummary, foreign: Foreign | None = None) -> list[str]:
    """What the reader of the summary should not miss."""
    out = [f"{r.driver} rejected {_many(r.frames, 'frame')} of the motors, the replay went on "
           f"without {'it' if r.frames == 1 else 'them'} ({r.reason}"
           + (f"; the last: {r.last}" if r.last else "") + ")"
           for r in s.rejections]
    if foreign is not None and foreign.share >= FOREIGN_SHARE:
        named = ", ".join(f"{title} node {node}" for title, node, _ in foreign.devices[:8])
        more = f" and {len(foreign.devices) - 8} more" if len(foreign.devices) > 8 else ""
        out.append(
            f"{foreign.share:.0%} of the controllers' frames in the log come from controllers "
            f"{cfg.name}'s configuration does not name ({named}{more}): probably another "
            f"robot's log; replay it with that robot's configuration (-c)")
    if s.steering is SteeringSource.NEUTRAL:
        out.append(f"{cfg.name} has steered wheels and the log holds no WG_Odom_Velocity "
                   "frames: they were replayed at their neutral angles, so every turn of "
                   "theirs is missing from the pose")
    if s.silent_wheels and s.updates:
        out.append(f"no feedback from {', '.join(s.silent_wheels)}")
    if s.skipped_updates:
        out.append(f"{s.skipped_updates} odometry intervals could not be solved (too few "
                   "wheels with feedback); their motion is missing")
    if s.position_jumps:
        out.append(jumps_warning(s.position_jumps, s.last_jump))
    check = s.pose_check
    if check is not None:
        allowed = max(POSE_TOLERANCE_M, POSE_TOLERANCE_RATIO * s.distance_m)
        if check.max_position_error_m > allowed:
            out.append(
                f"the replay departs from the gateway's own odometry in the log by up to "
                f"{fixed(check.max_position_error_m, 3)} m (more than {allowed:.3g} m): the "
                f"configuration is probably not the one the gateway ran (wheel radius, "
                f"gear_ratio, invert, geometry), or its odometry was reset during the log")
    return out
