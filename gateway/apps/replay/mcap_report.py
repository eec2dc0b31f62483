"""What ``wheelgate odom FILE.mcap`` says about a replayed recording: text, JSON, warnings.

The text keeps the lines of a candump replay that mean the same (``robot``, ``time``,
``odometry``, ``final pose``, ``distance``, ``steering``, in the same format) and adds what only
a recording has: its messages by topic, the pose the replay started at, the recording's own
last ``/odom`` (``recorded``) and the ``difference`` (replayed - recorded).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from gateway.apps.replay.mcap_source import pose_difference
from gateway.core.numfmt import fixed
from gateway.core.odom_feed import jumps_warning
from gateway.core.steer_log import SteeringSource
from gateway.runtime.liveview_channels import ODOM_TOPIC, STEERING_TOPIC, WHEELS_TOPIC

if TYPE_CHECKING:
    from gateway.apps.replay.mcap_source import McapSummary
    from gateway.core.kinematics.odometry import Pose
    from gateway.core.settings import GatewayConfig

__all__ = ["failure", "pose_text", "summary_json", "summary_lines", "warnings"]


def pose_text(p: Pose) -> str:
    """``x +1.2500 m, y -0.5000 m, theta +0.1000 rad (+5.73 deg)``: the pose as both replays
    write it (0.1 mm, 0.1 mrad)."""
    return (f"x {fixed(p.x_m, 4, sign=True)} m, y {fixed(p.y_m, 4, sign=True)} m, "
            f"theta {fixed(p.theta_rad, 4, sign=True)} rad "
            f"({fixed(math.degrees(p.theta_rad), 2, sign=True)} deg)")


def _factor(s: McapSummary, wall_s: float) -> float | None:
    return s.duration_s / wall_s if wall_s > 0 and s.duration_s > 0 else None


def summary_lines(cfg: GatewayConfig, path: str, s: McapSummary, wall_s: float) -> list[str]:
    """The summary, line by line."""
    n = s.messages
    factor = _factor(s, wall_s)
    lines = [
        f"robot: {cfg.name} ({cfg.drive}, {cfg.model.n} wheels); recording: {path}"
        + (f" (of {s.robot})" if s.robot else ""),
        f"messages: {sum(n.values()):,} read ({n.get(WHEELS_TOPIC, 0):,} on {WHEELS_TOPIC}, "
        f"{n.get(STEERING_TOPIC, 0):,} on {STEERING_TOPIC}, {n.get(ODOM_TOPIC, 0):,} on "
        f"{ODOM_TOPIC})" + ("; the file is damaged: see the warning" if s.damage else ""),
        f"time: {s.duration_s:.3f} s of recording replayed in {wall_s:.3f} s"
        + (f" ({factor:.1f}x real time)" if factor is not None else ""),
        f"odometry: {s.updates:,} updates, one per {WHEELS_TOPIC} message",
        f"start: {pose_text(s.start)} "
        + ("(nothing was replayed)" if not s.updates else
           "(the recording's pose there)" if s.from_recording else
           f"(the origin: no {ODOM_TOPIC} before the first {WHEELS_TOPIC})"),
        f"final pose: {pose_text(s.pose)}",
        f"distance: {fixed(s.distance_m, 3)} m",
        f"steering: {s.steering.value}",
    ]
    if s.recorded is None:
        lines.append(f"recorded: none (no {ODOM_TOPIC} messages: nothing to compare)")
        return lines
    lines.append(f"recorded: {pose_text(s.recorded)}; distance "
                 f"{fixed(s.recorded_distance_m or 0.0, 3)} m (the last {ODOM_TOPIC} message)")
    if not s.updates:
        lines.append("difference: none (nothing was replayed)")
        return lines
    dx, dy, dtheta = pose_difference(s.pose, s.recorded)
    lines += [
        f"difference: x {fixed(dx, 4, sign=True)} m, y {fixed(dy, 4, sign=True)} m, "
        f"theta {fixed(dtheta, 4, sign=True)} rad ({fixed(math.hypot(dx, dy), 4)} m apart); "
        f"distance {fixed(s.distance_m - (s.recorded_distance_m or 0.0), 4, sign=True)} m "
        "(replayed - recorded)",
    ]
    return lines


def summary_json(cfg: GatewayConfig, path: str, s: McapSummary,
                 wall_s: float) -> dict[str, object]:
    """The summary as a JSON object (the candump replay's keys where they mean the same)."""
    recorded = difference = None
    if s.recorded is not None:
        r = s.recorded
        recorded = {"x": r.x_m, "y": r.y_m, "theta": r.theta_rad,
                    "distance_m": s.recorded_distance_m}
    if s.recorded is not None and s.updates:
        r = s.recorded
        dx, dy, dtheta = pose_difference(s.pose, r)
        difference = {"x": dx, "y": dy, "theta": dtheta,
                      "distance_m": s.distance_m - (s.recorded_distance_m or 0.0)}
    return {
        "robot": cfg.name,
        "log": path,
        "format": "mcap",
        "recorded_robot": s.robot or None,
        "pose": {"x": s.pose.x_m, "y": s.pose.y_m, "theta": s.pose.theta_rad},
        "start_pose": {"x": s.start.x_m, "y": s.start.y_m, "theta": s.start.theta_rad},
        "distance_m": s.distance_m,
        "messages": dict(s.messages),
        "updates": s.updates,
        "skipped_updates": s.skipped_updates,
        "position_jumps": s.position_jumps,
        "start_s": s.start_s,
        "duration_s": s.duration_s,
        "replay_s": wall_s,
        "speed_factor": _factor(s, wall_s),
        "steering": s.steering.name.lower(),
        "silent_wheels": list(s.silent_wheels),
        "recorded": recorded,
        "difference": difference,
        "damage": s.damage or None,
        "unreadable": s.unreadable,
    }


def warnings(cfg: GatewayConfig, path: str, s: McapSummary) -> list[str]:
    """What the replay could not do as asked (one sentence each)."""
    out = []
    if s.damage:
        out.append(f"{path}: {s.damage}: replayed what came before")
    if s.unreadable:
        out.append(f"{s.unreadable:,} messages on {WHEELS_TOPIC}, {STEERING_TOPIC} or "
                   f"{ODOM_TOPIC} were not JSON objects: skipped")
    if s.robot and s.robot != cfg.name:
        out.append(f"the recording is of robot {s.robot!r}, the configuration of {cfg.name!r}")
    if s.steering is SteeringSource.NEUTRAL:
        out.append(f"{cfg.name} has steered wheels without steering actuators and none of its "
                   "wheels that are not steered fix the twist: they were replayed at their "
                   "neutral angles, so every turn of theirs is missing from the pose")
    if s.silent_wheels and s.updates:
        out.append(f"no angle of {', '.join(s.silent_wheels)} in the recording")
    if s.skipped_updates:
        out.append(f"{s.skipped_updates} odometry intervals could not be solved (too few "
                   "wheels with an angle); their motion is missing")
    if s.position_jumps:
        out.append(jumps_warning(s.position_jumps, s.last_jump))
    return out


def failure(cfg: GatewayConfig, path: str, s: McapSummary) -> str | None:
    """Why the replay gave no odometry (``None`` when it did)."""
    if s.updates:
        return None
    wheels = s.messages.get(WHEELS_TOPIC, 0)
    text = (f"{path}: no odometry: {wheels:,} {WHEELS_TOPIC} messages in "
            f"{sum(s.messages.values()):,}")
    if not wheels:
        if not s.damage:
            text += " (is it a recording of wheelgate's live view?)"
    elif s.silent_wheels:
        text += (f", none with an angle of {', '.join(s.silent_wheels)} (is it the right "
                 "config?)")
    if s.damage:
        text += f"; {s.damage}"
    return text
