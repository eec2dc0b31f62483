"""The CiA 402 driver and its simulated drives on a python-can virtual bus, for the tests of
``test_*cia402*.py``: a :class:`Bench` steps simulated time, passes what the drives send to the
driver and sends what the driver returns; :func:`rolling_tricycle` is a whole gateway on a
CiA 402 robot."""

from __future__ import annotations

import contextlib
import dataclasses
import math
from typing import TYPE_CHECKING

import can

from drivers.cia402 import Cia402Driver
from drivers.cia402.sim import Cia402Simulator
from gateway.bus.can_bus import drain, send_frames
from gateway.core.types import DriveState, Frame, MotorConfig, Twist
from gateway.sim.bus import SimulatedControllers
from tests import factories
from tests.conftest import CONFIG_DIR
from tests.e2e_helpers import Rig, virtual_config

if TYPE_CHECKING:
    from collections.abc import Callable, Iterator, Sequence

#: The loop period of a bench (s).
DT = 0.001
TWO_PI = 2.0 * math.pi
LEFT = factories.motor("cia402", 3, "left", gear_ratio=10.0)
RIGHT = factories.motor("cia402", 5, "right", gear_ratio=10.0, invert=True)
#: One position count at the wheel of LEFT or RIGHT (rad).
COUNT_RAD = TWO_PI / 4096 / 10.0


def hexb(text: str) -> bytes:
    return bytes.fromhex(text)


def left(*, validate: bool = True, **options: object) -> MotorConfig:
    """LEFT with these protocol keys (:func:`tests.factories.motor`)."""
    return factories.motor("cia402", 3, "left", gear_ratio=10.0, validate=validate,
                           options=options)


@dataclasses.dataclass
class Bench:
    drv: Cia402Driver
    sims: Sequence[Cia402Simulator]
    gw: can.BusABC
    ctl: SimulatedControllers
    t: float = 0.0
    seen: list[Frame] = dataclasses.field(default_factory=list)
    sent: list[Frame] = dataclasses.field(default_factory=list)

    def send(self, frames: Sequence[Frame]) -> None:
        send_frames(self.gw, frames)
        self.sent += frames

    def run(self, seconds: float, speeds: Sequence[float] | None = None,
            until: Callable[[], bool] | None = None) -> bool:
        """Step simulated time; ``speeds`` None means the loop does not call command()."""
        for _ in range(round(seconds / DT)):
            self.t += DT
            self.ctl.step(self.t)
            for raw in drain(self.gw):
                f = raw.stamped(self.t)
                self.seen.append(f)
                self.drv.on_frame(f)
            out = self.drv.poll(self.t)
            if speeds is not None:
                out += self.drv.command(speeds, self.t)
            self.send(out)
            if until is not None and until():
                return True
        return until is None

    def state(self, i: int = 0) -> DriveState:
        return self.drv.state(i, self.t)

    def enable(self, speeds: Sequence[float] | None = None, seconds: float = 0.5) -> bool:
        self.send(self.drv.enable(self.t))
        return self.run(seconds, speeds, until=lambda: all(
            self.state(i) is DriveState.ENABLED for i in range(len(self.sims))))


@contextlib.contextmanager
def benches(channel: str) -> Iterator[Callable[..., Bench]]:
    """A maker of benches on ``channel``, shutting every bench down at the end."""
    made: list[Bench] = []

    def make(motors: Sequence[MotorConfig], sim_class: type[Cia402Simulator] = Cia402Simulator,
             **sim_kwargs: object) -> Bench:
        drv = Cia402Driver(motors)
        sims = [sim_class(m, **sim_kwargs) for m in motors]  # type: ignore[arg-type]
        ctl = SimulatedControllers(sims, channel)
        try:
            gw = can.Bus(interface="virtual", channel=channel)
        except Exception:
            ctl.shutdown()
            raise
        made.append(Bench(drv, sims, gw, ctl))
        return made[-1]

    try:
        yield make
    finally:
        for b in made:
            b.gw.shutdown()
            b.ctl.shutdown()


@contextlib.contextmanager
def rolling_tricycle(name: str, vx_m_s: float) -> Iterator[tuple[Rig, Cia402Driver, int]]:
    """The tricycle (a CiA 402 drive motor and steering actuator) on its simulators, on a
    virtual channel named after ``name``, enabled and driven at ``vx_m_s`` for 0.3 s by CAN
    twists: the rig, its CiA 402 driver and the drive motor's index in it."""
    with Rig(virtual_config(CONFIG_DIR / "tricycle.yaml", name)) as rig:
        rig.enable()
        for _ in range(6):
            rig.send_can_twist(Twist(vx_m_s))
            rig.advance(0.05)
        drv = next(d for d, _ in rig.gw.drives.groups if isinstance(d, Cia402Driver))
        yield rig, drv, next(k for k, m in enumerate(drv.motors) if not m.steering)
