"""Helpers of the ``wheelgate spin`` tests: a robot's configuration with a motor block changed
(the configuration under test), the real shaft (simulated controllers from the *true*
configuration, on the same virtual bus), and an operator who answers spin's question from what
that shaft really did, when spin asks it."""

from __future__ import annotations

import io
import math
import threading
import time
from typing import TYPE_CHECKING, Any

import can
import yaml

from gateway.config import load_config
from gateway.sim.bus import SimulatedControllers
from gateway.sim.registry import simulator_for
from tests.conftest import CONFIG_DIR

if TYPE_CHECKING:
    from collections.abc import Callable
    from pathlib import Path

    from gateway.core.types import Frame
    from gateway.sim.device import DeviceSimulator


def robot_config(dest: Path, channel: str, base: str = "turtlebot3_burger.yaml",
                 motors: dict[str, dict[str, Any]] | None = None,
                 steering: dict[str, dict[str, Any]] | None = None,
                 gateway: dict[str, Any] | None = None, name: str = "",
                 geometry: dict[str, Any] | None = None) -> Path:
    """A shipped robot on the virtual bus ``channel``, with keys of its motor, steering and
    geometry blocks replaced, a control socket nobody listens on (unless ``gateway`` names
    one), written to ``dest`` (under another ``name`` when given)."""
    raw: dict[str, Any] = yaml.safe_load((CONFIG_DIR / base).read_text())
    raw["name"] = name or raw["name"]
    if geometry:
        raw.setdefault("geometry", {}).update(geometry)
    raw["bus"] = {"interface": "virtual", "channel": channel}
    raw.setdefault("gateway", {}).update({"socket": str(dest.parent / "nobody.sock"),
                                          **(gateway or {})})
    for wheel, keys in (motors or {}).items():
        raw["motors"][wheel].update(keys)
    for block, keys in (steering or {}).items():
        raw["steering"][block].update(keys)
    for block in (raw.get("motor_defaults"), *(raw.get("motors") or {}).values()):
        if isinstance(block, dict) and isinstance(block.get("dbc"), str):
            block["dbc"] = str((CONFIG_DIR / block["dbc"]).resolve())
    dest.write_text(yaml.safe_dump(raw, sort_keys=False))
    return dest


class Shaft:
    """The motor's real controller: its simulator from the true configuration on ``channel``,
    stepped in a thread; it keeps how far the output shaft turned (a wheel's angle, or a
    steering actuator's largest offset) since it started.

    :param config: the true configuration.
    :param name: the motor's name in it.
    """

    def __init__(self, config: Path, name: str) -> None:
        cfg = load_config(config)
        motor = next(m for m in (*cfg.motors, *cfg.steering) if m is not None and m.wheel == name)
        self.sim: DeviceSimulator = simulator_for(motor)
        self.start_rad = self.position()
        self.peak_rad = 0.0
        self.ctl = SimulatedControllers([self.sim], cfg.bus.channel)
        self.ctl.on_step = self._track
        self.ctl.start()

    def position(self) -> float:
        return self.sim.steer_rad if self.sim.motor.steering else self.sim.wheel_position_rad

    def _track(self, now_s: float) -> None:
        offset = self.position() - self.start_rad
        if abs(offset) > abs(self.peak_rad):
            self.peak_rad = offset

    def turned(self) -> float:
        """A wheel's turn (rad), or a steering actuator's largest offset (rad), so far."""
        return float(self.ctl.snapshot(lambda: self.peak_rad if self.sim.motor.steering
                                       else self.position() - self.start_rad))

    def answer(self) -> str:
        """What an operator who watched the shaft answers: the turns (degrees of a sweep) it
        made, in the positive direction spin describes for a positive command."""
        turned = self.turned()
        if self.sim.motor.steering:
            return f"{math.degrees(turned):.2f}"
        return f"{turned / math.tau:.4f}"

    def close(self) -> None:
        self.ctl.shutdown()

    def __enter__(self) -> Shaft:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class Operator(io.RawIOBase):
    """Standard input whose line is written only when it is first read (when spin asks its
    question, after the spin): ``answer()`` then."""

    def __init__(self, answer: Callable[[], str]) -> None:
        super().__init__()
        self._answer = answer
        self._data: bytes | None = None
        #: Whether the question was read (asked).
        self.asked = threading.Event()

    def readable(self) -> bool:
        return True

    def readinto(self, buffer: Any) -> int:
        if len(buffer) == 0:
            return 0
        if self._data is None:
            self._data = (self._answer() + "\n").encode()
            self.asked.set()
        n = min(len(buffer), len(self._data))
        buffer[:n] = self._data[:n]
        self._data = self._data[n:]
        return n


class Listener:
    """Every frame on a virtual channel while it is open (python-can's virtual bus delivers
    to every other connection of the channel)."""

    def __init__(self, channel: str) -> None:
        self.bus = can.Bus(interface="virtual", channel=channel)

    def frames(self) -> list[Frame]:
        from gateway.bus.can_bus import drain

        return drain(self.bus)

    def close(self) -> None:
        self.bus.shutdown()

    def __enter__(self) -> Listener:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


#: ODrive CANSimple of node 1: Set_Input_Vel (0x0D), Set_Axis_State (0x07) IDLE (1).
SET_INPUT_VEL = 1 << 5 | 0x0D
SET_AXIS_STATE = 1 << 5 | 0x07
IDLE = bytes([1, 0, 0, 0])


def when_turning(shaft: Shaft, act: Callable[[], object], after_rad: float = 0.0) -> None:
    """Call ``act`` once, from the simulator's thread, as soon as the wheel turns (and has
    turned ``after_rad``)."""
    done: list[float] = []

    def step(now_s: float) -> None:
        shaft._track(now_s)
        if (not done and shaft.sim.model.armed and shaft.sim.model.velocity_rad_s > 0.05
                and shaft.position() - shaft.start_rad >= after_rad):  # (on its thread)
            done.append(now_s)
            act()

    shaft.ctl.on_step = step


def assert_stopped(shaft: Shaft, sent: list[Frame]) -> None:
    """The stop reached the bus after the last command, and the simulated wheel is disarmed
    and standing."""
    commands = [k for k, f in enumerate(sent) if f.arbitration_id == SET_INPUT_VEL]
    stops = [k for k, f in enumerate(sent)
             if f.arbitration_id == SET_AXIS_STATE and f.data[:4] == IDLE]
    assert commands and stops and stops[-1] > commands[-1], [f.to_cansend() for f in sent]
    deadline = time.monotonic() + 2.0
    while shaft.sim.model.armed or abs(shaft.sim.model.velocity_rad_s) > 1e-3:
        assert time.monotonic() < deadline, "the simulated wheel was not stopped"
        time.sleep(0.01)
