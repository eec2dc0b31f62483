"""What one screen of ``wheelgate monitor`` holds, and how it is drawn.

Frozen snapshots (:class:`MonitorSnapshot` with :class:`MotorView`, :class:`IdView` and
:class:`BusLoad`), drawn as text by :func:`render` and as JSON data by :func:`snapshot_json`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from gateway.drive.labels import FrameLabel

@dataclass(frozen=True, slots=True)
class MotorView:
    """One motor as the monitor sees it (``None``: not known yet).

    :param velocity_rad_s: wheel speed, rad/s.
    :param motor_rpm: motor shaft speed through gear ratio and inversion, rpm.
    :param position_rad: wheel angle since the first feedback, rad.
    :param feedback_age_s: time since the last feedback, s.
    """

    name: str
    driver: str
    node_id: int
    state: str
    faults: tuple[str, ...]
    detail: str
    velocity_rad_s: float | None
    motor_rpm: float | None
    position_rad: float | None
    feedback_age_s: float | None


@dataclass(frozen=True, slots=True)
class IdView:
    """Traffic on one ID in one direction.

    :param direction: ``"rx"`` received or ``"tx"`` sent, as the gateway, the log or the
        listening monitor saw it.
    :param count: frames since the start.
    :param rate_hz: frames per second over the window.
    """

    arbitration_id: int
    extended: bool
    remote: bool
    direction: str
    count: int
    rate_hz: float
    label: FrameLabel


@dataclass(frozen=True, slots=True)
class BusLoad:
    """Bus load over the window, in percent of ``bitrate`` (``worst_percent``: with worst-case
    bit stuffing; ``None`` when the source does not know it)."""

    bitrate: int
    frames_per_s: float
    nominal_percent: float
    worst_percent: float | None


@dataclass(frozen=True, slots=True)
class MonitorSnapshot:
    """Everything one screen shows.

    :param source: where the data comes from, e.g. ``"log robot.log"``.
    :param time_s: the source's clock at the snapshot, s.
    :param elapsed_s: time since watching began (the first frame or status), s.
    :param window_s: the time the rates are averaged over, s.
    :param frames: frames seen since the start.
    :param errors: (counter name, count) pairs.
    :param state: the gateway's state (daemon source only).
    :param notes: remarks for the reader.
    """

    source: str
    time_s: float
    elapsed_s: float
    window_s: float
    frames: int
    load: BusLoad
    motors: tuple[MotorView, ...]
    ids: tuple[IdView, ...]
    errors: tuple[tuple[str, int], ...]
    state: str | None = None
    notes: tuple[str, ...] = ()


def _num(value: float | None, fmt: str, width: int, scale: float = 1.0) -> str:
    return f"{'-':>{width}}" if value is None else f"{value * scale:{width}{fmt}}"


def _hex_id(can_id: int, extended: bool) -> str:
    return f"0x{can_id:08X}" if extended else f"0x{can_id:03X}"


def render(snap: MonitorSnapshot, width: int = 100) -> str:
    """The snapshot as text lines no wider than ``width`` characters."""
    load = snap.load
    worst = "n/a" if load.worst_percent is None else f"{load.worst_percent:.1f} %"
    lines = [
        f"wheelgate monitor: {snap.source}  t = {snap.time_s:.3f} s (+{snap.elapsed_s:.3f} s)"
        + (f"  gateway {snap.state}" if snap.state else ""),
        f"bus {load.bitrate / 1000:g} kbit/s  load {load.nominal_percent:.1f} % nominal, "
        f"{worst} worst case  {load.frames_per_s:.0f} frames/s over {snap.window_s:.2f} s  "
        f"{snap.frames} frames",
        "",
        f"{'MOTOR':<14}{'DRIVER':<8}{'NODE':>4}  {'STATE':<9}{'rad/s':>9}{'rpm':>9}"
        f"{'pos rad':>11}{'age ms':>9}  FAULTS",
    ]
    for m in snap.motors:
        faults = ", ".join(m.faults) + (f" {m.detail}" if m.detail else "")
        lines.append(
            f"{m.name:<14.14}{m.driver:<8.8}{m.node_id:>4}  {m.state:<9}"
            f"{_num(m.velocity_rad_s, '.3f', 9)}{_num(m.motor_rpm, '.1f', 9)}"
            f"{_num(m.position_rad, '.3f', 11)}{_num(m.feedback_age_s, '.1f', 9, 1000.0)}  "
            f"{faults or '-'}")
    lines += ["", f"{'ID':<11} {'DIR':<3}{'RATE Hz':>9}{'COUNT':>10}  MESSAGE"]
    for i in snap.ids:
        lines.append(f"{_hex_id(i.arbitration_id, i.extended):<11} {i.direction:<3}"
                     f"{i.rate_hz:9.1f}{i.count:10d}  {i.label.text}")
    lines += ["", "errors: " + (", ".join(f"{name} {n}" for name, n in snap.errors) or "-")]
    lines += [f"note: {note}" for note in snap.notes]
    return "\n".join(line[:width] for line in lines)


def snapshot_json(snap: MonitorSnapshot) -> dict[str, object]:
    """The snapshot as JSON-able data (``wheelgate monitor --once --json``)."""
    load = snap.load
    return {
        "source": snap.source, "time_s": snap.time_s, "elapsed_s": snap.elapsed_s,
        "window_s": snap.window_s,
        "state": snap.state, "frames": snap.frames,
        "load": {"bitrate": load.bitrate, "frames_per_s": load.frames_per_s,
                 "nominal_percent": load.nominal_percent, "worst_percent": load.worst_percent},
        "motors": [
            {"name": m.name, "driver": m.driver, "node_id": m.node_id, "state": m.state,
             "faults": list(m.faults), "detail": m.detail, "velocity_rad_s": m.velocity_rad_s,
             "motor_rpm": m.motor_rpm, "position_rad": m.position_rad,
             "feedback_age_s": m.feedback_age_s}
            for m in snap.motors
        ],
        "ids": [
            {"id": i.arbitration_id, "id_hex": _hex_id(i.arbitration_id, i.extended),
             "extended": i.extended, "remote": i.remote, "direction": i.direction,
             "count": i.count, "rate_hz": i.rate_hz, "label": i.label.text,
             "source": i.label.source, "node_id": i.label.node_id, "message": i.label.message,
             "wheels": list(i.label.wheels)}
            for i in snap.ids
        ],
        "errors": dict(snap.errors),
        "notes": list(snap.notes),
    }
