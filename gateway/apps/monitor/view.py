"""What one screen of ``wheelgate monitor`` holds.

Frozen snapshots (:class:`MonitorSnapshot` with :class:`MotorView`, :class:`IdView` and
:class:`BusLoad`), written as JSON data by :func:`snapshot_json` and drawn as text by
:func:`gateway.apps.monitor.screen.render`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from gateway.core.types import hex_id

if TYPE_CHECKING:
    from gateway.drive.labels import FrameLabel

@dataclass(frozen=True, slots=True)
class MotorView:
    """One motor as the monitor sees it (``None``: not known yet).

    :param velocity_rad_s: wheel speed, rad/s.
    :param motor_rpm: motor shaft speed through gear ratio and inversion, rpm.
    :param position_rad: wheel angle since the first feedback, rad (a steering actuator: the
        steering angle).
    :param feedback_age_s: time since the last feedback, s.
    :param steers: a steering actuator's wheels (empty for a drive motor).
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
    steers: tuple[str, ...] = ()


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
    bit stuffing; ``None`` when the source does not know it); ``budget_percent``: what the
    configuration's periodic frames need, nominal and worst case
    (:mod:`gateway.config.budget`), to set the measured load against."""

    bitrate: int
    frames_per_s: float
    nominal_percent: float
    worst_percent: float | None
    budget_percent: tuple[float, float] | None = None


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


#: The error counter of every bus error frame, and the prefix of those by error class
#: (``"bus error frames: bus off"``), which the screen shows in parentheses after it.
ERROR_FRAMES = "bus error frames"
_CLASS_PREFIX = f"{ERROR_FRAMES}: "


def error_class_counter(name: str) -> str:
    """The error counter of one class of error frames (``"bus_off"``: ``"bus error frames:
    bus off"``)."""
    return _CLASS_PREFIX + name.replace("_", " ")


def error_class_of(counter: str) -> str | None:
    """The class of an error counter from :func:`error_class_counter` (``"bus off"``), else
    ``None``."""
    return counter.removeprefix(_CLASS_PREFIX) if counter.startswith(_CLASS_PREFIX) else None


def snapshot_json(snap: MonitorSnapshot) -> dict[str, object]:
    """The snapshot as JSON-able data (``wheelgate monitor --once --json``)."""
    load = snap.load
    return {
        "source": snap.source, "time_s": snap.time_s, "elapsed_s": snap.elapsed_s,
        "window_s": snap.window_s,
        "state": snap.state, "frames": snap.frames,
        "load": {"bitrate": load.bitrate, "frames_per_s": load.frames_per_s,
                 "nominal_percent": load.nominal_percent, "worst_percent": load.worst_percent,
                 "budget_percent": None if load.budget_percent is None
                 else list(load.budget_percent)},
        "motors": [
            {"name": m.name, "driver": m.driver, "node_id": m.node_id, "state": m.state,
             "faults": list(m.faults), "detail": m.detail, "velocity_rad_s": m.velocity_rad_s,
             "motor_rpm": m.motor_rpm, "position_rad": m.position_rad,
             "feedback_age_s": m.feedback_age_s, "steers": list(m.steers)}
            for m in snap.motors
        ],
        "ids": [
            {"id": i.arbitration_id, "id_hex": hex_id(i.arbitration_id, i.extended),
             "extended": i.extended, "remote": i.remote, "direction": i.direction,
             "count": i.count, "rate_hz": i.rate_hz, "label": i.label.text,
             "source": i.label.source, "node_id": i.label.node_id, "message": i.label.message,
             "wheels": list(i.label.wheels)}
            for i in snap.ids
        ],
        "errors": dict(snap.errors),
        "notes": list(snap.notes),
    }
