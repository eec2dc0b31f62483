"""The throughput benchmark's rig: the robot per protocol, its feedback pool, the timed loops.

The method is described in :mod:`bench_throughput` (and printed by it), which runs this rig and
prints the table; :mod:`throughput_instructions` runs it under callgrind.
"""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

import can
import yaml

from gateway.bus.can_bus import drain, open_bus, send_frames
from gateway.config import parse_config
from gateway.core.control import Source
from gateway.core.types import GatewayState, Twist
from gateway.runtime.loop import Gateway
from gateway.sim.registry import simulators_for

if TYPE_CHECKING:
    import cProfile
    from collections.abc import Callable

    from gateway.core.settings import GatewayConfig
    from gateway.core.types import Frame
    from gateway.sim.device import DeviceSimulator

ROOT = Path(__file__).resolve().parent.parent
PERIOD_S = 0.001
#: Frames per 1 ms cycle on a saturated 1 Mbit/s bus (8-byte standard frames).
SATURATED_PER_CYCLE = 9
TWIST = Twist(0.3, 0.1, 0.2)

#: Motor blocks per protocol, on the same mecanum robot.
PROTOCOLS: dict[str, dict[str, object]] = {
    # The simulator's watchdog endpoints, as in the shipped configurations.
    "odrive": {"driver": "odrive", "firmware": "0.6", "gear_ratio": 10.0, "max_rpm": 3000,
               "watchdog_endpoints": {"fw_version": "0.0.0", "enable_watchdog": 1,
                                      "watchdog_timeout": 2}},
    # Status 1 and 5 at 50 Hz, as the configuration states they were switched on in VESC Tool
    # (a factory VESC sends none).
    "vesc": {"driver": "vesc", "pole_pairs": 7, "gear_ratio": 10.0, "max_rpm": 3000,
             "status_rate_hz": 50.0, "controller_timeout_s": 1.0},
    "cia402": {"driver": "cia402", "gear_ratio": 10.0, "max_rpm": 3000},
    "dji": {"driver": "dji", "esc": "c620", "gear_ratio": 19.203208556149733, "max_rpm": 9000,
            "no_controller_stop": "acknowledged"},
    # The shipped example's controller (config/example_dbc.yaml), geared as the others.
    "dbc": {
        **yaml.safe_load((ROOT / "config" / "example_dbc.yaml").read_text())["motor_defaults"],
        "dbc": str(ROOT / "config" / "example_controller.dbc"),
        "gear_ratio": 10.0,
        "max_rpm": 3000,
    },
}


def robot_raw(protocol: str, channel: str) -> dict[str, Any]:
    """The configuration mapping of :func:`robot_config` (the anchor loop reads it too)."""
    return {
        "name": f"bench_{protocol}",
        "drive": "mecanum",
        "geometry": {"wheel_radius": 0.05, "wheelbase": 0.40, "track": 0.36},
        "motor_defaults": PROTOCOLS[protocol],
        "motors": {
            "front_left": {"node_id": 1},
            "front_right": {"node_id": 2, "invert": True},
            "rear_left": {"node_id": 3},
            "rear_right": {"node_id": 4, "invert": True},
        },
        "limits": {"max_wheel_accel_rad_s2": 60.0, "max_linear_m_s": 1.5,
                   "max_angular_rad_s": 3.0},
        "bus": {"interface": "virtual", "channel": channel, "bitrate": 1_000_000},
        "gateway": {"rate_hz": 1000.0, "cmd_timeout_s": 0.0},
    }


def robot_config(protocol: str, channel: str) -> GatewayConfig:
    """The 4-wheel mecanum demo robot with ``protocol`` motors on a virtual channel."""
    return parse_config(robot_raw(protocol, channel), f"<bench {protocol}>")


def clock_overhead_ns(clock: Callable[[], int], samples: int = 20_000) -> float:
    """The cost of an empty timed region (two clock reads), subtracted from every cycle."""
    runs = []
    for _ in range(5):
        total = 0
        for _ in range(samples):
            t0 = clock()
            total += clock() - t0
        runs.append(total / samples)
    return min(runs)


@dataclasses.dataclass
class Sims:
    """The device simulators on their own bus, stepped by hand (their output recorded)."""

    simulators: list[DeviceSimulator]
    bus: can.BusABC

    def step(self, now_s: float) -> list[Frame]:
        out: list[Frame] = []
        for frame in drain(self.bus):
            for sim in self.simulators:
                out.extend(sim.handle(frame, now_s))
        for sim in self.simulators:
            out.extend(sim.tick(now_s))
        send_frames(self.bus, out)
        return out


@dataclasses.dataclass
class Result:
    """One protocol and one feedback mix."""

    protocol: str
    mix: str
    sent_per_cycle: float
    received_per_cycle: float
    gateway_us: list[float]  # per cycle, one value per repeat
    bare_us: list[float]

    @property
    def frames_per_cycle(self) -> float:
        return self.sent_per_cycle + self.received_per_cycle

    def rate(self, us: float) -> float:
        return self.frames_per_cycle / us * 1e6


class Bench:
    """One protocol's gateway, its feedback pool and the python-can baseline buses."""

    def __init__(self, protocol: str, clock: Callable[[], int] = time.process_time_ns,
                 overhead_ns: float | None = None) -> None:
        self.protocol = protocol
        self.clock = clock
        self.overhead_ns = clock_overhead_ns(clock) if overhead_ns is None else overhead_ns
        self.channel = f"wgtp-{protocol}"
        self.cfg = robot_config(protocol, self.channel)
        self.gw = Gateway(self.cfg, stamp_with_cycle_time=True)
        self.t = 0.0
        self.pool: list[list[Frame]] = []
        self.injector = open_bus("virtual", self.channel)
        self.bare_channel = f"{self.channel}-bare"
        self.bare_injector = open_bus("virtual", self.bare_channel)
        self.bare = open_bus("virtual", self.bare_channel)

    def close(self) -> None:
        for bus in (self.bare, self.bare_injector, self.injector):
            bus.shutdown()
        self.gw.edge.close()

    def record_pool(self, seconds: float = 2.0, enable_cycles: int = 2000,
                    twist_cycles: int = 1000) -> None:
        """Enable against the simulators, then record their output per cycle."""
        sims = Sims(simulators_for(self.gw.drives.all_motors()), open_bus("virtual", self.channel))
        try:
            gw = self.gw
            gw.supervisor.enable(self.t)

            def run(cycles: int, record: bool) -> None:
                for _ in range(cycles):
                    gw.cycle(self.t)
                    got: list[Frame] = []
                    got += sims.step(self.t + PERIOD_S / 2)
                    got += sims.step(self.t + PERIOD_S)
                    if record:
                        self.pool.append(got)
                    self.t += PERIOD_S

            run(enable_cycles, False)
            if gw.state is not GatewayState.RUNNING:
                raise SystemExit(f"{self.protocol}: did not enable: {gw.supervisor.reason}")
            gw.twist(TWIST, self.t, Source.SOCKET)
            run(twist_cycles, False)
            sent0 = gw.edge.counts.frames_sent
            run(round(seconds / PERIOD_S), True)
            self.sent_estimate = (gw.edge.counts.frames_sent - sent0) / len(self.pool)
        finally:
            sims.bus.shutdown()
        self.gw.cycle(self.t)  # takes what the simulators sent after the last cycle
        self.t += PERIOD_S
        while self.injector.recv(0.0) is not None:  # what was sent so far
            pass

    def schedule(self, mix: str, cycles: int) -> list[list[can.Message]]:
        """The frames to inject before each cycle."""
        flat = [f for group in self.pool for f in group]
        if not flat:
            raise SystemExit(f"{self.protocol}: the simulators sent nothing")
        msgs = {id(f): can.Message(arbitration_id=f.arbitration_id, data=f.data,
                                   is_extended_id=f.is_extended_id,
                                   is_remote_frame=f.is_remote_frame, dlc=f.dlc)
                for f in flat}
        if mix == "1 kHz mix":
            groups = [self.pool[k % len(self.pool)] for k in range(cycles)]
            return [[msgs[id(f)] for f in g] for g in groups]
        sent = self.sent_estimate
        per = max(1, SATURATED_PER_CYCLE - round(sent))
        return [[msgs[id(flat[(k * per + j) % len(flat)])] for j in range(per)]
                for k in range(cycles)]

    sent_estimate = 4.0

    def run_gateway(self, schedule: list[list[can.Message]], profile: cProfile.Profile | None
                    ) -> tuple[float, int, int, list[list[can.Message]]]:
        """Time ``Gateway.cycle`` over the schedule; return (ns, sent, received, sent msgs)."""
        gw, inj = self.gw, self.injector
        sent0, recv0 = gw.edge.counts.frames_sent, gw.edge.counts.frames_received
        total = 0.0
        sent_msgs: list[list[can.Message]] = []
        clock = self.clock
        for group in schedule:
            for msg in group:
                inj.send(msg)
            if profile is not None:
                profile.enable()
            t0 = clock()
            gw.cycle(self.t)
            total += clock() - t0 - self.overhead_ns
            if profile is not None:
                profile.disable()
            self.t += PERIOD_S
            out = []
            while (m := inj.recv(0.0)) is not None:
                out.append(m)
            sent_msgs.append(out)
        return (total, gw.edge.counts.frames_sent - sent0,
                gw.edge.counts.frames_received - recv0, sent_msgs)

    def run_bare(self, schedule: list[list[can.Message]],
                 sent_msgs: list[list[can.Message]]) -> tuple[float, int, int]:
        """python-can alone: send the gateway's frames, drain the injected ones."""
        bus, inj, total, sent, received = self.bare, self.bare_injector, 0.0, 0, 0
        clock = self.clock
        for group, out in zip(schedule, sent_msgs, strict=True):
            for msg in group:
                inj.send(msg)
            t0 = clock()
            for msg in out:
                bus.send(msg)
            while bus.recv(0.0) is not None:
                received += 1
            total += clock() - t0 - self.overhead_ns
            sent += len(out)
            while inj.recv(0.0) is not None:
                pass
        return total, sent, received

    def rejected(self) -> int:
        return sum(sum(drv.rejected.values()) for drv, _ in self.gw.drives.groups)

    def measure(self, mix: str, cycles: int, repeats: int,
                profile: cProfile.Profile | None = None) -> Result:
        rejected0 = self.rejected()
        gw_us: list[float] = []
        bare_us: list[float] = []
        sent = received = 0
        for _ in range(repeats):
            schedule = self.schedule(mix, cycles)
            ns, s, r, sent_msgs = self.run_gateway(schedule, profile)
            gw_us.append(ns / cycles / 1000.0)
            bns, bs, br = self.run_bare(schedule, sent_msgs)
            bare_us.append(bns / cycles / 1000.0)
            if (bs, br) != (s, r):
                raise SystemExit(f"{self.protocol}: python-can moved {bs}+{br} frames, "
                                 f"the gateway {s}+{r}")
            sent, received = sent + s, received + r
        if self.gw.state is not GatewayState.RUNNING:
            raise SystemExit(f"{self.protocol}: left RUNNING: {self.gw.supervisor.reason}")
        if self.rejected() != rejected0:
            raise SystemExit(f"{self.protocol}: the drivers rejected injected frames")
        n = cycles * repeats
        return Result(self.protocol, mix, sent / n, received / n, gw_us, bare_us)
