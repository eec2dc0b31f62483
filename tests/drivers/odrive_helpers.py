"""Shared helpers of the ODrive CANSimple tests (test_odrive_*): the firmware
versions and their codecs, motors, hex frames, and a rig of simulators on a virtual bus with
the watchdog's endpoints."""

from __future__ import annotations

import contextlib
import math
from typing import TYPE_CHECKING

import can

from drivers.odrive import OdriveDriver
from drivers.odrive.codec import OdriveCodec
from drivers.odrive.enums import (
    Firmware,
)
from gateway.bus.can_bus import drain, send_frames
from gateway.sim.bus import SimulatedControllers
from tests import factories

if TYPE_CHECKING:
    from collections.abc import Iterator, Sequence

    from drivers.odrive.sim import OdriveSimulator
    from gateway.core.types import DriveState, Frame, MotorConfig
TAU = 2.0 * math.pi
V05, V06 = Firmware.V0_5, Firmware.V0_6


def hx(text: str) -> bytes:
    return bytes.fromhex(text.replace(" ", ""))


def motor(
    node: int = 3,
    wheel: str = "left",
    *,
    gear_ratio: float = 1.0,
    invert: bool = False,
    max_rpm: float = 3000.0,
    validate: bool = True,
    **options: object,
) -> MotorConfig:
    """An ODrive motor block of the factory (:func:`tests.factories.motor`)."""
    return factories.motor("odrive", node, wheel, gear_ratio=gear_ratio, invert=invert,
                           max_rpm=max_rpm, validate=validate, options=options)


C5, C6 = OdriveCodec(V05), OdriveCodec(V06)


# ----------------------------------------------------------------------------- virtual bus


class Rig:
    """Driver + simulators on a virtual bus, stepped at 1 kHz of simulated time."""

    def __init__(self, gw: can.BusABC, ctl: SimulatedControllers, drv: OdriveDriver) -> None:
        self.gw, self.ctl, self.drv, self.t = gw, ctl, drv, 0.0
        self.speeds = [0.0] * len(drv.motors)

    def send(self, frames: Sequence[Frame]) -> None:
        send_frames(self.gw, frames)

    def run(self, seconds: float, talk: bool = True, cmd_period_steps: int = 10) -> None:
        for k in range(round(seconds * 1000)):
            self.t = round(self.t + 0.001, 6)
            self.ctl.step(self.t)
            for f in drain(self.gw):
                self.drv.on_frame(f.stamped(self.t))
            if talk and k % cmd_period_steps == 0:
                self.send(self.drv.poll(self.t) + self.drv.command(self.speeds, self.t))

    def state(self, i: int = 0) -> DriveState:
        return self.drv.state(i, self.t)


@contextlib.contextmanager
def rig(channel: str, sims: Sequence[OdriveSimulator]) -> Iterator[Rig]:
    drv = OdriveDriver([s.motor for s in sims])
    gw = can.Bus(interface="virtual", channel=channel)
    try:
        with SimulatedControllers(sims, channel) as ctl:
            yield Rig(gw, ctl, drv)
    finally:
        gw.shutdown()


#: The watchdog's endpoint IDs the 0.6 tests name (the simulator's; real ones come from the
#: firmware's flat_endpoints.json).
ENDPOINTS = {"fw_version": "0.6.10", "enable_watchdog": 201, "watchdog_timeout": 200}
