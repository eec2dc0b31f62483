"""Drawing a replayed trajectory, in the manner of seed 000's ``plotcar`` and ``plotomni``.

The path in grey, the robot at intervals along it in blue with its wheels in red (at their
configured places, with their radius, turned by their plane and steering angles) and every
driven wheel's speed as a green arrow along its rolling direction, proportional to the rim
speed.  Axes in metres with equal scales.  The path is drawn over the outlines (they are
faded), with time marks along it (:func:`time_marks`: a round step, about eight marks; one
where the robot stood still); a
second panel below shows every wheel's speed over the same time.

The geometry (:func:`body_outline`, :func:`wheel_box`, :func:`speed_arrow`,
:func:`pick_poses`) is pure and needs no matplotlib; :func:`plot_trajectory` imports
matplotlib when called (the optional extra ``wheelgate[plot]``) and draws on a
:class:`matplotlib.figure.Figure` with the Agg canvas, so no display and no pyplot state are
involved.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from collections.abc import Sequence

    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

    from gateway.apps.replay.replay import Sample
    from gateway.core.kinematics import Wheel
    from gateway.core.kinematics.odometry import Pose
    from gateway.core.settings import GatewayConfig

#: Colours of seed 000: path, body, wheels, wheel speeds.
PATH_COLOUR = "#A0A0A0"
BODY_COLOUR = "#0000A0"
WHEEL_COLOUR = "#A00000"
SPEED_COLOUR = "#00A000"
#: Longest wheel-speed arrow, as a fraction of the robot's size.
ARROW_FRACTION = 0.75
#: Most path points drawn (longer paths are thinned evenly).
MAX_PATH_POINTS = 20_000
#: How many time marks the path gets, about.
TIME_MARKS = 8
#: Opacity of the robot's body outlines, so the path and the wheels show through them.
ROBOT_ALPHA = 0.55

Point = tuple[float, float]


def _hull(points: Sequence[Point]) -> list[Point]:
    """Convex hull, counter-clockwise (Andrew's monotone chain)."""
    pts = sorted(set(points))
    if len(pts) < 3:
        return pts

    def cross(o: Point, a: Point, b: Point) -> float:
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])

    lower: list[Point] = []
    upper: list[Point] = []
    for p in pts:
        while len(lower) >= 2 and cross(lower[-2], lower[-1], p) <= 0:
            lower.pop()
        lower.append(p)
    for p in reversed(pts):
        while len(upper) >= 2 and cross(upper[-2], upper[-1], p) <= 0:
            upper.pop()
        upper.append(p)
    return lower[:-1] + upper[:-1]


def body_outline(wheels: Sequence[Wheel]) -> list[Point]:
    """The robot's outline in the body frame, closed: the convex hull of the wheels' mounting
    points; two wheels (or wheels in one line) give a rectangle 0.6 times as deep as it is
    long, one wheel a square of four radii.

    >>> from gateway.core.kinematics import PRESETS
    >>> body_outline(PRESETS["differential"].wheels(wheel_radius=0.1, track=0.4))
    [(-0.12, -0.2), (0.12, -0.2), (0.12, 0.2), (-0.12, 0.2), (-0.12, -0.2)]
    """
    hull = _hull([(round(w.x, 12), round(w.y, 12)) for w in wheels])
    if len(hull) >= 3:
        return [*hull, hull[0]]
    if len(hull) == 2:
        (x1, y1), (x2, y2) = hull
        length = math.hypot(x2 - x1, y2 - y1)
        nx, ny = -(y2 - y1) / length * 0.3 * length, (x2 - x1) / length * 0.3 * length
        corners = [(x1 + nx, y1 + ny), (x1 - nx, y1 - ny), (x2 - nx, y2 - ny),
                   (x2 + nx, y2 + ny)]
        ring = _hull([(round(x, 12), round(y, 12)) for x, y in corners])
        return [*ring, ring[0]]
    x, y = hull[0]
    h = 2.0 * wheels[0].radius
    return [(x - h, y - h), (x + h, y - h), (x + h, y + h), (x - h, y + h), (x - h, y - h)]


def wheel_box(wheel: Wheel, sigma: float = 0.0) -> list[Point]:
    """A wheel seen from above, in the body frame, closed: a rectangle at its mounting point,
    two radii long along its rolling direction and 0.6 radii wide (the seed's proportions).

    :param sigma: steering angle, rad (steered wheels).
    """
    h = wheel.heading(sigma)
    ux, uy = math.cos(h), math.sin(h)
    r, w = wheel.radius, 0.3 * wheel.radius
    cx, cy = wheel.x, wheel.y
    return [
        (cx - r * ux + w * uy, cy - r * uy - w * ux),
        (cx + r * ux + w * uy, cy + r * uy - w * ux),
        (cx + r * ux - w * uy, cy + r * uy + w * ux),
        (cx - r * ux - w * uy, cy - r * uy + w * ux),
        (cx - r * ux + w * uy, cy - r * uy - w * ux),
    ]


def speed_arrow(wheel: Wheel, sigma: float, wheel_rad_s: float, scale: float) -> tuple[Point,
                                                                                        Point]:
    """The arrow of a wheel's speed in the body frame: from its mounting point along its
    rolling direction, ``scale`` metres per m/s of rim speed.

    :return: start point and (dx, dy).
    """
    h = wheel.heading(sigma)
    length = wheel_rad_s * wheel.radius * scale
    return (wheel.x, wheel.y), (length * math.cos(h), length * math.sin(h))


def to_world(points: Sequence[Point], pose: Pose) -> tuple[list[float], list[float]]:
    """Body-frame points placed at ``pose``: (xs, ys)."""
    c, s = math.cos(pose.theta_rad), math.sin(pose.theta_rad)
    xs = [pose.x_m + c * x - s * y for x, y in points]
    ys = [pose.y_m + s * x + c * y for x, y in points]
    return xs, ys


def pick_poses(samples: Sequence[Sample], count: int) -> list[int]:
    """Indices of ``count`` samples evenly spaced along the path (by distance, so a robot
    that stood still is drawn once), the first and the last always among them."""
    if not samples or count <= 0:
        return []
    if count == 1 or len(samples) == 1:
        return [len(samples) - 1]
    d0, d1 = samples[0].distance_m, samples[-1].distance_m
    picked: list[int] = []
    k = 0
    for j in range(count):
        target = d0 + (d1 - d0) * j / (count - 1)
        while k < len(samples) - 1 and samples[k].distance_m < target:
            k += 1
        if not picked or k != picked[-1]:
            picked.append(k)
    if picked[-1] != len(samples) - 1:
        picked.append(len(samples) - 1)
    return picked


def mark_step(duration_s: float, count: int = TIME_MARKS) -> float:
    """A round time step (1, 2 or 5 times a power of ten) giving about ``count`` marks: the
    one nearest ``duration_s / count`` on a log scale.

    >>> mark_step(20.0), mark_step(3.0), mark_step(600.0), mark_step(0.0)
    (2.0, 0.5, 100.0, 1.0)
    """
    if not duration_s > 0.0:
        return 1.0
    raw = duration_s / max(1, count)
    power = 10.0 ** math.floor(math.log10(raw))
    return min((k * power for k in (1.0, 2.0, 5.0, 10.0)),
               key=lambda step: abs(math.log(step / raw)))


def time_marks(samples: Sequence[Sample], count: int = TIME_MARKS) -> list[tuple[int, float]]:
    """Where the path gets a time mark: ``(sample index, seconds since the first sample)`` at
    every round step (:func:`mark_step`), the first sample at or after each."""
    if not samples:
        return []
    t0 = samples[0].time_s
    step = mark_step(samples[-1].time_s - t0, count)
    marks: list[tuple[int, float]] = []
    k = 1
    for i, s in enumerate(samples):
        if s.time_s - t0 >= k * step - 1e-9:
            marks.append((i, round(k * step, 9)))
            k = math.floor((s.time_s - t0) / step + 1e-9) + 1
    return marks


def robot_size(wheels: Sequence[Wheel]) -> float:
    """Half the largest extent of the robot's outline, m (at least two wheel radii)."""
    pts = body_outline(wheels)
    span = max(max(x for x, _ in pts) - min(x for x, _ in pts),
               max(y for _, y in pts) - min(y for _, y in pts))
    return max(0.5 * span, 2.0 * max(w.radius for w in wheels))


def plot_trajectory(
    samples: Sequence[Sample],
    config: GatewayConfig,
    robots: int = 8,
    title: str | None = None,
) -> Figure:
    """Draw a replayed trajectory.

    :param samples: the odometry updates, in time order.
    :param config: the robot (wheel places, radii, names).
    :param robots: how many robot outlines to draw along the path (first and last included).
    :param title: the figure's title; by default the robot's name, distance and duration.
    :return: the figure (Agg canvas attached; save it with :func:`save_figure`).
    :raises ValueError: if there are no samples.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg  # noqa: PLC0415
    from matplotlib.figure import Figure  # noqa: PLC0415

    if not samples:
        raise ValueError("Expected at least one odometry sample to plot, but got none")
    wheels = config.model.wheels
    fig = Figure(figsize=(7.0, 9.0), dpi=100)
    FigureCanvasAgg(fig)
    grid = fig.add_gridspec(2, 1, height_ratios=(3, 1), hspace=0.25)
    ax = fig.add_subplot(grid[0])
    path = _thinned(samples)
    # Over the robot outlines (zorder), so the path stays visible where they cover it.
    ax.plot([s.pose.x_m for s in path], [s.pose.y_m for s in path], color=PATH_COLOUR,
            lw=1.0, label="path", zorder=5)
    size = robot_size(wheels)
    drawn: list[Pose] = []
    for index, seconds in time_marks(samples):
        pose = samples[index].pose
        if drawn and math.hypot(pose.x_m - drawn[-1].x_m, pose.y_m - drawn[-1].y_m) < 0.2 * size:
            continue  # standing still: one mark, not a pile of labels
        drawn.append(pose)
        ax.plot([pose.x_m], [pose.y_m], ".", color="black", ms=4, zorder=6)
        ax.annotate(f"{seconds:g} s", (pose.x_m, pose.y_m), xytext=(3, 3),
                    textcoords="offset points", fontsize="x-small", zorder=6)
    rims = [abs(v) * w.radius for s in samples for v, w in zip(s.wheel_rad_s, wheels,
                                                                  strict=True) if v is not None]
    top = max(rims, default=0.0)
    scale = ARROW_FRACTION * size / top if top > 0 else 0.0
    outline = body_outline(wheels)
    labels = {"robot": "robot", "wheel": "wheel",
              "speed": f"wheel speed ({scale:.2g} m per m/s at the rim)"}
    for index in pick_poses(samples, robots):
        _draw_robot(ax, samples[index], wheels, outline, scale, labels)
    start, end = samples[0].pose, samples[-1].pose
    ax.plot([start.x_m], [start.y_m], "o", color="black", mfc="none", ms=9, label="start",
            zorder=4)
    ax.plot([end.x_m], [end.y_m], "x", color="black", ms=9, mew=2, label="end", zorder=4)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.grid(True, color="#E0E0E0", lw=0.5)
    duration = samples[-1].time_s - samples[0].time_s
    ax.set_title(title if title is not None else
                 f"{config.name}: {samples[-1].distance_m:.2f} m in {duration:.1f} s")
    ax.legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize="small")
    _speed_panel(fig.add_subplot(grid[1]), samples, config)
    return fig


def _thinned(samples: Sequence[Sample]) -> list[Sample]:
    """At most about :data:`MAX_PATH_POINTS` samples, evenly, the last one always."""
    step = max(1, math.ceil(len(samples) / MAX_PATH_POINTS))
    shown = list(samples[::step])
    if shown[-1] is not samples[-1]:
        shown.append(samples[-1])
    return shown


def _speed_panel(ax: Axes, samples: Sequence[Sample], config: GatewayConfig) -> None:
    """Every driven wheel's reported speed over the log's time (a gap where it had none)."""
    t0 = samples[0].time_s
    shown = _thinned(samples)
    times = [s.time_s - t0 for s in shown]
    for i, name in enumerate(config.model.names):
        speeds = [math.nan if (v := s.wheel_rad_s[i]) is None else v for s in shown]
        if all(math.isnan(v) for v in speeds):
            continue  # a passive wheel
        ax.plot(times, speeds, lw=1.0, label=name)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("wheel speed (rad/s)")
    ax.grid(True, color="#E0E0E0", lw=0.5)
    ax.legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize="small")


def _draw_robot(ax: Axes, sample: Sample, wheels: Sequence[Wheel], outline: Sequence[Point],
                scale: float, labels: dict[str, str]) -> None:
    """One robot outline with a heading arrow, its wheels and their speed arrows; each legend
    label is used once (and removed from ``labels``)."""
    pose = sample.pose
    xs, ys = to_world(outline, pose)
    ax.plot(xs, ys, color=BODY_COLOUR, lw=2.0, label=labels.pop("robot", None), zorder=2,
            alpha=ROBOT_ALPHA)
    front = max(x for x, _ in outline)
    (x0, x1), (y0, y1) = to_world([(0.0, 0.0), (front, 0.0)], pose)
    head = 0.15 * front
    if head > 0:
        ax.arrow(x0, y0, x1 - x0, y1 - y0, color=BODY_COLOUR, width=0.0, lw=1.0,
                 head_width=head, head_length=head, length_includes_head=True, zorder=2)
    for wheel, speed, steer in zip(wheels, sample.wheel_rad_s, sample.steer_rad, strict=True):
        sigma = steer or 0.0
        wx, wy = to_world(wheel_box(wheel, sigma), pose)
        ax.plot(wx, wy, color=WHEEL_COLOUR, lw=2.0, label=labels.pop("wheel", None), zorder=3)
        if speed is None:
            continue
        start, (dx, dy) = speed_arrow(wheel, sigma, speed, scale)
        length = math.hypot(dx, dy)
        if length < 1e-9:
            continue
        (sx, tx), (sy, ty) = to_world([start, (start[0] + dx, start[1] + dy)], pose)
        tip = 0.4 * wheel.radius
        ax.arrow(sx, sy, tx - sx, ty - sy, color=SPEED_COLOUR, width=0.0, lw=2.0,
                 head_width=tip, head_length=min(tip, length), length_includes_head=True,
                 zorder=3, label=labels.pop("speed", None))


def save_figure(fig: Figure, path: str, dpi: int = 100) -> None:
    """Write the figure as a PNG (or the format the name's suffix says).

    :raises OSError: if the file cannot be written.
    """
    fig.savefig(path, dpi=dpi, bbox_inches="tight")
