"""The VESC device simulator, and the driver against it on a python-can virtual bus."""

from __future__ import annotations

import contextlib
import dataclasses
import math
import re
from typing import TYPE_CHECKING

import can
import pytest
from hypothesis import strategies as st

from drivers.vesc import VescDriver
from drivers.vesc.codec import (
    VescStatus,
    VescStatus5,
    decode,
    make_ping,
    make_set_current,
    make_set_current_brake,
    make_set_rpm,
    wrap_int32,
)
from drivers.vesc.settings import STATUS_1, STATUS_5
from drivers.vesc.sim import SimMode, VescSimulator, simulator_for
from gateway.bus.can_bus import drain, send_frames
from gateway.core.errors import ConfigError
from gateway.core.types import DriveState, Frame, MotorConfig
from gateway.sim.bus import SimulatedControllers
from gateway.sim.device import SimFault
from tests import factories
from tests.drivers.test_drivers_vesc import PP, ext, motor

if TYPE_CHECKING:
    from collections.abc import Iterator, Sequence

I32 = st.integers(-(2**31), 2**31 - 1)
#: A speed command above the factory s_pid_min_erpm (900), so the speed controller runs.
ERPM = 1400
#: STATUS and STATUS_5 on: a factory VESC sends no status (test_vesc_protection.py).
STATUS_ON = STATUS_1 | STATUS_5
#: How far a reported wheel speed at gear 1 may be from the command (rad/s): SET_RPM rounds
#: to one eRPM (half of one off), and STATUS truncates toward zero, as the firmware's
#: (int32_t) cast does (up to one more).
ERPM_LSB = 1.5 * 2 * math.pi / 60 / PP


def mode_of(sim: VescSimulator) -> SimMode:
    """The simulator's mode (a call, so mypy does not narrow it between steps)."""
    return sim.mode


def sim_for(**kwargs: object) -> VescSimulator:
    """A simulated VESC 23 at factory settings, but for ``kwargs``."""
    return VescSimulator(motor(23), **kwargs)  # type: ignore[arg-type]


def test_sim_needs_pole_pairs() -> None:
    with pytest.raises(ConfigError, match="pole_pairs"):
        VescSimulator(factories.motor("vesc", 23, validate=False))
    assert isinstance(simulator_for(motor(23)), VescSimulator)
    refused = re.escape("motor 'left'.command_period_s: expected less")
    with pytest.raises(ConfigError, match=refused):  # a block the driver refuses
        simulator_for(motor(23, validate=False, command_period_s=0.5))


def test_sim_answers_ping() -> None:
    sim = sim_for()
    assert sim.handle(make_ping(23, 1), 0.0) == [ext(0x1201, "1700")]
    assert sim.handle(make_ping(255, 9), 0.0) == [ext(0x1209, "FF00")]  # firmware echoes 255
    assert sim.handle(make_ping(24, 1), 0.0) == []


def test_sim_status_rate_and_layout() -> None:
    sim = sim_for(status_msgs=STATUS_ON, status_rate_hz=50.0, initial_tacho=-5, v_in_v=36.0)
    frames = [f for k in range(1000) for f in sim.tick(k * 0.001)]
    decoded = [decode(f) for f in frames]
    assert sum(isinstance(d, VescStatus) for d in decoded) == 50
    assert sum(isinstance(d, VescStatus5) for d in decoded) == 50
    assert decoded[1] == VescStatus5(23, -5, 36.0)


def run_sim(sim: VescSimulator, start: float, stop: float, dt: float = 0.001) -> float:
    for k in range(round((stop - start) / dt)):
        sim.tick(start + (k + 1) * dt)
    return stop


def test_sim_releases_motor_after_its_timeout() -> None:
    sim = sim_for(timeout_s=0.5)
    sim.handle(make_set_rpm(23, ERPM), 0.0)
    # Started, but held at duty 0 until the set point has ramped up to s_pid_min_erpm
    # (900 eRPM at 25000 eRPM/s: 36 ms).
    assert mode_of(sim) == SimMode.BELOW_MIN_ERPM
    run_sim(sim, 0.0, 0.5)
    assert mode_of(sim) == SimMode.SPEED
    assert sim.model.armed
    run_sim(sim, 0.5, 0.51)
    assert mode_of(sim) == SimMode.RELEASED
    assert not sim.model.armed


def test_sim_timeout_is_the_factory_one_or_the_stated_one() -> None:
    assert VescSimulator(motor(23, controller_timeout_s=0.3)).timeout_s == 1.0  # not read here
    assert simulator_for(motor(23, controller_timeout_s=0.3)).timeout_s == 0.3


@pytest.mark.parametrize(
    ("frame", "mode"),
    [
        (make_set_current(23, 0.0), SimMode.RELEASED),
        (make_set_current(23, 0.04), SimMode.RELEASED),  # below cc_min_current
        (make_set_current(23, 5.0), SimMode.CURRENT),
        (make_set_current_brake(23, 5.0), SimMode.BRAKE),
        (make_set_current_brake(23, 0.0), SimMode.RELEASED),
        (make_set_rpm(255, ERPM), SimMode.SPEED),  # broadcast
    ],
)
def test_sim_command_modes(frame: Frame, mode: SimMode) -> None:
    sim = sim_for()
    sim.handle(make_set_rpm(23, -ERPM), 0.0)
    run_sim(sim, 0.0, 0.2)
    sim.handle(frame, 0.2)
    assert mode_of(sim) == mode
    assert sim.model.armed == (mode != SimMode.RELEASED)


def test_sim_current_mode_accelerates_and_reports_current() -> None:
    sim = sim_for(status_msgs=STATUS_ON)
    sim.tick(0.0)
    sim.handle(make_set_current(23, 4.0), 0.0)
    run_sim(sim, 0.0, 0.1)
    assert sim.model.velocity_rad_s == pytest.approx(4.0 * 50.0 * 0.1, rel=1e-6)
    status = [decode(f) for f in sim.tick(0.2)]
    assert any(isinstance(s, VescStatus) and s.current_a == 4.0 for s in status)


def test_sim_ignores_malformed_and_foreign_commands() -> None:
    sim = sim_for()
    assert sim.handle(ext(0x117, "00000000C738"), 0.0) == []
    assert sim.handle(ext(0x318, "000002BC"), 0.0) == []
    assert sim.rejected == 1
    assert mode_of(sim) == SimMode.RELEASED


def test_sim_fault_ignores_commands_then_clears_itself() -> None:
    sim = sim_for(fault_stop_s=0.5, timeout_s=1.0)
    sim.handle(make_set_rpm(23, ERPM), 0.0)
    run_sim(sim, 0.0, 0.1)
    sim.inject(SimFault.FAULT)
    assert mode_of(sim) == SimMode.RELEASED
    t = 0.1
    for _ in range(4):
        sim.handle(make_set_rpm(23, ERPM), t)
        assert mode_of(sim) == SimMode.RELEASED  # ignored
        t = run_sim(sim, t, t + 0.1)
    assert sim.faults & SimFault.FAULT
    t = run_sim(sim, t, t + 0.11)
    assert not sim.faults & SimFault.FAULT  # cleared itself after fault_stop_s
    assert mode_of(sim) == SimMode.RELEASED  # until the next command
    sim.handle(make_set_rpm(23, ERPM), t)
    run_sim(sim, t, t + 0.05)  # the set point ramps up past s_pid_min_erpm (36 ms)
    assert mode_of(sim) == SimMode.SPEED


def test_sim_tachometer_counts_whole_60_degree_steps() -> None:
    sim = sim_for(initial_tacho=100)
    step = 2 * math.pi / (6 * PP)  # motor rad per step
    for fraction, tacho in [(0.99, 100), (1.0, 101), (2.5, 102), (-0.01, 99), (-1.5, 98)]:
        sim.model.position_rad = fraction * step
        assert sim.tachometer == tacho, fraction


def test_sim_tachometer_wraps() -> None:
    sim = sim_for(initial_tacho=2**31 - 3)
    assert sim.tachometer == 2**31 - 3
    sim.handle(make_set_rpm(23, ERPM), 0.0)
    run_sim(sim, 0.0, 0.2)  # (held 36 ms at duty 0 while the set point ramps to min ERPM)
    assert sim.tachometer < 0  # wrapped through 0x80000000
    revs = sim.model.position_rad / (2 * math.pi)
    assert wrap_int32(sim.tachometer - (2**31 - 3)) == math.floor(revs * 6 * PP)


# ============================================================================ on the virtual bus


def step_rad(m: MotorConfig) -> float:
    """One tachometer step as wheel angle (rad)."""
    return 2 * math.pi / (6 * PP) / m.gear_ratio


@dataclasses.dataclass
class Rig:
    """A driver and simulators on a virtual bus, stepped in simulated time (no threads)."""

    gw: can.BusABC
    ctl: SimulatedControllers
    drv: VescDriver
    sims: list[VescSimulator]
    dt: float = 0.002
    step: int = 0

    @property
    def t(self) -> float:
        return self.step * self.dt

    def send(self, frames: list[Frame]) -> None:
        send_frames(self.gw, frames)

    def run(self, seconds: float, speeds: Sequence[float] | None, *, poll: bool = True) -> None:
        """Run ``seconds``; ``speeds=None`` skips command() (a loop that only polls)."""
        for _ in range(round(seconds / self.dt)):
            self.step += 1
            t = self.t
            self.ctl.step(t)
            for f in drain(self.gw):
                self.drv.on_frame(f.stamped(t))
            out = self.drv.poll(t) if poll else []
            if speeds is not None:
                out += self.drv.command(speeds, t)
            self.send(out)

    def states(self) -> list[DriveState]:
        return [self.drv.state(i, self.t) for i in range(len(self.sims))]

    def truth(self) -> list[float]:
        return [sim.wheel_position_rad for sim in self.sims]

    def velocities(self) -> list[float]:
        fbs = [self.drv.feedback(i) for i in range(len(self.sims))]
        return [math.nan if fb is None else fb.velocity_rad_s for fb in fbs]

    def odometry_error_steps(self, start: Sequence[float]) -> list[float]:
        """|driver position - ground-truth travel| per wheel, in tachometer steps."""
        out = []
        for i, (sim, m) in enumerate(zip(self.sims, self.drv.motors, strict=True)):
            fb = self.drv.feedback(i)
            err = math.inf if fb is None else fb.position_rad - (sim.wheel_position_rad - start[i])
            out.append(abs(err) / step_rad(m))
        return out


@contextlib.contextmanager
def rig(channel: str, motors: list[MotorConfig], sims: list[VescSimulator]) -> Iterator[Rig]:
    gw = can.Bus(interface="virtual", channel=channel)
    try:
        with SimulatedControllers(sims, channel) as ctl:
            yield Rig(gw, ctl, VescDriver(motors), sims)
    finally:
        gw.shutdown()


def kind_vesc(m: MotorConfig, **kwargs: object) -> VescSimulator:
    """A kinder VESC than the factory's, as these protocol tests need: STATUS and STATUS_5 on
    (none from the factory) and ``s_pid_min_erpm`` 0 (900 from the factory), so the wheels
    can be driven slowly; the motor block states ``min_erpm: 0`` to match.  The factory
    settings are tested in test_vesc_protection.py."""
    return VescSimulator(m, status_msgs=STATUS_ON, min_erpm=0.0, **kwargs)  # type: ignore[arg-type]


def two_wheels() -> tuple[list[MotorConfig], list[VescSimulator]]:
    left = motor(23, wheel="left", min_erpm=0.0)
    right = motor(24, wheel="right", gear_ratio=2.0, invert=True, min_erpm=0.0)
    # Both counters start next to the int32 wrap, on the side they will run towards.
    sims = [
        kind_vesc(left, initial_tacho=2**31 - 20),
        kind_vesc(right, initial_tacho=-(2**31) + 20),
    ]
    return [left, right], sims


def test_drive_and_odometry_across_the_wrap(channel: str) -> None:
    motors, sims = two_wheels()
    with rig(channel, motors, sims) as r:
        r.run(0.1, None)
        assert r.states() == [DriveState.DISABLED] * 2
        start = r.truth()
        r.send(r.drv.enable(r.t))
        assert r.states() == [DriveState.ENABLING] * 2
        r.run(1.0, [6.0, 6.0])
        assert r.states() == [DriveState.ENABLED] * 2
        assert r.velocities() == pytest.approx([6.0, 6.0], abs=ERPM_LSB)
        assert [s.wheel_velocity_rad_s for s in sims] == pytest.approx([6.0, 6.0], abs=0.01)
        assert sims[0].tachometer < 0 < sims[1].tachometer  # both wrapped
        r.run(0.5, [0.0, 0.0])
        travel = [now - then for now, then in zip(r.truth(), start, strict=True)]
        assert travel == pytest.approx([6.0, 6.0], rel=0.05)
        assert max(r.odometry_error_steps(start)) <= 1.0


def test_lost_status5_stream_goes_offline_and_odometry_catches_up(channel: str) -> None:
    motors, sims = two_wheels()
    with rig(channel, motors, sims) as r:
        r.run(0.05, None)
        start = r.truth()
        r.send(r.drv.enable(r.t))
        r.run(0.2, [-4.0, 4.0])
        # DROP loses every second frame; the device sends STATUS then STATUS_5 each period,
        # so only STATUS gets through: position is stale and the driver must say so.
        sims[0].inject(SimFault.DROP)
        r.run(0.4, [-4.0, 4.0])
        assert r.states() == [DriveState.OFFLINE, DriveState.ENABLED]
        assert r.velocities() == pytest.approx([-4.0, 4.0], abs=ERPM_LSB)  # STATUS arrives
        sims[0].clear(SimFault.DROP)
        r.run(0.3, [0.0, 0.0])
        assert r.states() == [DriveState.ENABLED] * 2
        assert r.truth()[1] - start[1] == pytest.approx(4.0 * 0.6, rel=0.1)
        assert max(r.odometry_error_steps(start)) <= 1.0


def test_silence_goes_offline_and_recovers(channel: str) -> None:
    motors, sims = two_wheels()
    with rig(channel, motors, sims) as r:
        r.run(0.05, None)
        start = r.truth()
        r.send(r.drv.enable(r.t))
        r.run(0.3, [3.0, 3.0])
        sims[0].inject(SimFault.SILENT)
        r.run(0.2, [3.0, 3.0])
        assert r.states() == [DriveState.ENABLED] * 2  # within liveness_s
        r.run(0.1, [3.0, 3.0])
        assert r.states() == [DriveState.OFFLINE, DriveState.ENABLED]
        assert r.drv.status(r.t)[0].state == DriveState.OFFLINE
        r.run(0.8, [3.0, 3.0])
        # The silent device heard nothing either, so its own (factory, 1 s) timeout released
        # the motor.
        assert mode_of(sims[0]) == SimMode.RELEASED
        sims[0].clear(SimFault.SILENT)
        r.run(0.5, [3.0, 3.0])
        assert r.states() == [DriveState.ENABLED] * 2
        assert mode_of(sims[0]) == SimMode.SPEED
        r.run(0.4, [0.0, 0.0])
        assert max(r.odometry_error_steps(start)) <= 1.0


def test_fault_releases_motor_and_clears_itself(channel: str) -> None:
    motors, sims = two_wheels()
    with rig(channel, motors, sims) as r:
        r.send(r.drv.enable(r.t))
        r.run(0.4, [5.0, 5.0])
        sims[0].inject(SimFault.FAULT)
        r.run(0.3, [5.0, 5.0])
        # The motor coasts although commanded: the status frames carry no fault code, so the
        # driver cannot tell (documented limitation) and still says ENABLED.
        assert not sims[0].model.armed
        assert r.velocities()[0] < 4.0
        assert r.states() == [DriveState.ENABLED] * 2
        r.run(0.6, [5.0, 5.0])  # fault_stop_s = 0.5 s has passed: the stream drives again
        assert not sims[0].faults & SimFault.FAULT
        assert r.velocities() == pytest.approx([5.0, 5.0], abs=ERPM_LSB)


def test_keepalive_and_device_timeout(channel: str) -> None:
    # Built as the motor block states the VESC was set up: a 0.5 s timeout, status at 50 Hz,
    # and (kinder than the factory) s_pid_min_erpm 0 for the slow 5 rad/s.
    left = motor(23, controller_timeout_s=0.5, status_rate_hz=50.0, min_erpm=0.0)
    sim = simulator_for(left)
    with rig(channel, [left], [sim]) as r:
        r.send(r.drv.enable(r.t))
        r.run(0.01, None)  # the timeout read back (a round trip), then armed
        r.send(r.drv.command([5.0], r.t))
        r.run(1.5, None)  # command() never again; poll() resends the last command
        assert mode_of(sim) == SimMode.SPEED
        assert sim.wheel_velocity_rad_s == pytest.approx(5.0, abs=0.01)
        r.run(0.6, None, poll=False)  # the gateway stalls: the VESC releases the motor
        assert mode_of(sim) == SimMode.RELEASED
        r.run(0.1, None)  # polling again resumes the stream
        assert mode_of(sim) == SimMode.SPEED
        r.send(r.drv.disable(r.t))
        r.run(1.0, None)
        assert mode_of(sim) == SimMode.RELEASED  # SET_CURRENT 0, and no stream after it
        assert sim.wheel_velocity_rad_s == pytest.approx(0.0, abs=1e-3)
        assert r.states() == [DriveState.DISABLED]
