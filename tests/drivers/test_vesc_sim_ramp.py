"""The simulated VESC's speed ramp (``s_pid_ramp_erpms_s``), read off its status frames.

The firmware (https://github.com/vedderb/bldc, read at ``b9d287b3``): ``mcpwm_foc_set_pid_speed``
(``motor/mcpwm_foc.c``) only stores a SET_RPM command, taking the set point from the measured
speed when the motor was not speed-controlled; ``foc_run_pid_control_speed``
(``motor/foc_math.c``) steps the set point toward the command by ``s_pid_ramp_erpms_s * dt``
every speed-loop period, up and down alike: 25000 eRPM/s from the factory
(``MCCONF_S_PID_RAMP_ERPMS_S``, ``motor/mcconf_default.h``).  The FOC interrupt brakes at duty 0
only once that ramped set point is below ``s_pid_min_erpm`` ("Brake when set ERPM is below min
ERPM", ``motor/mcpwm_foc.c``), so a stop from speed takes the ramp's time to get there.
"""

from __future__ import annotations

import contextlib
import dataclasses
from typing import TYPE_CHECKING

import can
import pytest

from drivers.vesc.codec import (
    RPM_PER_RAD_S,
    VescStatus,
    decode,
    make_set_current,
    make_set_rpm,
)
from drivers.vesc.min_erpm import FACTORY_MIN_ERPM
from drivers.vesc.settings import STATUS_1
from drivers.vesc.sim import FACTORY_RAMP_ERPM_S, SimMode, VescSimulator
from gateway.bus.can_bus import drain, send_frames
from gateway.sim.bus import SimulatedControllers
from tests.drivers.test_drivers_vesc import PP, motor

if TYPE_CHECKING:
    from collections.abc import Iterator

#: The speed step (eRPM): 0.4 s of the factory ramp, 0.36 s back down to min ERPM.
STEP = 10000
#: How far the motor trails a ramping set point (eRPM): the model's 10 ms time constant times
#: the ramp.
LAG = 0.01 * FACTORY_RAMP_ERPM_S
#: Simulator step (s), as the background thread of ``--sim`` runs it; SET_RPM goes out every
#: ``SEND_EVERY`` steps (the driver's 20 ms command period).
DT = 0.001
SEND_EVERY = 20


@dataclasses.dataclass
class Bench:
    """A host and one simulated VESC on a virtual bus, stepped in simulated time."""

    host: can.BusABC
    ctl: SimulatedControllers
    sim: VescSimulator
    step: int = 0
    #: Every STATUS the host received: (time, erpm, duty).
    seen: list[tuple[float, int, float]] = dataclasses.field(default_factory=list)

    @property
    def t(self) -> float:
        return self.step * DT

    def run(self, seconds: float, erpm: int | None) -> float:
        """Run ``seconds`` sending SET_RPM ``erpm`` every 20 ms (none if ``None``); return
        the time of the first SET_RPM."""
        first = self.t + seconds
        for _ in range(round(seconds / DT)):
            self.step += 1
            if erpm is not None and self.step % SEND_EVERY == 0:
                first = min(first, self.t)
                send_frames(self.host, [make_set_rpm(self.sim.node_id, erpm)])
            self.ctl.step(self.t)
            for f in drain(self.host):
                msg = decode(f)
                if isinstance(msg, VescStatus):
                    self.seen.append((self.t, msg.erpm, msg.duty))
        return first

    def since(self, t0: float) -> list[tuple[float, int, float]]:
        """The status seen from ``t0`` on, as (time since ``t0``, erpm, duty)."""
        return [(t - t0, e, d) for t, e, d in self.seen if t >= t0]


@contextlib.contextmanager
def bench(channel: str, **kwargs: float) -> Iterator[Bench]:
    # Kinder than the factory in one respect, which the test reads the ramp off: STATUS on
    # (at the factory 50 Hz; a factory VESC sends none, test_vesc_protection.py).
    sim = VescSimulator(motor(23), status_msgs=STATUS_1, **kwargs)  # type: ignore[arg-type]
    host = can.Bus(interface="virtual", channel=channel)
    try:
        with SimulatedControllers([sim], channel) as ctl:
            yield Bench(host, ctl, sim)
    finally:
        host.shutdown()


def test_a_speed_step_and_a_stop_follow_the_factory_ramp(channel: str) -> None:
    with bench(channel) as b:
        b.run(0.1, None)
        t0 = b.run(0.2, STEP)  # the first SET_RPM
        up = b.since(t0)
        # Held at duty 0 until the set point reaches min ERPM (36 ms), then trailing it.
        assert all((erpm, duty) == (0, 0.0) for t, erpm, duty in up if t < 0.036)
        on_ramp = [(t, e) for t, e, _ in up if t >= 0.1]
        assert len(on_ramp) >= 4
        for t, erpm in on_ramp:
            assert erpm == pytest.approx(FACTORY_RAMP_ERPM_S * t - LAG, abs=100), t
        (ta, ea), (tb, eb) = on_ramp[0], on_ramp[-1]
        assert (eb - ea) / (tb - ta) == pytest.approx(FACTORY_RAMP_ERPM_S, rel=0.02)
        b.run(0.5, STEP)
        up = b.since(t0)
        reached = [t for t, e, _ in up if e >= STEP - 1]
        assert reached[0] >= STEP / FACTORY_RAMP_ERPM_S  # 0.4 s, not sooner
        assert up[-1][1] == pytest.approx(STEP, abs=1)

        t1 = b.run(0.7, 0)  # the first stop command
        down = b.since(t1)
        ramp_s = (STEP - FACTORY_MIN_ERPM) / FACTORY_RAMP_ERPM_S  # 0.364 s to min ERPM
        below = [t for t, e, _ in down if abs(e) < FACTORY_MIN_ERPM]
        assert ramp_s - DT <= below[0] <= ramp_s + 0.05  # speed-controlled down the ramp first
        for t, erpm, duty in down:
            if 0.05 <= t <= ramp_s - 0.02:  # speed-controlled, trailing the ramp down
                assert erpm == pytest.approx(STEP - FACTORY_RAMP_ERPM_S * t + LAG, abs=100)
                assert duty > 0.0
            elif t >= ramp_s + 0.002:  # below min ERPM: duty 0, braking to a stop
                assert duty == 0.0
        assert down[-1][1] == 0
        assert b.sim.mode is SimMode.BELOW_MIN_ERPM


@pytest.mark.parametrize(
    ("ramp", "reach", "below_min"),
    [(0.0, (0.0, 0.2), (0.0, 0.1)), (50000.0, (0.2, 0.3), (0.18, 0.21))],
)
def test_a_stated_ramp_is_the_one_followed(
    channel: str, ramp: float, reach: tuple[float, float], below_min: tuple[float, float]
) -> None:
    # 0 (s_pid_ramp_erpms_s 0): the set point is the command at once, and the motor's own
    # dynamics alone limit it; 50000: twice the factory's, half its times (0.2 s up to the
    # step, 0.18 s down to min ERPM).  The factory's would be 0.45 s and 0.36 s.
    with bench(channel, ramp_erpm_s=ramp) as b:
        t0 = b.run(0.5, STEP)
        reached = [t for t, e, _ in b.since(t0) if e >= STEP - 1]
        assert reach[0] <= reached[0] <= reach[1]
        t1 = b.run(0.5, 0)
        below = [t for t, e, _ in b.since(t1) if abs(e) < FACTORY_MIN_ERPM]
        assert below_min[0] <= below[0] <= below_min[1]


def test_speed_control_taken_over_starts_its_ramp_at_the_measured_speed() -> None:
    # A motor turning under SET_CURRENT, then SET_RPM 0: the set point starts at the measured
    # speed and ramps down under speed control; it does not brake at once.
    sim = VescSimulator(motor(23))
    t = 0.0
    sim.tick(t)
    sim.handle(make_set_current(23, 4.0), t)
    while t < 0.2 - 1e-9:
        t += DT
        sim.tick(t)
    start = sim.erpm
    assert start == pytest.approx(4.0 * 50.0 * 0.2 * RPM_PER_RAD_S * PP, rel=1e-3)  # 2674
    sim.handle(make_set_rpm(23, 0), t)
    assert sim.mode is SimMode.SPEED
    assert sim.set_point_erpm == start
    for _ in range(40):
        t += DT
        sim.tick(t)
    assert sim.set_point_erpm == pytest.approx(start - 0.04 * FACTORY_RAMP_ERPM_S, abs=1)
    assert sim.erpm == pytest.approx(sim.set_point_erpm + LAG, abs=100)
    for _ in range(200):
        t += DT
        sim.tick(t)
    assert (sim.mode, sim.set_point_erpm) == (SimMode.BELOW_MIN_ERPM, 0.0)
    assert sim.erpm == pytest.approx(0.0, abs=0.5)
