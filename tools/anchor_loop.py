"""The anchor: the control loop a robot builder would write by hand instead of using wheelgate.

For the embedded default robot (``gateway/data/default.yaml``): a 4-wheel mecanum platform with
four ODrive axes (firmware 0.6, CANSimple, 11-bit identifiers) on one CAN bus.  The loop is what
a competent builder writes in an afternoon with python-can, ``struct`` and the ODrive CAN
documentation, and nothing else: it imports no wheelgate module.  The geometry, gear ratios,
motor directions and node IDs come from the same YAML file, read once at start-up.

One :meth:`AnchorLoop.cycle`:

1. receive until the bus queue is empty; decode Get_Encoder_Estimates (position in turns,
   kept per axis) and Heartbeat (axis error and state);
2. mecanum inverse kinematics of the current twist ``(vx, vy, wz)`` (REP-103 body frame:
   x forward, y left, counter-clockwise positive), wheel rad/s to motor turns/s through the
   gear ratio and the motor's direction, one common scale-down if a motor would exceed
   ``max_rpm``, zero while an axis reports an error;
3. four Set_Input_Vel frames, one per axis, sent back to back;
4. odometry, when an encoder estimate came in: wheel angle deltas since the last integration,
   mecanum forward kinematics to a body displacement, SE(2) integration (the exact exponential
   of a constant twist over the interval).

What it leaves out, and the gateway does: feasibility checks and limits on acceleration,
command timeouts, liveness and fault supervision, the enable sequence's retries and the ODrive
watchdog set-up over CAN (set here once with odrivetool, as a builder would), steering, other
controllers, the control socket, status and odometry on CAN.

ODrive CANSimple frames (`ODrive CAN protocol
<https://docs.odriverobotics.com/v/latest/manual/can-protocol.html>`_, and the `odrive-cansimple
DBC <https://github.com/odriverobotics/ODrive/blob/master/tools/odrive-cansimple.dbc>`_):
arbitration ID ``node_id << 5 | cmd_id`` (11 bits), payload little endian:

====  ====================  ===========================================================
cmd   message               payload
====  ====================  ===========================================================
0x01  Heartbeat (axis ->)   uint32 Axis_Error, uint8 Axis_State, uint8 Procedure_Result,
                            uint8 Trajectory_Done_Flag (bit 0)
0x07  Set_Axis_State        uint32 Axis_Requested_State (1 IDLE, 8 CLOSED_LOOP_CONTROL)
0x09  Get_Encoder_          float32 Pos_Estimate (turns), float32 Vel_Estimate (turns/s)
      Estimates (axis ->)
0x0B  Set_Controller_Mode   uint32 Control_Mode (2 VELOCITY_CONTROL), uint32 Input_Mode
                            (1 PASSTHROUGH)
0x0D  Set_Input_Vel         float32 Input_Vel (turns/s), float32 Input_Torque_FF (Nm)
0x18  Clear_Errors          uint8 Identify
====  ====================  ===========================================================

Run against real axes: ``python tools/anchor_loop.py --interface socketcan --channel can0
--vx 0.2 --duration 3`` (arms, drives at 1 kHz, stops, prints the pose).
"""

from __future__ import annotations

import argparse
import math
import struct
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import can
import yaml

DEFAULT_CONFIG = Path(__file__).resolve().parent.parent / "gateway" / "data" / "default.yaml"

HEARTBEAT = 0x01
SET_AXIS_STATE = 0x07
GET_ENCODER_ESTIMATES = 0x09
SET_CONTROLLER_MODE = 0x0B
SET_INPUT_VEL = 0x0D
CLEAR_ERRORS = 0x18
AXIS_IDLE = 1
AXIS_CLOSED_LOOP_CONTROL = 8
VELOCITY_CONTROL = 2
PASSTHROUGH = 1

TAU = 2.0 * math.pi
VEL = struct.Struct("<ff")  # Set_Input_Vel
ESTIMATES = struct.Struct("<ff")  # Get_Encoder_Estimates
HB = struct.Struct("<IB")  # Heartbeat: Axis_Error, Axis_State (the first 5 bytes)
U32 = struct.Struct("<I")
MODES = struct.Struct("<II")
#: The corners in the order of the formulas below.
CORNERS = ("front_left", "front_right", "rear_left", "rear_right")


@dataclass(frozen=True)
class Robot:
    """What the loop needs to know about the robot, read once at start-up.

    :param wheel_radius: m.
    :param k: ``lx + ly``: half the wheelbase plus half the track, m.
    :param node_ids: the ODrive node IDs, in :data:`CORNERS` order.
    :param turns_per_rad: motor turns per wheel radian, signed: ``gear_ratio / 2 pi``, negative
        for an inverted motor.
    :param max_turns_s: the motor speed limit, turns/s (``max_rpm / 60``).
    """

    wheel_radius: float
    k: float
    node_ids: tuple[int, ...]
    turns_per_rad: tuple[float, ...]
    max_turns_s: float

    @classmethod
    def from_file(cls, path: Path = DEFAULT_CONFIG) -> Robot:
        """The robot of a wheelgate configuration file (mecanum on ODrives)."""
        return cls.from_mapping(yaml.safe_load(path.read_text(encoding="utf-8")), str(path))

    @classmethod
    def from_mapping(cls, raw: dict[str, Any], source: str = "<mapping>",
                     driver: str = "odrive") -> Robot:
        """The robot of a parsed configuration: ``geometry``, ``motor_defaults``, ``motors``.

        :param driver: the motors' driver (``dji``: the loop of :mod:`anchor_dji`).
        :raises ValueError: for another drive, another roller angle than 45 degrees, or motors
            that are not four motors of ``driver`` on the four corners.
        """
        if raw.get("drive") != "mecanum":
            raise ValueError(f"{source}: drive: expected 'mecanum', got {raw.get('drive')!r}")
        geo = raw["geometry"]
        if geo.get("roller_angle", math.pi / 4) != math.pi / 4:
            raise ValueError(f"{source}: geometry.roller_angle: expected pi/4 (45 degree "
                             f"rollers), got {geo['roller_angle']!r}")
        defaults = raw.get("motor_defaults", {})
        motors = [{**defaults, **raw["motors"][name]} for name in CORNERS]
        if sorted(raw["motors"]) != sorted(CORNERS) or any(
                m.get("driver") != driver for m in motors):
            raise ValueError(f"{source}: motors: expected four {driver!r} motors named "
                             f"{', '.join(CORNERS)}, got {sorted(raw['motors'])}")
        rpms = {float(m["max_rpm"]) for m in motors}
        return cls(
            wheel_radius=float(geo["wheel_radius"]),
            k=float(geo["wheelbase"]) / 2 + float(geo["track"]) / 2,
            node_ids=tuple(int(m["node_id"]) for m in motors),
            turns_per_rad=tuple(float(m.get("gear_ratio", 1.0)) / TAU
                                * (-1.0 if m.get("invert", False) else 1.0) for m in motors),
            max_turns_s=min(rpms) / 60.0,
        )


def wheel_speeds(robot: Robot, vx: float, vy: float, wz: float) -> tuple[float, ...]:
    """Mecanum inverse kinematics: wheel rad/s (front_left, front_right, rear_left, rear_right),
    rollers in an "X" seen from above (the textbook formula, e.g. Lynch and Park, Modern
    Robotics, section 13.2)."""
    r, kw = robot.wheel_radius, robot.k * wz
    return ((vx - vy - kw) / r, (vx + vy + kw) / r, (vx + vy - kw) / r, (vx - vy + kw) / r)


class AnchorLoop:
    """The hand-written loop: one :meth:`cycle` per period on an open python-can bus."""

    #: The frames one cycle sends (one Set_Input_Vel per axis).
    FRAMES_PER_CYCLE = 4

    def __init__(self, robot: Robot, bus: can.BusABC) -> None:
        self.robot = robot
        self.bus = bus
        self.vx = self.vy = self.wz = 0.0
        #: Axis index of each node ID.
        self.index = {node: i for i, node in enumerate(robot.node_ids)}
        self.ids = tuple((node << 5) | SET_INPUT_VEL for node in robot.node_ids)
        self.axis_error = [0, 0, 0, 0]
        self.axis_state = [0, 0, 0, 0]
        #: The newest position estimate of each axis (turns), and those odometry last used.
        self.pos_turns: list[float | None] = [None, None, None, None]
        self.last_turns: list[float] | None = None
        self.x = self.y = self.theta = 0.0
        self.distance = 0.0

    @classmethod
    def from_mapping(cls, raw: dict[str, Any], bus: can.BusABC,
                     source: str = "<mapping>") -> AnchorLoop:
        """The loop of a parsed configuration (mecanum on four ``odrive`` motors)."""
        return cls(Robot.from_mapping(raw, source), bus)

    def _send(self, node: int, cmd: int, data: bytes) -> None:
        self.bus.send(can.Message(arbitration_id=(node << 5) | cmd, data=data,
                                  is_extended_id=False))

    def arm(self) -> None:
        """Clear errors, velocity control with passthrough input, CLOSED_LOOP_CONTROL."""
        for node in self.robot.node_ids:
            self._send(node, CLEAR_ERRORS, b"\x00")
            self._send(node, SET_CONTROLLER_MODE, MODES.pack(VELOCITY_CONTROL, PASSTHROUGH))
            self._send(node, SET_AXIS_STATE, U32.pack(AXIS_CLOSED_LOOP_CONTROL))

    def disarm(self) -> None:
        """Speed 0, then IDLE."""
        for node in self.robot.node_ids:
            self._send(node, SET_INPUT_VEL, VEL.pack(0.0, 0.0))
            self._send(node, SET_AXIS_STATE, U32.pack(AXIS_IDLE))

    def healthy(self) -> bool:
        """Every axis error-free in CLOSED_LOOP_CONTROL."""
        return not any(self.axis_error) and all(
            s == AXIS_CLOSED_LOOP_CONTROL for s in self.axis_state)

    def set_twist(self, vx: float, vy: float, wz: float) -> None:
        """The body twist to follow (m/s, m/s, rad/s)."""
        self.vx, self.vy, self.wz = vx, vy, wz

    def cycle(self) -> None:
        """Receive, command, integrate."""
        # 1. receive until the queue is empty
        fresh = False
        bus, index, pos = self.bus, self.index, self.pos_turns
        while (msg := bus.recv(0.0)) is not None:
            i = index.get(msg.arbitration_id >> 5)
            if i is None or msg.is_extended_id or msg.is_remote_frame:
                continue
            cmd = msg.arbitration_id & 0x1F
            if cmd == GET_ENCODER_ESTIMATES:
                pos[i] = ESTIMATES.unpack_from(msg.data)[0]
                fresh = True
            elif cmd == HEARTBEAT:
                self.axis_error[i], self.axis_state[i] = HB.unpack_from(msg.data)
        # 2. inverse kinematics, motor speeds
        robot = self.robot
        turns = [w * c for w, c in zip(wheel_speeds(robot, self.vx, self.vy, self.wz),
                                       robot.turns_per_rad, strict=True)]
        peak = max(abs(t) for t in turns)
        if peak > robot.max_turns_s:
            turns = [t * robot.max_turns_s / peak for t in turns]
        if any(self.axis_error):
            turns = [0.0, 0.0, 0.0, 0.0]
        # 3. one Set_Input_Vel per axis
        for arb, t in zip(self.ids, turns, strict=True):
            bus.send(can.Message(arbitration_id=arb, data=VEL.pack(t, 0.0),
                                 is_extended_id=False))
        # 4. odometry
        if fresh and None not in pos:
            self.integrate()

    def integrate(self) -> None:
        """Mecanum forward kinematics of the wheel angle deltas, then an SE(2) step."""
        now = [p for p in self.pos_turns if p is not None]
        last, self.last_turns = self.last_turns, now
        if last is None:
            return
        fl, fr, rl, rr = ((p - q) / c for p, q, c
                          in zip(now, last, self.robot.turns_per_rad, strict=True))
        r4 = self.robot.wheel_radius / 4.0
        dx = r4 * (fl + fr + rl + rr)
        dy = r4 * (-fl + fr + rl - rr)
        dth = r4 * (-fl + fr - rl + rr) / self.robot.k
        # The exponential map: the displacement of a constant twist over the interval.
        if abs(dth) < 1e-9:
            a, b = 1.0 - dth * dth / 6.0, dth / 2.0
        else:
            a, b = math.sin(dth) / dth, (1.0 - math.cos(dth)) / dth
        lx, ly = a * dx - b * dy, b * dx + a * dy
        c, s = math.cos(self.theta), math.sin(self.theta)
        self.x += c * lx - s * ly
        self.y += s * lx + c * ly
        self.theta = math.atan2(math.sin(self.theta + dth), math.cos(self.theta + dth))
        self.distance += math.hypot(dx, dy)


def main(argv: list[str] | None = None) -> None:
    """Arm, drive the twist at ``--rate`` for ``--duration`` seconds, stop, print the pose."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--config", type=Path, default=DEFAULT_CONFIG)
    parser.add_argument("--interface", default="socketcan")
    parser.add_argument("--channel", default="can0")
    parser.add_argument("--vx", type=float, default=0.0)
    parser.add_argument("--vy", type=float, default=0.0)
    parser.add_argument("--wz", type=float, default=0.0)
    parser.add_argument("--duration", type=float, default=2.0)
    parser.add_argument("--rate", type=float, default=1000.0)
    args = parser.parse_args(argv)
    robot = Robot.from_file(args.config)
    with can.Bus(interface=args.interface, channel=args.channel) as bus:
        loop = AnchorLoop(robot, bus)
        loop.arm()
        loop.set_twist(args.vx, args.vy, args.wz)
        period = 1.0 / args.rate
        start = due = time.monotonic()
        while due - start < args.duration:
            loop.cycle()
            due += period
            time.sleep(max(0.0, due - time.monotonic()))
        loop.set_twist(0.0, 0.0, 0.0)
        loop.cycle()
        loop.disarm()
    print(f"x {loop.x:.4f} m, y {loop.y:.4f} m, theta {loop.theta:.4f} rad, "
          f"distance {loop.distance:.4f} m, axis states {loop.axis_state}, "
          f"errors {loop.axis_error}")


if __name__ == "__main__":
    main()
