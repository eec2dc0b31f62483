"""Shared harness for end-to-end tests: the gateway and its simulators on simulated time."""

from __future__ import annotations

import dataclasses
import math
from typing import TYPE_CHECKING

import can

from gateway.bus.can_bus import drain, send_frames
from gateway.config import load_config
from gateway.core.errors import BusError
from gateway.core.kinematics.limits import speed_scale
from gateway.core.kinematics.odometry import Odometry
from gateway.core.types import GatewayState, Twist
from gateway.runtime.daemon import Daemon
from gateway.runtime.loop import Gateway
from gateway.runtime.sdnotify import SystemdNotifier
from gateway.sim.bus import SimulatedControllers
from gateway.sim.registry import simulators_for
from gateway.wire.can import ErrorReport, TwistCommand, TwistFlags

if TYPE_CHECKING:
    from collections.abc import Callable
    from pathlib import Path

    from gateway.core.settings import GatewayConfig
    from gateway.sim.device import DeviceSimulator


#: Simulator step (s).  DJI ESCs report the 13-bit rotor angle every millisecond; a slower
#: step would let the rotor turn more than half a revolution between reports, which no
#: unwrapping can recover (as on the real bus), so their simulators step at 1 kHz.
DJI_STEP_S = 0.001


def virtual_config(path: Path | None, channel: str, **loop: object) -> GatewayConfig:
    """A shipped config moved onto a virtual channel."""
    cfg = load_config(path, {"interface": "virtual", "channel": channel})
    if loop:
        cfg = dataclasses.replace(cfg, loop=dataclasses.replace(cfg.loop, **loop))  # type: ignore[arg-type]
    return cfg


class Rig:
    """A gateway, its simulated controllers, and a CAN controller that sends twists.

    Time is simulated: :meth:`advance` steps the simulators several times per gateway
    cycle.  Ground truth: the simulators' exact wheel angles integrated by an independent
    odometry every simulator step, with the steering actuators' exact angles (the commanded
    ones for wheels without an actuator).

    :param send_stamps: the gateway takes the simulators' frames at the simulated time they
        were sent (a kernel's receive stamp), not at the cycle that drains them (the default:
        what a ``--record`` log holds, so that a replay of one sees what the gateway saw).
    """

    def __init__(self, config: GatewayConfig, socket_path: str | None = None,
                 send_stamps: bool = False) -> None:
        self.config = config
        self.daemon: Daemon | None = None
        if socket_path is not None:
            self.daemon = Daemon(config, socket_path=socket_path, notifier=SystemdNotifier(None))
            self.gw = self.daemon.gateway
            self.gw.edge.stamp_with_cycle_time = True
        else:
            self.gw = Gateway(config, stamp_with_cycle_time=True)
        self.sims = simulators_for(self.gw.drives.all_motors())
        # The simulators and the pilot join the gateway's bus: the virtual one, or a kernel
        # interface in the socketcan tier.
        # With send_stamps, on the virtual bus the simulators' frames keep their send time
        # (simulated), which the gateway takes as their receive time, as a kernel's stamp on a
        # real bus.  Without, the gateway stamps them with the cycle that drains them (as a
        # --record log does): up to a period late, and differently for each controller (they
        # send at phases of their own).
        keep = send_stamps and config.bus.interface == "virtual"
        self.ctl = SimulatedControllers(self.sims, config.bus.channel, config.bus.interface,
                                        **({"preserve_timestamps": True} if keep else {}))
        self.pilot = can.Bus(interface=config.bus.interface, channel=config.bus.channel)
        #: Simulator steps whose frames the bus refused (a full transmit queue in the tier).
        self.sim_send_failures = 0
        self.t = 0.0
        self.period = 1.0 / config.loop.rate_hz
        self.truth = Odometry(config.model)
        self._sim_index = self._map_sims()
        self.counter = 0
        dji = any(m is not None and m.driver == "dji" for m in (*config.motors, *config.steering))
        self.sim_steps = max(2, math.ceil(self.period / DJI_STEP_S - 1e-9)) if dji else 2

    def _map_sims(self) -> list[int | None]:
        """Which simulator turns which wheel (model order)."""
        index = {s.motor.wheel: k for k, s in enumerate(self.sims)}
        return [index.get(w.name) for w in self.config.model.wheels]

    def close(self) -> None:
        self.pilot.shutdown()
        self.ctl.shutdown()
        if self.daemon is not None:
            self.daemon.close()
        else:
            self.gw.close()

    def __enter__(self) -> Rig:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def drive_sims(self) -> list[DeviceSimulator]:
        """The simulators of the drive motors (not the steering actuators)."""
        return [s for s in self.sims if not s.motor.steering]

    def truth_positions(self) -> list[float | None]:
        return [None if k is None else self.sims[k].wheel_position_rad for k in self._sim_index]

    def truth_steer(self) -> tuple[float | None, ...]:
        """Every wheel's steering angle: the actuator simulator's, else the commanded one."""
        steer = list(self.gw.prev.steer_rad)
        for sim in self.sims:
            if not sim.motor.steering:
                continue
            k = self.config.steering.index(sim.motor)
            for i, angle in self.gw.drives.wheel_angles(k, sim.steer_rad):
                steer[i] = angle
        return tuple(steer)

    def advance(self, seconds: float, each: Callable[[Rig], None] | None = None) -> None:
        """Run ``seconds`` of simulated time."""
        for _ in range(max(1, round(seconds / self.period))):
            if each is not None:
                each(self)
            if self.daemon is not None:
                for client, request in self.daemon.server.poll(0.0):
                    self.daemon.handle(client, request, self.t)
                self.daemon.step(self.t)
            else:
                self.gw.cycle(self.t)
            for k in range(self.sim_steps):
                ts = self.t + (k + 1) * self.period / self.sim_steps
                try:
                    self.ctl.step(ts)
                except BusError:
                    self.sim_send_failures += 1  # as a device whose transmit buffer is full
                self.truth.update(self.truth_positions(), ts, self.truth_steer())
            self.t += self.period

    def enable(self, timeout_s: float = 5.0) -> None:
        self.gw.supervisor.enable(self.t)
        waited = 0.0
        while self.gw.state is not GatewayState.RUNNING and waited < timeout_s:
            self.advance(self.period)
            waited += self.period
        if self.gw.state is not GatewayState.RUNNING:
            raise AssertionError(f"did not enable: {self.gw.supervisor.reason}")
        self.truth.update(self.truth_positions(), self.t, self.truth_steer())
        self.gw.odometry.reset()
        self.truth.reset()

    def send_can_twist(self, twist: Twist, flags: TwistFlags = TwistFlags.NONE) -> None:
        frame = self.gw.wg.encode_twist(TwistCommand(twist, self.counter & 0xFF, flags))
        self.counter += 1
        send_frames(self.pilot, [frame])


def path_legs(config: GatewayConfig, shape: str, speed: float = 0.4
              ) -> list[tuple[Twist, float]]:
    """Twist legs that drive a 1 m square or a circle (radius 1 m, or the smallest the robot
    can follow), as the robot can, at a speed within its limits."""
    model = config.model
    for probe in (Twist(1.0, 0.0, 1.0), Twist(0.0, 0.0, 1.0), Twist(1.0, 0.0, 0.0)):
        res = model.try_ik(probe)
        if res is not None:
            speed = min(speed, 0.8 * speed_scale(model, res, config.limits))
    radii = [r for r in (1.0, 1.5, 2.0, 3.0) if model.feasible(Twist(speed, 0.0, speed / r))]
    if shape == "circle":
        if not radii:
            # The base cannot turn (synchro drive): translate around a 72-gon of radius 1 m.
            n = 72
            step = 2 * math.pi / n / speed
            return [(Twist(speed * math.cos(2 * math.pi * k / n),
                           speed * math.sin(2 * math.pi * k / n), 0.0), step) for k in range(n)]
        return [(Twist(speed, 0.0, speed / radii[0]), 2 * math.pi * radii[0] / speed)]
    side = 1.0 / speed
    turn_rate = speed / 0.4
    if model.feasible(Twist(0.0, 0.0, turn_rate)):
        leg: list[tuple[Twist, float]] = [(Twist(speed, 0.0, 0.0), side),
                                          (Twist(0.0, 0.0, turn_rate), math.pi / 2 / turn_rate)]
        return leg * 4
    if model.feasible(Twist(0.0, speed, 0.0)):
        return [(Twist(speed, 0.0, 0.0), side), (Twist(0.0, speed, 0.0), side),
                (Twist(-speed, 0.0, 0.0), side), (Twist(0.0, -speed, 0.0), side)]
    # Car-like: straight sides joined by quarter arcs.
    arc = (Twist(speed, 0.0, speed / radii[0]), math.pi / 2 * radii[0] / speed)
    return [(Twist(speed, 0.0, 0.0), side), arc] * 4


class SocketPilot:
    """A raw client of the control socket that never blocks the single-threaded test."""

    def __init__(self, path: str) -> None:
        import socket

        self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        self.sock.connect(path)
        self.sock.setblocking(False)
        self.buf = b""

    def send(self, **request: object) -> None:
        import json

        self.sock.sendall(json.dumps(request).encode() + b"\n")

    def messages(self) -> list[dict[str, object]]:
        """Every complete message received so far."""
        import json

        try:
            while True:
                chunk = self.sock.recv(65536)
                if not chunk:
                    break
                self.buf += chunk
        except BlockingIOError:
            pass
        *lines, self.buf = self.buf.split(b"\n")
        return [json.loads(line) for line in lines if line]

    def close(self) -> None:
        self.sock.close()


def error_frame(can_id: int, data: bytes = bytes(8)) -> can.Message:
    """A SocketCAN error frame of class ``can_id`` (``linux/can/error.h``), as the kernel
    delivers them; python-can's virtual bus passes them on like any frame."""
    return can.Message(arbitration_id=can_id, data=data, is_error_frame=True,
                       is_extended_id=False)


def errors_on_can(rig: Rig) -> list[ErrorReport]:
    """Every WG_Error the pilot's bus received since it was last drained."""
    out = []
    for frame in drain(rig.pilot):
        report = rig.gw.wg.decode_error(frame)
        if report is not None:
            out.append(report)
    return out


def sent(gw: Gateway) -> list[tuple[int, bool]]:
    """Every frame ``gw`` hands to python-can from now on (what reaches the bus), as
    ``(identifier, extended)``."""
    out: list[tuple[int, bool]] = []
    bus = gw.edge.bus
    send = bus.send

    def spy(msg: can.Message, timeout: float | None = None) -> None:
        out.append((msg.arbitration_id, msg.is_extended_id))
        send(msg, timeout)

    bus.send = spy  # type: ignore[method-assign]
    return out


def reports(gw: Gateway) -> set[tuple[int, bool]]:
    """The identifiers of the gateway's own WG_* reports."""
    ids = gw.config.loop.can_ids
    return {(ids.odom_pose, ids.extended), (ids.odom_velocity, ids.extended),
            (ids.status, ids.extended), (ids.error, ids.extended)}
