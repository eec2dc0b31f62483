"""The trajectory plot (:mod:`gateway.apps.replay.plot`): its geometry, and the figure checked as
data and
as a picture."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import pytest

from gateway.apps.replay.plot import (
    BODY_COLOUR,
    PATH_COLOUR,
    SPEED_COLOUR,
    WHEEL_COLOUR,
    body_outline,
    mark_step,
    pick_poses,
    robot_size,
    speed_arrow,
    time_marks,
    to_world,
    wheel_box,
)
from gateway.apps.replay.replay import Sample
from gateway.config import load_config
from gateway.core.kinematics import PRESETS
from gateway.core.kinematics.odometry import Pose, compose, se2_exp
from gateway.core.types import Twist
from tests.conftest import CONFIG_DIR

if TYPE_CHECKING:
    from pathlib import Path

    from matplotlib.figure import Figure

    from gateway.core.settings import GatewayConfig


# ----------------------------------------------------------------- geometry


def test_outline_of_four_wheels_is_their_rectangle() -> None:
    wheels = PRESETS["mecanum"].wheels(wheel_radius=0.05, wheelbase=0.4, track=0.36)
    ring = body_outline(wheels)
    assert ring[0] == ring[-1]
    corners = sorted(set(ring))
    assert [c for xy in corners for c in xy] == pytest.approx(
        [-0.2, -0.18, -0.2, 0.18, 0.2, -0.18, 0.2, 0.18])


def test_outline_of_three_omni_wheels_is_a_triangle() -> None:
    wheels = PRESETS["omni"].wheels(wheel_radius=0.05, wheel_distance=0.2, wheel_count=3,
                                    first_wheel_angle=0.0)
    ring = body_outline(wheels)
    assert len(ring) == 4
    for x, y in ring:
        assert math.hypot(x, y) == pytest.approx(0.2)


def test_wheel_box_lies_along_the_rolling_direction() -> None:
    left = PRESETS["differential"].wheels(wheel_radius=0.1, track=0.4)[0]
    box = wheel_box(left)
    xs, ys = [p[0] for p in box], [p[1] for p in box]
    assert max(xs) - min(xs) == pytest.approx(0.2)      # two radii along x (forward)
    assert max(ys) - min(ys) == pytest.approx(0.06)     # 0.6 radii across
    assert sum(ys[:4]) / 4 == pytest.approx(left.y)
    steered = wheel_box(left, math.pi / 2)
    assert max(p[1] for p in steered) - min(p[1] for p in steered) == pytest.approx(0.2)


def test_speed_arrow_is_proportional_to_the_rim_speed() -> None:
    right = PRESETS["differential"].wheels(wheel_radius=0.1, track=0.4)[1]
    start, (dx, dy) = speed_arrow(right, 0.0, 5.0, 2.0)   # 0.5 m/s at the rim, 2 m per m/s
    assert start == pytest.approx((right.x, right.y))
    assert (dx, dy) == pytest.approx((1.0, 0.0), abs=1e-12)
    _, (bx, _) = speed_arrow(right, 0.0, -5.0, 2.0)
    assert bx == pytest.approx(-1.0)


def test_to_world_rotates_then_translates() -> None:
    xs, ys = to_world([(1.0, 0.0)], Pose(2.0, 3.0, math.pi / 2))
    assert (xs[0], ys[0]) == pytest.approx((2.0, 4.0))


def sample(t: float, pose: Pose, distance: float, speeds: tuple[float | None, ...],
           steer: tuple[float | None, ...] | None = None) -> Sample:
    return Sample(t, pose, Twist(), 0.0, distance, speeds,
                  steer if steer is not None else (None,) * len(speeds))


def test_pick_poses_spaces_robots_by_distance() -> None:
    # 10 samples standing still, then 10 m in 100 samples.
    samples = [sample(0.1 * k, Pose(), 0.0, (0.0,)) for k in range(10)]
    samples += [sample(1 + 0.1 * k, Pose(0.1 * k, 0, 0), 0.1 * k, (1.0,)) for k in range(1, 101)]
    picked = pick_poses(samples, 6)
    assert picked[0] == 0
    assert picked[-1] == len(samples) - 1
    assert [round(samples[i].distance_m, 6) for i in picked] == [0.0, 2.0, 4.0, 6.0, 8.0, 10.0]
    assert pick_poses(samples, 0) == []
    assert pick_poses([], 5) == []
    still = [sample(0.1 * k, Pose(), 0.0, (0.0,)) for k in range(10)]
    assert pick_poses(still, 5) == [0, 9]


# ----------------------------------------------------------------- the figure


def square_samples(config: GatewayConfig) -> list[Sample]:
    """A 2 m x 1 m rectangle driven with quarter turns, wheel speeds from the inverse
    kinematics."""
    model = config.model
    out: list[Sample] = []
    pose, dist, t = Pose(), 0.0, 0.0
    legs = [(Twist(0.5, 0, 0), 4.0), (Twist(0, 0, 1.0), math.pi / 2),
            (Twist(0.5, 0, 0), 2.0), (Twist(0, 0, 1.0), math.pi / 2)] * 2
    for twist, seconds in legs:
        speeds = model.ik(twist).wheel_rad_s
        steps = max(1, round(seconds / 0.05))
        dt = seconds / steps
        for _ in range(steps):
            pose = compose(pose, se2_exp(twist.vx_m_s * dt, twist.vy_m_s * dt,
                                         twist.wz_rad_s * dt))
            dist += abs(twist.vx_m_s) * dt
            t += dt
            out.append(sample(t, pose, dist, tuple(speeds)))
    return out


@pytest.fixture
def figure() -> tuple[Figure, list[Sample], GatewayConfig]:
    pytest.importorskip("matplotlib")
    from gateway.apps.replay.plot import plot_trajectory

    cfg = load_config(CONFIG_DIR / "mecanum.yaml")
    samples = square_samples(cfg)
    return plot_trajectory(samples, cfg, robots=6), samples, cfg


def test_figure_axes_enclose_the_path_with_equal_scales(
    figure: tuple[Figure, list[Sample], GatewayConfig],
) -> None:
    fig, samples, cfg = figure
    ax, _ = fig.axes  # the path, then the wheel speeds over time
    xs = [s.pose.x_m for s in samples]
    ys = [s.pose.y_m for s in samples]
    assert max(xs) == pytest.approx(2.0, abs=1e-6)
    assert max(ys) == pytest.approx(1.0, abs=1e-6)
    fig.canvas.draw()
    x0, x1 = ax.get_xlim()
    y0, y1 = ax.get_ylim()
    size = robot_size(cfg.model.wheels)
    assert x0 <= min(xs) - size < max(xs) + size <= x1
    assert y0 <= min(ys) - size < max(ys) + size <= y1
    assert ax.get_aspect() == 1.0
    # One metre is as many pixels along x as along y.
    (px0, py0), (px1, py1) = ax.transData.transform([(0.0, 0.0), (1.0, 1.0)])
    assert px1 - px0 == pytest.approx(py1 - py0, rel=1e-6)
    assert ax.get_xlabel() == "x (m)"
    assert ax.get_ylabel() == "y (m)"
    assert ax.get_title() == f"mecanum: {samples[-1].distance_m:.2f} m in " \
                             f"{samples[-1].time_s - samples[0].time_s:.1f} s"


def test_figure_uses_the_seed_colours(figure: tuple[Figure, list[Sample], GatewayConfig]) -> None:
    from matplotlib.colors import to_hex

    fig, samples, cfg = figure
    ax, _ = fig.axes  # the path, then the wheel speeds over time
    colours = [to_hex(line.get_color()).upper() for line in ax.get_lines()]
    assert colours.count(PATH_COLOUR) == 1
    robots = len(pick_poses(samples, 6))
    assert colours.count(BODY_COLOUR) == robots
    assert colours.count(WHEEL_COLOUR) == robots * cfg.model.n
    arrows = [p for p in ax.patches if to_hex(p.get_edgecolor()).upper() == SPEED_COLOUR]
    assert len(arrows) == robots * cfg.model.n   # every wheel turns at every drawn pose
    (path,) = [line for line in ax.get_lines()
               if to_hex(line.get_color()).upper() == PATH_COLOUR]
    assert path.get_linewidth() == 1.0
    labels = ax.get_legend_handles_labels()[1]
    assert labels[:3] == ["path", "robot", "wheel"]
    assert "start" in labels
    assert "end" in labels


def test_png_is_a_picture_of_the_path(figure: tuple[Figure, list[Sample], GatewayConfig],
                                      tmp_path: Path) -> None:
    import numpy as np
    from matplotlib.image import imread

    from gateway.apps.replay.plot import save_figure

    fig, _, _ = figure
    png = tmp_path / "p.png"
    save_figure(fig, str(png))
    img = imread(str(png))
    height, width = img.shape[:2]
    assert 600 <= height <= 1000
    assert 500 <= width <= 1200
    rgb = img[..., :3]
    inked = np.any(rgb < 0.9, axis=2).mean()
    assert 0.02 < inked < 0.6
    # The wheel red and the speed green are there.
    red = np.all(np.abs(rgb - np.array([0xA0, 0, 0]) / 255) < 0.08, axis=2).sum()
    green = np.all(np.abs(rgb - np.array([0, 0xA0, 0]) / 255) < 0.08, axis=2).sum()
    assert red > 200
    assert green > 200


def test_steered_wheels_are_drawn_at_their_angle() -> None:
    pytest.importorskip("matplotlib")
    import numpy as np
    from matplotlib.colors import to_hex

    from gateway.apps.replay.plot import plot_trajectory

    cfg = load_config(CONFIG_DIR / "tricycle.yaml")
    steer = tuple(math.pi / 2 if w.steered else None for w in cfg.model.wheels)
    samples = [sample(0.0, Pose(), 0.0, (None, None, 1.0), steer),
               sample(1.0, Pose(), 0.0, (None, None, 1.0), steer)]
    fig = plot_trajectory(samples, cfg, robots=1)
    ax, _ = fig.axes  # the path, then the wheel speeds over time
    front = cfg.model.wheels[cfg.model.index("front")]
    boxes = [line for line in ax.get_lines() if to_hex(line.get_color()).upper() == WHEEL_COLOUR]
    spans = []
    for box in boxes:
        xs = np.asarray(box.get_xdata(), dtype=float)
        ys = np.asarray(box.get_ydata(), dtype=float)
        spans.append((float(xs.max() - xs.min()), float(ys.max() - ys.min())))
    # The steered front wheel turned a quarter: across x, along y.
    assert any(math.isclose(dx, 0.6 * front.radius) and math.isclose(dy, 2 * front.radius)
               for dx, dy in spans), spans


def test_nothing_to_plot_is_an_error() -> None:
    pytest.importorskip("matplotlib")
    from gateway.apps.replay.plot import plot_trajectory

    with pytest.raises(ValueError, match="at least one odometry sample"):
        plot_trajectory([], load_config(CONFIG_DIR / "mecanum.yaml"))


def test_the_path_is_drawn_over_the_robots_with_time_marks(
    figure: tuple[Figure, list[Sample], GatewayConfig],
) -> None:
    from matplotlib.colors import to_hex
    from matplotlib.text import Annotation

    fig, samples, _ = figure
    ax, _ = fig.axes
    lines = ax.get_lines()
    (path,) = [line for line in lines if to_hex(line.get_color()).upper() == PATH_COLOUR]
    others = [line for line in lines if to_hex(line.get_color()).upper()
              in (BODY_COLOUR, WHEEL_COLOUR)]
    assert all(path.get_zorder() > line.get_zorder() for line in others)
    assert all((line.get_alpha() or 1.0) < 1.0 for line in others
               if to_hex(line.get_color()).upper() == BODY_COLOUR)
    # The square takes 2 x (4 + 2 + pi) = 18.3 s: a mark every 2 s, labelled, on the path.
    marks = [t.get_text() for t in ax.texts]
    assert marks == [f"{k} s" for k in range(2, 19, 2)], marks
    for text, (index, seconds) in zip(ax.texts, time_marks(samples), strict=True):
        assert isinstance(text, Annotation)
        assert text.xy == (samples[index].pose.x_m, samples[index].pose.y_m)
        assert samples[index].time_s - samples[0].time_s >= seconds - 1e-9


def test_the_second_panel_shows_every_wheel_speed_over_time(
    figure: tuple[Figure, list[Sample], GatewayConfig],
) -> None:
    fig, samples, cfg = figure
    _, speeds = fig.axes
    assert speeds.get_xlabel() == "time (s)"
    assert speeds.get_ylabel() == "wheel speed (rad/s)"
    assert [line.get_label() for line in speeds.get_lines()] == list(cfg.model.names)
    for i, line in enumerate(speeds.get_lines()):
        xs, ys = line.get_xydata().T  # type: ignore[union-attr]
        assert list(xs) == pytest.approx([s.time_s - samples[0].time_s for s in samples])
        assert list(ys) == pytest.approx([s.wheel_rad_s[i] for s in samples])


def test_time_marks_fall_at_round_steps() -> None:
    samples = [sample(100.0 + 0.3 * k, Pose(), 0.0, (0.0,)) for k in range(34)]  # 9.9 s
    assert mark_step(9.9) == 1.0
    assert [t for _, t in time_marks(samples)] == [float(k) for k in range(1, 10)]
    assert all(samples[i].time_s - 100.0 >= t - 1e-9 for i, t in time_marks(samples))
    assert time_marks([]) == []


def test_a_robot_standing_still_gets_one_time_mark() -> None:
    pytest.importorskip("matplotlib")
    from gateway.apps.replay.plot import plot_trajectory

    cfg = load_config(CONFIG_DIR / "mecanum.yaml")
    still = [sample(0.1 * k, Pose(), 0.0, (0.0,) * 4) for k in range(50)]  # 5 s at rest
    moving = [sample(5.0 + 0.1 * k, Pose(0.05 * k, 0.0, 0.0), 0.05 * k, (1.0,) * 4)
              for k in range(1, 51)]  # then 2.5 m in 5 s
    fig = plot_trajectory(still + moving, cfg)
    ax, _ = fig.axes
    labels = [t.get_text() for t in ax.texts]
    assert labels[0] == "1 s" and not {"2 s", "3 s", "4 s"} & set(labels), labels
    assert {"6 s", "7 s", "8 s", "9 s"} <= set(labels), labels
