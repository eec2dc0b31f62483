"""The DJI anchor: the loop a robot builder would write by hand for four DJI M3508 motors.

The same 4-wheel mecanum robot as :mod:`anchor_loop`, its motors four RoboMaster C620 ESCs
(IDs 1-4) instead of ODrives: the loop the throughput benchmark's DJI figures are measured
against (``bench_anchor.py --protocol dji``).  The ESCs take a torque current only, so the
builder closes each rotor's speed loop on the computer, as DJI's example firmware does on its
board (`RoboMaster/Development-Board-C-Examples
<https://github.com/RoboMaster/Development-Board-C-Examples>`_, ``chassis_task.c``: a PI on the
rotor speed in rpm, at a fixed period).  Python-can, ``struct`` and :mod:`anchor_loop`'s
kinematics and odometry, nothing of wheelgate.

One :meth:`DjiAnchorLoop.cycle`:

1. receive until the bus queue is empty; decode each ESC's feedback (``0x200 + ID``, big
   endian: u16 rotor angle 0..8191, i16 rotor speed rpm, i16 current, u8 temperature) and
   unwrap the angle the shorter way round into a rotor position (turns);
2. mecanum inverse kinematics of the twist, wheel to rotor speed through the gear ratio and the
   motor's direction, one common scale-down over ``max_rpm``;
3. per motor a PI on the rotor speed error (A per rad/s, A per rad; the integrator clamped to
   the current limit, the output too), zero current until every ESC has reported;
4. one ``0x200`` frame with the four currents (i16, 16384 = 20 A), big endian;
5. odometry when feedback came in (:meth:`anchor_loop.AnchorLoop.integrate`).

What it leaves out, and the gateway does: everything :mod:`anchor_loop` names, and the
over-temperature check, the stale-feedback check that zeroes a motor's current, and the tracking
check that stops a wheel that does not follow its loop.
"""

from __future__ import annotations

import struct
from typing import Any

import can
from anchor_loop import TAU, AnchorLoop, Robot, wheel_speeds

#: C620: -16384..16384 stands for -20..20 A (RoboMaster C620 user guide, CAN protocol).
RAW_PER_A = 16384 / 20.0
COUNTS_PER_REV = 8192
COMMAND_ID = 0x200
FEEDBACK = struct.Struct(">Hh")  # rotor angle, rotor speed (the first 4 bytes)
COMMAND = struct.Struct(">hhhh")
RAD_S_PER_RPM = TAU / 60.0


class DjiAnchorLoop(AnchorLoop):
    """The hand-written DJI loop: one :meth:`cycle` per ``period_s`` on an open bus.

    :param robot: the robot; ``node_ids`` are the ESC IDs, ``turns_per_rad`` rotor turns per
        wheel radian (signed), ``max_turns_s`` the rotor limit.
    :param kp: A per rad/s of rotor speed error; ``ki``: A per rad; ``limit_a``: the current
        limit (A); the defaults are wheelgate's DJI defaults (0.1, 1.0, the C620's 20 A).
    """

    #: One command frame for the four ESCs.
    FRAMES_PER_CYCLE = 1

    def __init__(self, robot: Robot, bus: can.BusABC, period_s: float = 0.001,
                 kp: float = 0.1, ki: float = 1.0, limit_a: float = 20.0) -> None:
        super().__init__(robot, bus)
        self.index = {COMMAND_ID + esc: i for i, esc in enumerate(robot.node_ids)}
        self.period_s, self.kp, self.ki, self.limit_a = period_s, kp, ki, limit_a
        #: Rotor rad per wheel rad, signed, and the rotor speed limit (rad/s).
        self.ratio = tuple(c * TAU for c in robot.turns_per_rad)
        self.max_rad_s = robot.max_turns_s * TAU
        self.angle: list[int | None] = [None, None, None, None]
        self.counts = [0, 0, 0, 0]
        self.speed_rad_s = [0.0, 0.0, 0.0, 0.0]
        self.integral_a = [0.0, 0.0, 0.0, 0.0]

    @classmethod
    def from_mapping(cls, raw: dict[str, Any], bus: can.BusABC,
                     source: str = "<mapping>") -> DjiAnchorLoop:
        """The loop of a parsed configuration (mecanum on four ``dji`` motors), its gains and
        current limit from ``motor_defaults`` (``kp``, ``ki``, ``max_current_a``)."""
        robot = Robot.from_mapping(raw, source, driver="dji")
        d = raw.get("motor_defaults", {})
        rate = float(raw.get("gateway", {}).get("rate_hz", 1000.0))
        return cls(robot, bus, 1.0 / rate, float(d.get("kp", 0.1)), float(d.get("ki", 1.0)),
                   float(d.get("max_current_a", 0.0)) or 20.0)

    def arm(self) -> None:
        """Nothing to arm: a C620 follows its current from the first frame."""

    def disarm(self) -> None:
        """Zero current on every ESC."""
        self.bus.send(self._frame(COMMAND.pack(0, 0, 0, 0)))

    def healthy(self) -> bool:
        """Every ESC has reported."""
        return None not in self.angle

    def cycle(self) -> None:
        """Receive, close the speed loops, send, integrate."""
        # 1. receive until the queue is empty
        fresh = False
        bus, index, angle, counts, speed = (self.bus, self.index, self.angle, self.counts,
                                            self.speed_rad_s)
        while (msg := bus.recv(0.0)) is not None:
            i = index.get(msg.arbitration_id)
            if i is None or msg.is_extended_id or msg.is_remote_frame or msg.dlc != 8:
                continue
            a, rpm = FEEDBACK.unpack_from(msg.data)
            last = angle[i]
            if last is not None:
                d = a - last
                if d > COUNTS_PER_REV // 2:
                    d -= COUNTS_PER_REV
                elif d < -COUNTS_PER_REV // 2:
                    d += COUNTS_PER_REV
                counts[i] += d
            angle[i] = a
            speed[i] = rpm * RAD_S_PER_RPM
            self.pos_turns[i] = counts[i] / COUNTS_PER_REV
            fresh = True
        # 2. inverse kinematics, rotor speeds
        targets = [w * c for w, c in zip(wheel_speeds(self.robot, self.vx, self.vy, self.wz),
                                         self.ratio, strict=True)]
        peak = max(abs(t) for t in targets)
        if peak > self.max_rad_s:
            targets = [t * self.max_rad_s / peak for t in targets]
        # 3. the speed loops
        raw = [0, 0, 0, 0]
        if None not in angle:
            lim, kp, step = self.limit_a, self.kp, self.ki * self.period_s
            integral = self.integral_a
            for i in range(4):
                e = targets[i] - speed[i]
                integral[i] = min(max(integral[i] + step * e, -lim), lim)
                raw[i] = round(min(max(kp * e + integral[i], -lim), lim) * RAW_PER_A)
        # 4. one frame for the four ESCs
        bus.send(self._frame(COMMAND.pack(*raw)))
        # 5. odometry
        if fresh and None not in angle:
            self.integrate()

    def _frame(self, data: bytes) -> can.Message:
        return can.Message(arbitration_id=COMMAND_ID, data=data, is_extended_id=False)
