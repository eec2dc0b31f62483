"""Recorded sessions for the ``wheelgate odom`` and replay tests (test_odom_*).

The logs are recorded by the gateway itself (``Gateway(record=...)``, as ``wheelgate run
--record`` does) driving simulated controllers on simulated time, with the simulators' exact
wheel angles as the ground truth.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import can
import pytest

from drivers.odrive.codec import OdriveCodec
from gateway.apps.replay.replay import Replay
from gateway.core.control import Source
from gateway.core.types import Twist
from tests.conftest import CONFIG_DIR
from tests.e2e_helpers import Rig, path_legs, virtual_config

if TYPE_CHECKING:
    from collections.abc import Callable
    from pathlib import Path

    from gateway.core.kinematics.odometry import OdometryState
    from gateway.core.settings import GatewayConfig

OBJ = {"interface": None, "channel": None, "debug": False}
DIFF = CONFIG_DIR / "turtlebot3_burger.yaml"


# ----------------------------------------------------------------- recorded sessions


class SimClockLog(can.Listener):
    """A candump writer that stamps frames with the rig's simulated time (the gateway stamps
    them with ``time.time()``, which would make the test depend on the wall clock)."""

    def __init__(self, path: Path, clock: Callable[[], float]) -> None:
        self.writer = can.CanutilsLogWriter(str(path))
        self.clock = clock

    def on_message_received(self, msg: can.Message) -> None:
        msg.timestamp = self.clock()
        self.writer.on_message_received(msg)

    def stop(self) -> None:
        self.writer.stop()


@dataclass(frozen=True)
class Session:
    config: GatewayConfig
    log: Path
    gateway: OdometryState
    truth: OdometryState


def short_legs(config: GatewayConfig) -> list[tuple[Twist, float]]:
    """A straight metre, a quarter turn of radius 1.5 m, another metre (car-like robots)."""
    v = 0.4
    return [(Twist(v, 0.0, 0.0), 2.5), (Twist(v, 0.0, v / 1.5), math.pi / 2 * 1.5 / v),
            (Twist(v, 0.0, 0.0), 2.5)]


def record(name: str, folder: Path) -> Session:
    """Drive a session of ``config/<name>.yaml`` and keep its log and odometry; a name ending
    in ``_external`` drives that robot without its steering actuators (steered outside the
    gateway, so the log holds no angles)."""
    base = name.removesuffix("_external")
    source = None if base == "default" else CONFIG_DIR / f"{base}.yaml"  # the embedded demo
    cfg = virtual_config(source, f"wg-odom-{name}", rate_hz=100.0)
    if base != name:
        cfg = dataclasses.replace(cfg, steering=())
    legs = short_legs(cfg) if base == "ackermann" else path_legs(cfg, "square")
    return drive(cfg, legs, folder / f"{name}.log")


def drive(cfg: GatewayConfig, legs: list[tuple[Twist, float]], path: Path) -> Session:
    """Drive ``legs`` (twist, seconds) on simulated controllers, recording the log at
    ``path``, then a second at rest."""
    with Rig(cfg) as rig:
        log = SimClockLog(path, lambda: rig.t)
        rig.gw.edge.record = log
        try:
            rig.enable()
            for twist, seconds in legs:
                rig.advance(seconds, lambda r, t=twist: r.gw.twist(t, r.t, Source.SOCKET))  # type: ignore[misc]
            rig.advance(1.0)
        finally:
            log.stop()
        return Session(cfg, path, rig.gw.odometry.state, rig.truth.state)


@pytest.fixture(scope="module")
def sessions(tmp_path_factory: pytest.TempPathFactory) -> Callable[[str], Session]:
    """Sessions by config name, recorded once per module."""
    folder = tmp_path_factory.mktemp("odom")
    cache: dict[str, Session] = {}

    def get(name: str) -> Session:
        if name not in cache:
            cache[name] = record(name, folder)
        return cache[name]

    return get


def replay_file(config: GatewayConfig, path: Path, **kw: float) -> Replay:
    replay = Replay(config, **kw)
    with open(path, encoding="ascii") as f:
        for _ in replay.feed_lines(f):
            pass
    return replay


def line(t: float, node: int, turns: float, direction: str = "R") -> str:
    """A Get_Encoder_Estimates line of an ODrive axis (turtlebot3: nodes 1 and 2, gear 1)."""
    f = OdriveCodec.from_options({}).make_encoder_estimates(node, turns, 0.0)
    return f"({t:.6f}) can0 {f.arbitration_id:03X}#{f.data.hex().upper()} {direction}\n"
