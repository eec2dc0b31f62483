"""Shared helpers of the monitor's tests (test_monitor_*, tests/cli/test_monitor_cli.py): the
default configuration, a simulated session, and the bits of a standard frame."""

from __future__ import annotations

from typing import TYPE_CHECKING

from gateway.config import load_config
from gateway.drive.driveset import DriveSet
from gateway.sim.registry import simulators_for
from tests.conftest import CONFIG_DIR

if TYPE_CHECKING:
    from collections.abc import Sequence

    from gateway.core.settings import GatewayConfig
    from gateway.core.types import Frame

#: Bits of one 8-byte standard frame: nominal and with worst-case stuffing (by hand:
#: 34 + 64 + 13 = 111; plus floor((34 + 64 - 1) / 4) = 24 stuff bits).
STD8_NOMINAL, STD8_WORST = 111, 135


def default_config() -> GatewayConfig:
    """The embedded demo robot: mecanum on four ODrives (gear 10, right side inverted)."""
    return load_config(None, {})


class Session:
    """A gateway's drivers and the simulated controllers talking on simulated time, without a
    bus: what a recorded log of a real session holds.

    :param config: the robot.
    :param step_s: simulator and command step.
    """

    def __init__(self, config: GatewayConfig, step_s: float = 0.005) -> None:
        self.host = DriveSet(config)
        self.sims = simulators_for(self.host.all_motors())
        self.step_s = step_s
        self.t = 0.0
        self._tx = self.host.enable(0.0)

    def run(self, seconds: float, speeds: Sequence[float]) -> list[tuple[float, Frame, str]]:
        """``seconds`` more of the session with these wheel speeds (model order, rad/s).

        :return: (time, frame, ``"tx"`` from the gateway or ``"rx"`` to it) in bus order.
        """
        out: list[tuple[float, Frame, str]] = []
        for _ in range(round(seconds / self.step_s)):
            t = self.t
            rx = [f for frame in self._tx for sim in self.sims for f in sim.handle(frame, t)]
            rx += [f for sim in self.sims for f in sim.tick(t)]
            out += [(t, f, "tx") for f in self._tx] + [(t, f, "rx") for f in rx]
            for f in rx:
                self.host.on_frame(f.stamped(t))
            self.t = round(t + self.step_s, 9)
            self._tx = self.host.poll(self.t) + self.host.command(
                speeds, self.t, self.host.config.model.neutral_steer
            )
        return out


def config_at(name: str) -> GatewayConfig:
    return load_config(CONFIG_DIR / name, {})
