"""Tests of the DJI C620 / C610 simulator, alone and with the driver on a virtual bus."""

from __future__ import annotations

import math

import pytest

import drivers.dji.sim
from drivers.dji import (
    C610,
    DjiFeedback,
)
from drivers.dji.codec import (
    C620,
    COMMAND_STRUCT,
    RAD_S_PER_RPM,
    EscModel,
    decode_feedback,
)
from drivers.dji.sim import M2006_NO_LOAD_RPM, M3508_NO_LOAD_RPM, DjiMotorModel, DjiSimulator
from gateway.bus.can_bus import send_frames
from gateway.core.errors import ConfigError
from gateway.core.types import DriveFault, DriveState, Frame
from gateway.sim.device import SimFault
from gateway.sim.registry import simulator_for
from tests.drivers.dji_helpers import TWO_PI, Rig, _rig, currents_in, motor

# ===================================================================== simulator alone


def test_sim_quantises_and_reports() -> None:
    sim = DjiSimulator(motor(3), initial_position_rad=-TWO_PI / 8192 * 0.5)
    (frame,) = sim.tick(0.0)
    fb = decode_feedback(frame)
    assert fb == DjiFeedback(3, 8191, 0, 0, 35)  # floor of -0.5 count wraps to 8191
    assert sim.tick(0.0005) == []  # next feedback due at 1 ms
    assert len(sim.tick(0.001)) == 1
    sim.handle(Frame(0x700, bytes(8)), 0.001)
    sim.handle(Frame(0x200, bytes(4)), 0.001)
    sim.handle(Frame(0x200, COMMAND_STRUCT.pack(0, 0, 20000, 0)), 0.001)
    assert (sim.id_set_requests, sim.malformed, sim.command_raw) == (1, 1, 16384)
    c610 = DjiSimulator(motor(1, esc="c610"), temperature_c=50)
    assert c610.measure().temperature_c == 0


def test_sim_physics_exact_and_steady_state() -> None:
    a, b = DjiMotorModel(current_a=0.5, armed=True), DjiMotorModel(current_a=0.5, armed=True)
    a.step(0.01)
    b.step(0.005)
    b.step(0.005)
    assert a.velocity_rad_s == pytest.approx(b.velocity_rad_s)
    assert a.position_rad == pytest.approx(b.position_rad)
    a.step(100.0)  # (0.5 A balances friction below the no-load speed)
    assert a.velocity_rad_s == pytest.approx(a.torque_constant_nm_a * 0.5 / a.damping_nm_s_rad)
    assert a.applied_a == 0.5
    with pytest.raises(ConfigError, match="inertia_kg_m2"):
        DjiMotorModel(inertia_kg_m2=0.0)
    with pytest.raises(ConfigError, match="no_load_rad_s"):
        DjiMotorModel(no_load_rad_s=math.inf)


@pytest.mark.parametrize(("esc", "no_load_rpm"), [(C620, M3508_NO_LOAD_RPM),
                                                  (C610, M2006_NO_LOAD_RPM)])
def test_sim_a_held_full_current_stops_short_of_the_no_load_speed(
        esc: EscModel, no_load_rpm: float) -> None:
    """The supply voltage, not friction, bounds the speed (the ESC's current falls as it
    runs out), and the same whatever the step: a held current spins the wheel no faster
    than the motor's no-load speed."""
    runs = [DjiMotorModel.for_esc(esc) for _ in range(3)]
    for m in runs:
        m.armed, m.current_a = True, -esc.full_scale_a
    runs[0].step(5.0)
    for _ in range(50):
        runs[1].step(0.1)
    for _ in range(5000):
        runs[2].step(0.001)
    output_rpm = [m.velocity_rad_s / RAD_S_PER_RPM / esc.gear_ratio for m in runs]
    assert output_rpm == pytest.approx([output_rpm[0]] * 3, rel=1e-9)
    assert -no_load_rpm < output_rpm[0] < -0.99 * no_load_rpm
    assert [m.position_rad for m in runs] == pytest.approx([runs[0].position_rad] * 3)
    fell = runs[0].applied_a
    assert -0.1 * esc.full_scale_a < fell < 0.0  # what it reports, against a full set point
    assert DjiSimulator(motor(1, esc=esc.name), runs[0]).measure().current_raw == \
        esc.amps_to_raw(fell)


def test_sim_braking_is_not_limited_and_a_faster_wheel_gets_no_drive() -> None:
    braking = DjiMotorModel(armed=True, current_a=-20.0, velocity_rad_s=0.99 * 1000.0,
                            no_load_rad_s=1000.0)
    braking.step(1e-6)
    assert braking.applied_a == -20.0
    pushed = DjiMotorModel(armed=True, current_a=20.0, velocity_rad_s=2000.0,
                           no_load_rad_s=1000.0)
    pushed.step(0.01)
    assert pushed.applied_a == 0.0
    tau = pushed.inertia_kg_m2 / pushed.damping_nm_s_rad  # coasting on friction alone
    assert pushed.velocity_rad_s == pytest.approx(2000.0 * math.exp(-0.01 / tau))


@pytest.mark.parametrize(("timeout", "held"), [(None, True), (0.1, False)])
def test_sim_command_timeout(timeout: float | None, held: bool) -> None:
    sim = DjiSimulator(motor(1), command_timeout_s=timeout)
    sim.handle(Frame(0x200, COMMAND_STRUCT.pack(1000, 0, 0, 0)), 0.0)
    for k in range(1, 201):
        sim.tick(k * 1e-3)
    assert (sim.command_raw == 1000) == held


def test_simulator_for() -> None:
    for find in (drivers.dji.sim.simulator_for, simulator_for):
        sim = find(motor(4, esc="c610"))
        assert isinstance(sim, DjiSimulator)
        assert sim.esc is C610 and sim.esc_id == 4
        assert sim.command_timeout_s is None


@pytest.mark.parametrize("esc", ["c620", "c610"])
def test_pi_converges_on_bus(channel: str, esc: str) -> None:
    motors = [motor(1, esc=esc), motor(6, esc=esc, invert=True)]
    sims = [DjiSimulator(m) for m in motors]

    def check(rig: Rig) -> None:
        rig.drv.enable(rig.t)
        rig.run(1.0, [15.0, 8.0])
        for i, (sim, target) in enumerate(zip(sims, (15.0, 8.0), strict=True)):
            assert sim.wheel_velocity_rad_s == pytest.approx(target, rel=0.01)
            fb = rig.drv.feedback(i)
            assert fb is not None
            assert fb.velocity_rad_s == pytest.approx(target, rel=0.02)
        assert sims[1].command_raw < 0 < sims[0].command_raw  # inverted motor turns backwards
        before = sims[0].wheel_velocity_rad_s
        send_frames(rig.gw, rig.drv.disable(rig.t))
        rig.run(0.5, [15.0, 8.0])  # disarmed: zero current, the wheels coast down
        assert all(s.command_raw == 0 for s in sims)
        assert 0.0 < sims[0].wheel_velocity_rad_s < 0.98 * before

    _rig(channel, motors, sims, check)


@pytest.mark.parametrize("drop", [False, True])
def test_position_matches_ground_truth_across_wraps(channel: str, drop: bool) -> None:
    m = motor(2)
    start = (8100 + 0.5) * TWO_PI / 8192  # just below the 13-bit wrap
    sim = DjiSimulator(m, initial_position_rad=start)
    if drop:
        sim.inject(SimFault.DROP)
    one_count = TWO_PI / 8192 / m.gear_ratio

    def check(rig: Rig) -> None:
        rig.run(0.001, [0.0])
        truth0 = sim.wheel_position_rad
        rig.drv.enable(rig.t)
        for speed in (10.0, -25.0, 4.0):  # many rotor turns forwards, then backwards
            rig.run(0.7, [speed])
            fb = rig.drv.feedback(0)
            assert fb is not None
            last_frame_truth = sim.wheel_position_rad
            if drop:  # the last frame may be the one before
                assert abs(fb.position_rad - (last_frame_truth - truth0)) < 2.0 * one_count + abs(
                    sim.wheel_velocity_rad_s * 0.001
                )
            else:
                assert abs(fb.position_rad - (last_frame_truth - truth0)) < one_count
        assert abs(sim.model.position_rad - start) > 20 * TWO_PI

    _rig(channel, [m], [sim], check)


def test_silence_goes_offline_with_zero_current(channel: str) -> None:
    m = motor(1)
    sim = DjiSimulator(m)

    def check(rig: Rig) -> None:
        rig.drv.enable(rig.t)
        rig.run(0.5, [10.0])
        assert sim.command_raw != 0
        sim.inject(SimFault.SILENT)
        rig.run(0.15, [10.0])
        assert rig.drv.state(0, rig.t) is DriveState.OFFLINE
        assert rig.drv.currents_a == (0.0,)
        assert rig.drv.integrals_a == (0.0,)  # integrator reset while offline
        sent = currents_in(rig.drv.command([10.0], rig.t))
        assert sent[1] == 0  # zero current goes out while offline
        sim.clear(SimFault.SILENT)
        rig.run(1.0, [10.0])
        assert rig.drv.state(0, rig.t) is DriveState.ENABLED
        assert sim.wheel_velocity_rad_s == pytest.approx(10.0, rel=0.01)

    _rig(channel, [m], [sim], check)


def test_over_temperature_fault_and_recover(channel: str) -> None:
    m = motor(3)
    sim = DjiSimulator(m)

    def check(rig: Rig) -> None:
        rig.drv.enable(rig.t)
        rig.run(0.5, [10.0])
        sim.inject(SimFault.FAULT)
        rig.run(0.05, [10.0])
        (status,) = rig.drv.status(rig.t)
        assert status.state is DriveState.FAULT
        assert status.faults == DriveFault.OVER_TEMPERATURE
        assert "110 degC" in status.detail
        assert sim.command_raw == 0 and rig.drv.currents_a == (0.0,)
        sim.clear(SimFault.FAULT)
        rig.run(0.05, [10.0])
        assert rig.drv.state(0, rig.t) is DriveState.DISABLED
        rig.drv.enable(rig.t)
        rig.run(1.0, [10.0])
        assert rig.drv.state(0, rig.t) is DriveState.ENABLED
        assert sim.wheel_velocity_rad_s == pytest.approx(10.0, rel=0.01)

    _rig(channel, [m], [sim], check)
