"""Shared builders of the DJI C620 / C610 tests (test_drivers_dji_*, test_steering_dji_*): motors,
the currents in command frames, and a rig of driver and simulators on a virtual bus."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import can

from drivers.dji import (
    M2006_GEAR_RATIO,
    M3508_GEAR_RATIO,
    DjiDriver,
)
from drivers.dji.codec import (
    decode_command,
)
from gateway.bus.can_bus import drain, send_frames
from gateway.sim.bus import SimulatedControllers
from tests import factories

if TYPE_CHECKING:
    from collections.abc import Callable, Sequence

    from drivers.dji.sim import DjiSimulator
    from gateway.core.types import Frame, MotorConfig

TWO_PI = 2.0 * math.pi


def motor(
    node_id: int = 1,
    esc: str = "c620",
    gear: float | None = None,
    invert: bool = False,
    *,
    validate: bool = True,
    **options: object,
) -> MotorConfig:
    """A DJI motor block of the factory (:func:`tests.factories.motor`): wheel ``w<node>``, the
    gearbox of the ESC's motor unless ``gear`` is given, no controller stop acknowledged."""
    ratio = gear if gear is not None else (M3508_GEAR_RATIO if esc == "c620" else M2006_GEAR_RATIO)
    return factories.motor(
        "dji", node_id, f"w{node_id}", gear_ratio=ratio, invert=invert, max_rpm=20000.0,
        validate=validate, options={"esc": esc, "no_controller_stop": "acknowledged", **options},
    )


def currents_in(frames: Sequence[Frame]) -> dict[int, int]:
    out: dict[int, int] = {}
    for f in frames:
        decoded = decode_command(f)
        assert decoded is not None
        out.update(decoded)
    return out


# ===================================================================== on the virtual bus


class Rig:
    """Driver + simulators on a virtual bus; simulators at 1 kHz, the driver every
    ``period_ms``."""

    def __init__(self, drv: DjiDriver, gw: can.BusABC, ctl: SimulatedControllers) -> None:
        self.drv, self.gw, self.ctl, self.ms = drv, gw, ctl, 0

    @property
    def t(self) -> float:
        return self.ms * 0.001

    def run(
        self,
        seconds: float,
        setpoints: Sequence[float],
        period_ms: int = 1,
        probe: DjiSimulator | None = None,
    ) -> list[float]:
        """Run; return ``probe.steer_rad`` every ms (nothing without a probe)."""
        trace = []
        for _ in range(round(seconds * 1000)):
            self.ms += 1
            self.ctl.step(self.t)
            for f in drain(self.gw):
                self.drv.on_frame(f.stamped(self.t))
            if self.ms % period_ms == 0:
                send_frames(self.gw, self.drv.poll(self.t) + self.drv.command(setpoints, self.t))
            if probe is not None:
                trace.append(probe.steer_rad)
        return trace


def _rig(
    channel: str, motors: list[MotorConfig], sims: list[DjiSimulator], test: Callable[[Rig], None]
) -> None:
    drv = DjiDriver(motors)
    gw = can.Bus(interface="virtual", channel=channel)
    try:
        with SimulatedControllers(sims, channel) as ctl:
            test(Rig(drv, gw, ctl))
    finally:
        gw.shutdown()
    assert all(s.id_set_requests == 0 for s in sims)
