"""The runs of ``wheelgate calibrate``: recorded logs with the end pose measured on the floor,
and the odometry's end pose for any calibration factors.

A run is a candump log of the robot driving from a marked start (``wheelgate run --record``),
read once through the drivers as ``wheelgate odom`` reads it
(:class:`~gateway.apps.replay.replay.Replay`), keeping what every odometry update took: the
wheels' positions and the steering angles.  For candidate factors the same updates are
integrated again on the geometry the factors make: every driven wheel's radius times its
factor (``kinematics.wheel_radius_multipliers``) and, on a preset drive with a track, the
track times the separation factor (``kinematics.wheel_separation_multiplier``), exactly as
the configuration loader applies them.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import TYPE_CHECKING

from gateway.apps.replay.replay import Replay, Update
from gateway.config.wheels import preset_wheels
from gateway.core.errors import ConfigError, KinematicsError
from gateway.core.kinematics import RobotModel, wrap_angle
from gateway.core.kinematics.odometry import Odometry, Pose
from gateway.core.steer_log import SteeringSource, fixed_subset

if TYPE_CHECKING:
    from collections.abc import Iterable, Sequence

    from gateway.core.settings import GatewayConfig

__all__ = ["Factors", "Run", "end_poses", "factors_of", "own_radii", "read_run", "residual"]


@dataclass(frozen=True, slots=True)
class Run:
    """One recorded run.

    :param name: the log's name, for messages.
    :param measured: where the robot ended, in its start pose's frame (x forward, y left).
    :param updates: what every odometry update of the replay took.
    """

    name: str
    measured: Pose
    updates: tuple[Update, ...]


@dataclass(frozen=True, slots=True)
class Factors:
    """What the fit may change.

    :param wheels: the driven wheels, by name, whose radius factor is fitted.
    :param separation: whether the track's factor is fitted (a preset drive with a track).
    """

    wheels: tuple[str, ...]
    separation: bool

    @property
    def names(self) -> tuple[str, ...]:
        """The factors as configuration keys, in fit order."""
        return (*(f"wheel_radius_multipliers.{w}" for w in self.wheels),
                *(("wheel_separation_multiplier",) if self.separation else ()))

    @property
    def labels(self) -> tuple[str, ...]:
        """The factors in a word each (the wheel, ``separation``), in fit order."""
        return (*self.wheels, *(("separation",) if self.separation else ()))

    def configured(self, config: GatewayConfig) -> tuple[float, ...]:
        """The configuration's own factors, in fit order (1.0 where it states none)."""
        radii = own_radii(config)
        return (*(radii.get(w, 1.0) for w in self.wheels),
                *((config.calibration.get("wheel_separation_multiplier", 1.0),)
                  if self.separation else ()))


def own_radii(config: GatewayConfig) -> dict[str, float]:
    """The configuration's ``wheel_radius_multipliers``, by wheel, in model order."""
    return {w.name: config.calibration[f"radius {w.name}"] for w in config.model.wheels
            if f"radius {w.name}" in config.calibration}


def factors_of(config: GatewayConfig) -> Factors:
    """The factors a configuration can take: every driven wheel's radius, and the track's on
    a preset drive that has one."""
    wheels = tuple(w.name for w, m in zip(config.model.wheels, config.motors, strict=True)
                   if m is not None)
    return Factors(wheels, config.drive != "generic" and "track" in config.geometry)


def read_run(config: GatewayConfig, name: str, lines: Iterable[str], measured: Pose) -> Run:
    """Replay a log's lines and keep its odometry updates.

    :param name: the log's name, for messages.
    :raises ConfigError: for a log that gives no odometry, or a robot whose steered wheels'
        angles the log does not hold (the fit needs the angles the odometry used).
    """
    replay = Replay(config)
    if replay.steering not in (SteeringSource.NONE, SteeringSource.ACTUATORS,
                               SteeringSource.FIXED_WHEELS):
        raise ConfigError(f"{name}: expected a robot whose steering angles a log holds (its "
                          f"steering actuators') or that needs none, got steered wheels that "
                          f"no actuator of the configuration turns")
    replay.kept = []
    for _ in replay.feed_lines(lines):
        pass
    if not replay.kept:
        raise ConfigError(f"{name}: expected a log with the feedback of the configuration's "
                          f"motors (`wheelgate run --record`), got no odometry update from it")
    return Run(name, measured, tuple(replay.kept))


def _model(config: GatewayConfig, factors: Factors, values: Sequence[float]) -> RobotModel:
    """The geometry ``values`` make (on top of the configuration's own multipliers)."""
    wheels = list(config.model.wheels)
    if factors.separation:
        separation = config.calibration.get("wheel_separation_multiplier", 1.0) * values[-1]
        _, built = preset_wheels(config.drive, dict(config.geometry), config.source, separation)
        wheels = [dataclasses.replace(b, radius=w.radius, max_steer_rate=w.max_steer_rate)
                  for b, w in zip(built, wheels, strict=True)]
    scale = dict(zip(factors.wheels, values, strict=False))
    wheels = [dataclasses.replace(w, radius=w.radius * scale.get(w.name, 1.0)) for w in wheels]
    return RobotModel(wheels, config.model.slip_tolerance_m_s)


def end_poses(config: GatewayConfig, factors: Factors, values: Sequence[float],
              runs: Sequence[Run]) -> list[Pose]:
    """Where the odometry ends each run on the geometry ``values`` make."""
    model = _model(config, factors, values)
    subset = fixed_subset(dataclasses.replace(config, model=model))
    out = []
    for run in runs:
        odometry = Odometry(model if subset is None else subset[1])
        for positions, stamp, steer in run.updates:
            try:
                if subset is None:
                    odometry.take(positions, stamp, steer)
                else:
                    odometry.take([positions[i] for i in subset[0]], stamp)
            except KinematicsError:
                continue  # (skipped by the replay too)
        out.append(odometry.state.pose)
    return out


def residual(config: GatewayConfig, factors: Factors, values: Sequence[float],
             runs: Sequence[Run]) -> list[float]:
    """Per run, the odometry's end minus the measured end: x, y (m) and the heading times the
    robot's size (``RobotModel.rho``, m), as the model weighs yaw against speed."""
    out = []
    for pose, run in zip(end_poses(config, factors, values, runs), runs, strict=True):
        out += [pose.x_m - run.measured.x_m, pose.y_m - run.measured.y_m,
                config.model.rho * wrap_angle(pose.theta_rad - run.measured.theta_rad)]
    return out
