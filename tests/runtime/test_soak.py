"""Soak: the daemon at 1 kHz on simulated time with random twists and random injected faults.

Ten minutes of simulated time on the ``mecanum`` config (DJI ESCs, host-side speed loops) and
on the embedded default (four ODrive axes), marked ``slow``; a short variant of the same run
(15 s each) is in the quick suite.  A seeded :class:`Planner` picks a feasible twist every
0.2 s to 2 s (sent on the control socket every 0.1 s) and, after 1 s to 5 s of clean running,
a fault on a random motor: silence, a controller fault, dropped frames, late answers (below or
above ``liveness_s``), garbage, or a stalled wheel (the device reports healthy, the motor
coasts; the robot is sent straight ahead meanwhile, so the wheel is well off its command), each
cleared after 0.5 s to 2 s (a stall: ``tracking_time_s`` more); where the gateway waits for
one, the runner sends ``enable``.  Asserted:

* no exception escapes, and no FAULT while nothing is injected (a tracking fault within
  ``tracking_time_s`` of a clear is the injected fault's: its count was gathered during the
  injection, and it is reported apart);
* memory: traced memory (``tracemalloc``, after a warm-up and ``gc.collect()``) grows by less
  than :data:`MEMORY_BOUND_BYTES` (5 MB) from the end of the warm-up to the end;
* no missed safety reaction: every silence, controller fault or latency above ``liveness_s``
  is answered by FAULT with every wheel at zero within ``liveness_s`` + 2 cycles, and garbage
  within :data:`GARBAGE_BOUND_S` (a garbage frame of the right length can pass for fresh
  feedback -- a DJI frame has no checksum -- so garbage is not held to the liveness bound),
  and a stall within ``tracking_time_s`` + :data:`STALL_MARGIN_S`; the worst reaction time per
  kind is printed;
* odometry: over every clean stretch (from 0.5 s after a recovery to the next fault), the
  gateway's displacement agrees with the simulators' ground truth; the summed error is below
  1 % of the distance travelled in those stretches.  While a fault blinds the gateway (a
  silent or garbling encoder) odometry cannot follow, so those stretches are not counted.
"""

from __future__ import annotations

import collections
import gc
import logging
import math
import random
import time
import tracemalloc
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import pytest

from gateway.core.kinematics.limits import speed_scale
from gateway.core.types import ErrorCode, GatewayState, Twist
from gateway.sim.device import SimFault
from tests.conftest import CONFIG_DIR
from tests.e2e_helpers import Rig, SocketPilot, virtual_config

if TYPE_CHECKING:
    from collections.abc import Sequence

    from gateway.core.kinematics.odometry import Pose
    from gateway.core.settings import GatewayConfig

#: Largest growth of traced memory allowed from the end of the warm-up to the end (bytes).
MEMORY_BOUND_BYTES = 5 * 1024 * 1024
#: Longest time from garbage to FAULT with every wheel at zero (s).
GARBAGE_BOUND_S = 0.5
#: Largest summed odometry error, as a fraction of the distance travelled.
ODOMETRY_BOUND = 0.01
#: Longest time from a stall to FAULT beyond ``tracking_time_s`` (s).  The twist sent at the
#: stall ramps in through the acceleration limits, one scale factor for the whole twist, so a
#: wheel may reverse over 0.6 s (mecanum, 40 rad/s^2); while its command crosses zero the
#: stalled wheel is inside its window and the count goes down for as long as it stays there.
STALL_MARGIN_S = 0.6
#: The twist held while a wheel is stalled: straight ahead, every wheel turning.
STALL_TWIST = Twist(0.4, 0.0, 0.0)
ALL_KINDS = (SimFault.SILENT, SimFault.FAULT, SimFault.DROP, SimFault.LATE, SimFault.GARBAGE,
             SimFault.STALL)


@dataclass(frozen=True, slots=True)
class Injection:
    """One fault: what, where, for how long, and whether it must end in FAULT."""

    kind: SimFault
    motor: int
    duration_s: float
    latency_s: float
    must_fault: bool


class Planner:
    """The random part of the soak, seeded; pure (no I/O, no clock).

    :param kinds: the faults to draw from; each round uses every kind once, in random order.
    """

    def __init__(self, seed: int, config: GatewayConfig, liveness_s: float,
                 kinds: Sequence[SimFault], gap_s: tuple[float, float] = (1.0, 5.0)) -> None:
        self.rng = random.Random(seed)
        self.config = config
        self.liveness_s = liveness_s
        self.kinds = tuple(kinds)
        self.gap_s = gap_s
        self._round: list[SimFault] = []

    def twist(self) -> tuple[Twist, float]:
        """A feasible twist within the robot's limits, and how long to hold it (s)."""
        rng, model = self.rng, self.config.model
        while True:
            tw = Twist(rng.uniform(-0.6, 0.6), rng.uniform(-0.6, 0.6), rng.uniform(-1.2, 1.2))
            result = model.try_ik(tw)
            if result is not None:
                break
        scale = min(1.0, 0.9 * speed_scale(model, result, self.config.limits))
        return (Twist(tw.vx_m_s * scale, tw.vy_m_s * scale, tw.wz_rad_s * scale),
                rng.uniform(0.2, 2.0))

    def gap(self) -> float:
        """Clean running before the next fault (s)."""
        return self.rng.uniform(*self.gap_s)

    def injection(self) -> Injection:
        rng = self.rng
        if not self._round:
            self._round = list(self.kinds)
            rng.shuffle(self._round)
        kind = self._round.pop()
        latency = 0.0
        must = kind in (SimFault.SILENT, SimFault.FAULT, SimFault.GARBAGE, SimFault.STALL)
        if kind is SimFault.LATE:
            must = rng.random() < 0.5
            # Harmless: well below liveness (DJI's host loop is stable up to about 30 ms).
            latency = (self.liveness_s + rng.uniform(0.05, 0.3) if must
                       else rng.uniform(0.002, 0.03))
        motors = sum(m is not None for m in self.config.motors)
        duration = rng.uniform(max(0.5, GARBAGE_BOUND_S), 2.0)
        if kind is SimFault.STALL:
            duration += self.config.loop.tracking_time_s + STALL_MARGIN_S
        return Injection(kind, rng.randrange(motors), duration, latency, must)


@dataclass(slots=True)
class Report:
    """What a soak run measured."""

    cycles: int = 0
    real_s: float = 0.0
    memory_growth_bytes: int = 0
    injections: dict[str, int] = field(default_factory=dict)
    #: Worst time from injection to FAULT with zero wheels, per kind (s).
    worst_reaction_s: dict[str, float] = field(default_factory=dict)
    missed: list[str] = field(default_factory=list)
    spurious: list[str] = field(default_factory=list)
    #: Tracking faults that fired just after a fault was cleared, on evidence gathered while
    #: it was injected (the count goes down only as fast as it went up).
    after_clear: list[str] = field(default_factory=list)
    worst_recovery_s: float = 0.0
    enables_sent: int = 0
    distance_m: float = 0.0
    odometry_error_m: float = 0.0
    worst_heading_error_rad: float = 0.0
    #: Steps of a wheel's position the odometry took for jumps: only while a controller sent
    #: garbage (random bytes on an ODrive's estimates ID decode as random positions) and on
    #: the way back from it; one at any other time is spurious.
    position_jumps: int = 0

    def text(self) -> str:
        reactions = ", ".join(f"{k} {v * 1000:.1f} ms" for k, v in
                              sorted(self.worst_reaction_s.items()))
        return (f"{self.cycles} cycles in {self.real_s:.1f} s real; memory growth "
                f"{self.memory_growth_bytes / 1024:.1f} KiB; injections {self.injections}; "
                f"worst reaction: {reactions}; worst recovery {self.worst_recovery_s:.2f} s "
                f"({self.enables_sent} enables sent); odometry error "
                f"{self.odometry_error_m * 1000:.3f} mm over {self.distance_m:.1f} m "
                f"({100 * self.odometry_error_m / max(self.distance_m, 1e-9):.4f} %), worst "
                f"heading error {math.degrees(self.worst_heading_error_rad):.3f} deg; "
                f"{len(self.missed)} missed reactions, {len(self.spurious)} spurious faults, "
                f"{len(self.after_clear)} tracking faults just after a clear; "
                f"{self.position_jumps} position jumps (garbage)")


def _delta(start: Pose, end: Pose) -> tuple[float, float, float]:
    """``end`` seen from ``start``: body-frame displacement and heading change."""
    c, s = math.cos(start.theta_rad), math.sin(start.theta_rad)
    dx, dy = end.x_m - start.x_m, end.y_m - start.y_m
    dth = math.remainder(end.theta_rad - start.theta_rad, math.tau)
    return c * dx + s * dy, -s * dx + c * dy, dth


class Soak:
    """Runs a :class:`Planner`'s scenario on a rig and measures it."""

    def __init__(self, rig: Rig, pilot: SocketPilot, planner: Planner) -> None:
        self.rig, self.pilot, self.planner = rig, pilot, planner
        self.gw = rig.gw
        self.report = Report()
        self._segment: tuple[Pose, Pose, float] | None = None
        #: The ground truth of the last 0.2 s by time, to compare with the gateway's odometry at
        #: the time of its last feedback (ODrive estimates come every 10 ms).
        self._truth: collections.deque[tuple[float, Pose, float]] = collections.deque(maxlen=200)

    def _speeds_zero(self) -> bool:
        return all(v == 0.0 for v in self.gw.prev.wheel_rad_s)

    def _record_truth(self) -> None:
        st = self.rig.truth.state
        self._truth.append((self.rig.t, st.pose, st.distance_m))

    def _truth_at(self, t: float) -> tuple[Pose, float]:
        """The ground truth at the simulator step nearest to ``t``."""
        _, pose, dist = min(self._truth, key=lambda e: abs(e[0] - t))
        return pose, dist

    def _start_segment(self) -> None:
        odo = self.gw.odometry.state
        self._segment = (odo.pose, *self._truth_at(odo.timestamp_s))

    def _end_segment(self) -> None:
        if self._segment is None:
            return
        gw0, truth0, dist0 = self._segment
        odo = self.gw.odometry.state
        truth, dist1 = self._truth_at(odo.timestamp_s)
        a, b = _delta(gw0, odo.pose), _delta(truth0, truth)
        r = self.report
        r.distance_m += dist1 - dist0
        r.odometry_error_m += math.hypot(a[0] - b[0], a[1] - b[1])
        r.worst_heading_error_rad = max(r.worst_heading_error_rad, abs(a[2] - b[2]))
        self._segment = None

    def run(self, duration_s: float, warmup_s: float) -> Report:
        rig, gw, plan, r = self.rig, self.gw, self.planner, self.report
        strict = plan.liveness_s + 2 * rig.period + 1e-9
        cfg_tracking_s = plan.config.loop.tracking_time_s
        bound = strict
        twist, next_twist = Twist(), 0.0
        phase, fault_at, settle_until = "clean", plan.gap(), 0.0
        inj: Injection | None = None
        t_inj = clear_at = next_enable = 0.0
        t_clear = -math.inf  # no fault cleared yet
        reaction: float | None = None
        tracing = False
        name = ""
        start = time.perf_counter()
        self._record_truth()
        self._start_segment()
        for cycle in range(round(duration_s / rig.period)):
            t = rig.t
            if not tracing and t >= warmup_s:
                gc.collect()
                tracemalloc.start()
                base, tracing = tracemalloc.get_traced_memory()[0], True
            if t >= next_twist:
                twist, hold = plan.twist()
                next_twist = t + hold
            if cycle % 100 == 0:
                self.pilot.send(op="twist", vx=twist.vx_m_s, vy=twist.vy_m_s, wz=twist.wz_rad_s)
                self.pilot.messages()
            if phase == "clean" and t >= fault_at and gw.state is GatewayState.RUNNING:
                self._end_segment()
                inj = plan.injection()
                sim = rig.sims[inj.motor]
                sim.latency_s = inj.latency_s if inj.latency_s else sim.latency_s
                sim.inject(inj.kind)
                name = str(inj.kind.name) if inj.kind is not SimFault.LATE else (
                    "LATE>liveness" if inj.must_fault else "LATE<liveness")
                r.injections[name] = r.injections.get(name, 0) + 1
                phase, t_inj, clear_at, reaction = "faulted", t, t + inj.duration_s, None
                bound = GARBAGE_BOUND_S if inj.kind is SimFault.GARBAGE else strict
                if inj.kind is SimFault.STALL:
                    bound = cfg_tracking_s + STALL_MARGIN_S
                    twist, next_twist = STALL_TWIST, clear_at
                    self.pilot.send(op="twist", vx=twist.vx_m_s, vy=twist.vy_m_s,
                                    wz=twist.wz_rad_s)
            elif phase == "faulted" and inj is not None and t >= clear_at:
                if inj.must_fault and reaction is None:
                    r.missed.append(f"{name} on motor {inj.motor} at {t_inj:.3f} s")
                rig.sims[inj.motor].clear(inj.kind)
                phase, t_clear, next_enable = "recovering", t, t + 2.0
            elif phase == "recovering":
                if gw.state is GatewayState.RUNNING:
                    r.worst_recovery_s = max(r.worst_recovery_s, t - t_clear)
                    phase, settle_until = "settling", t + 0.5
                elif t >= next_enable and gw.state in (GatewayState.FAULT,
                                                       GatewayState.DISABLED):
                    self.pilot.send(op="enable")
                    r.enables_sent += 1
                    next_enable = t + 2.0
                assert t - t_clear < 30.0, f"no recovery: {gw.state.name} {gw.supervisor.reason}"
            elif phase == "settling":
                if gw.state is not GatewayState.RUNNING:
                    phase = "recovering"
                elif t >= settle_until:
                    phase, fault_at = "clean", t + plan.gap()
                    self._start_segment()
            rig.advance(rig.period)
            self._record_truth()
            if gw.counts.position_jumps != r.position_jumps:
                r.position_jumps = gw.counts.position_jumps
                if phase == "clean" or inj is None or inj.kind is not SimFault.GARBAGE:
                    r.spurious.append(f"{t:.3f} s: position jump of "
                                      f"{gw.odom_feed.last_jump_text(gw.model.names)}")
            state = gw.state
            if phase in ("clean", "settling") and state is GatewayState.FAULT:
                fault = f"{t:.3f} s: {gw.supervisor.reason}"
                if (gw.supervisor.fault_code is ErrorCode.TRACKING_ERROR
                        and t - t_clear <= cfg_tracking_s + strict):
                    r.after_clear.append(fault)
                else:
                    r.spurious.append(fault)
            if phase == "faulted" and inj is not None:
                safe = state is GatewayState.FAULT and self._speeds_zero()
                if inj.must_fault and reaction is None and safe:
                    reaction = t - t_inj
                    r.worst_reaction_s[name] = max(r.worst_reaction_s.get(name, 0.0), reaction)
                    if reaction > bound:
                        r.missed.append(f"{name} on motor {inj.motor}: {reaction:.4f} s")
                if not inj.must_fault and inj.kind is SimFault.LATE and state is GatewayState.FAULT:
                    r.spurious.append(f"harmless latency {inj.latency_s:.3f} s: "
                                      f"{gw.supervisor.reason}")
        if phase == "clean":
            self._end_segment()
        r.cycles = round(duration_s / rig.period)
        r.real_s = time.perf_counter() - start
        if tracing:
            gc.collect()
            r.memory_growth_bytes = tracemalloc.get_traced_memory()[0] - base
            tracemalloc.stop()
        return r


#: (config, faults drawn) per robot.
ROBOTS = {
    "mecanum_dji": (CONFIG_DIR / "mecanum.yaml", ALL_KINDS),
    "default_odrive": (None, ALL_KINDS),
}


def soak(robot: str, channel: str, sock_path: str, duration_s: float, warmup_s: float,
         gap_s: tuple[float, float]) -> Report:
    path, kinds = ROBOTS[robot]
    cfg = virtual_config(path, channel, rate_hz=1000.0)
    with Rig(cfg, sock_path) as rig:
        rig.sim_steps = 1  # 1 ms steps: enough for DJI's 13-bit angle (DJI_STEP_S)
        rig.pilot.shutdown()  # twists go over the socket; nobody reads the CAN side
        rig.enable()
        liveness = max(drv.live.liveness_s for drv, _ in rig.gw.drives.groups)
        pilot = SocketPilot(sock_path)
        logging.disable(logging.CRITICAL)  # pytest would keep every record in memory
        try:
            return Soak(rig, pilot, Planner(7, cfg, liveness, kinds, gap_s)).run(
                duration_s, warmup_s)
        finally:
            logging.disable(logging.NOTSET)
            pilot.close()


def check(report: Report, capsys: pytest.CaptureFixture[str], robot: str,
          min_injections: int) -> None:
    with capsys.disabled():
        print(f"\nsoak {robot}: {report.text()}")  # noqa: T201 - the figures are the point
    assert sum(report.injections.values()) >= min_injections, report.injections
    assert not report.missed, report.missed
    assert not report.spurious, report.spurious
    assert report.memory_growth_bytes < MEMORY_BOUND_BYTES
    assert report.distance_m > 0.0
    assert report.odometry_error_m <= ODOMETRY_BOUND * report.distance_m


@pytest.mark.timeout(120)
@pytest.mark.parametrize("robot", list(ROBOTS))
def test_soak_short(robot: str, channel: str, sock_path: str,
                    capsys: pytest.CaptureFixture[str]) -> None:
    report = soak(robot, channel, sock_path, duration_s=15.0, warmup_s=12.0, gap_s=(0.5, 1.5))
    check(report, capsys, robot, min_injections=4)


@pytest.mark.slow
@pytest.mark.timeout(3600)
@pytest.mark.parametrize("robot", list(ROBOTS))
def test_soak_ten_minutes(robot: str, channel: str, sock_path: str,
                          capsys: pytest.CaptureFixture[str]) -> None:
    report = soak(robot, channel, sock_path, duration_s=600.0, warmup_s=30.0, gap_s=(1.0, 5.0))
    check(report, capsys, robot, min_injections=60)
    assert set(report.worst_reaction_s) >= {"SILENT", "FAULT", "LATE>liveness", "STALL"}
