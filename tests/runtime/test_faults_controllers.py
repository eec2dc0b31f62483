"""Fault injection during a run, at the controllers: the simulator's fault flags, then a
controller that stops answering, reports a fault, answers late, or does not follow its command.

The matrix of faults, safe states, errors and recoveries is in :mod:`tests.runtime.fault_helpers`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import pytest

from drivers.dji.sim import DjiSimulator
from drivers.odrive.enums import AxisState, CmdId
from gateway.bus.can_bus import send_frames
from gateway.config import load_config
from gateway.core.control import AUTO_RETRY_DELAY_S
from gateway.core.types import ErrorCode, Frame, GatewayState
from gateway.sim.device import DeviceSimulator, SimFault
from tests.runtime import fault_helpers
from tests.runtime.fault_helpers import (
    DRIVERS,
    RATE_HZ,
    VICTIM,
    VX,
    Run,
    Sample,
    assert_safe_from,
    reaction_bound,
    victim_text,
)

if TYPE_CHECKING:

    from gateway.core.types import MotorConfig

pytestmark = pytest.mark.timeout(60)


# The shared fixtures (fault_helpers.py), bound here so that pytest finds them.
run = fault_helpers.run


#: What the FAULT reason says about an injected controller fault, per driver.
FAULT_DETAIL = {
    "odrive": "reports a fault: axis error 0x00000020: DRV_FAULT",
    "dji": "reports a fault: temperature 110 degC above max_temp_c 80",
    "cia402": "reports a fault: node 2 (\"wheel_2\"): statusword",
}


# -- the simulator's fault flags (pure) ------------------------------------------------------


class CountingSim(DeviceSimulator):
    """Emits one numbered frame per tick on ID 0x100 and echoes received frames on 0x200."""

    def __init__(self, motor: MotorConfig) -> None:
        super().__init__(motor)
        self.n = 0

    def _on_frame(self, frame: Frame, now_s: float) -> list[Frame]:
        return [Frame(0x200, frame.data)]

    def _on_tick(self, now_s: float) -> list[Frame]:
        self.n += 1
        return [Frame(0x100, bytes([self.n % 256]))]


def counting_sim() -> CountingSim:
    motor = load_config(None).motors[0]
    assert motor is not None
    return CountingSim(motor)


def ticks(sim: DeviceSimulator, start_ms: int, stop_ms: int) -> list[tuple[int, int]]:
    """(time ms, frame number) of what the simulator emits, one tick per millisecond."""
    return [(ms, f.data[0]) for ms in range(start_ms, stop_ms) for f in sim.tick(ms / 1000)]


def test_late_holds_every_frame_for_the_latency_in_order() -> None:
    sim = counting_sim()
    sim.latency_s = 0.005
    assert ticks(sim, 0, 3) == [(0, 1), (1, 2), (2, 3)]
    sim.inject(SimFault.LATE)
    assert sim.handle(Frame(0x7, b"\x09"), 0.0025) == []  # an answer is held as well
    assert sim.held == 1
    out = ticks(sim, 3, 12)
    assert out == [(8, 9), (8, 4), (9, 5), (10, 6), (11, 7)]  # 9: the answer
    assert sim.held == 5  # frames 8..12 are still on their way
    sim.clear(SimFault.LATE)
    # What is held goes out at once, in order, ahead of the new frame.
    assert [f.data[0] for f in sim.tick(0.012)] == [8, 9, 10, 11, 12, 13]
    assert sim.held == 0
    assert ticks(sim, 13, 14) == [(13, 14)]


def test_late_answer_comes_after_the_latency() -> None:
    sim = counting_sim()
    sim.latency_s = 0.002
    sim.inject(SimFault.LATE)
    assert sim.handle(Frame(0x7, b"\x09"), 0.0) == []
    assert [f for f in sim.tick(0.001) if f.arbitration_id == 0x200] == []
    assert Frame(0x200, b"\x09") in sim.tick(0.002)


def test_silence_discards_what_late_holds() -> None:
    sim = counting_sim()
    sim.inject(SimFault.LATE)
    ticks(sim, 0, 5)
    assert sim.held == 5
    sim.inject(SimFault.SILENT)
    assert ticks(sim, 5, 50) == []
    assert sim.held == 0
    sim.clear()
    assert ticks(sim, 50, 51) == [(50, 51)]


def test_garbage_is_random_bytes_of_random_length_on_the_same_id_seeded() -> None:
    sim, twin = counting_sim(), counting_sim()
    for s in (sim, twin):
        s.inject(SimFault.GARBAGE)
    frames = [f for ms in range(2000) for f in sim.tick(ms / 1000)]
    assert frames == [f for ms in range(2000) for f in twin.tick(ms / 1000)]  # the seed
    assert {f.arbitration_id for f in frames} == {0x100}
    assert {len(f.data) for f in frames} == set(range(9))
    assert sim.garbage_sent == 2000
    assert sum(f.data == bytes([(k + 1) % 256]) for k, f in enumerate(frames)) < 20
    sim.clear(SimFault.GARBAGE)
    assert sim.tick(2.0) == [Frame(0x100, bytes([2001 % 256]))]


# -- a controller stops answering ------------------------------------------------------------


@pytest.mark.parametrize("run", DRIVERS, indirect=True)
def test_silent_controller_faults_names_motor_and_recovers(run: Run) -> None:
    run.pilot.send(op="subscribe", topics=["error"])
    t0 = run.inject(SimFault.SILENT)
    samples = run.drive(0.6)
    fault = next(s for s in samples if s.state is GatewayState.FAULT)
    assert fault.t - t0 <= reaction_bound(run)
    assert_safe_from(samples, fault)
    assert f"{victim_text(run)} stopped answering" in run.rig.gw.supervisor.reason
    events = [m for m in run.messages() if m.get("event") == "error"]
    assert events and victim_text(run) in str(events[-1]["message"])
    run.pilot.send(op="twist", vx=VX, id="refused")
    run.drive(0.02)
    refused = next(m for m in run.messages() if m.get("id") == "refused")
    assert refused["ok"] is False
    assert refused["error"] == {"code": "feedback_timeout", "message": "gateway is in FAULT: "
                                + run.rig.gw.supervisor.reason}
    run.victim.clear(SimFault.SILENT)
    run.until(GatewayState.RUNNING, within_s=1.5)
    run.drive(1.0)
    assert run.following()


# -- a controller reports a fault -------------------------------------------------------------


@pytest.mark.parametrize("run", DRIVERS, indirect=True)
def test_controller_fault_zeroes_every_wheel_and_recovers(run: Run) -> None:
    t0 = run.inject(SimFault.FAULT)
    samples = run.drive(0.2)
    if run.key == "vesc":
        # STATUS frames carry no fault code: the gateway cannot see it.  The VESC releases
        # the motor by itself, ignores commands for fault_stop_s, then follows again.
        assert all(s.state is GatewayState.RUNNING for s in samples)
        assert not run.victim.model.armed
        # The released wheel may stay off its command long enough for the tracking check
        # (tracking_time_s 0.5 s against the VESC's 0.5 s fault stop): a fault and an
        # automatic recovery then come first.
        run.drive(2.0)
        assert run.following()
        return
    fault = next(s for s in samples if s.state is GatewayState.FAULT)
    assert fault.t - t0 <= reaction_bound(run)
    assert_safe_from(samples, fault)
    reason = run.rig.gw.supervisor.reason
    assert reason.startswith(victim_text(run))
    assert FAULT_DETAIL[run.key] in reason
    run.victim.clear(SimFault.FAULT)  # before the first automatic retry (0.5 s)
    run.until(GatewayState.RUNNING, within_s=1.5)
    run.drive(1.0)
    assert run.following()
    assert run.rig.gw.supervisor.counts.faults == 1


# -- a controller answers late ----------------------------------------------------------------


@pytest.mark.parametrize("run", DRIVERS, indirect=True)
def test_late_answers_below_liveness_are_harmless(run: Run) -> None:
    assert run.victim.latency_s == 0.02  # the default, well below every liveness_s
    run.inject(SimFault.LATE)
    samples = run.drive(2.0)
    assert run.victim.held > 0, "the simulator held nothing back"
    assert all(s.state is GatewayState.RUNNING for s in samples)
    assert run.following()
    run.victim.clear(SimFault.LATE)
    run.drive(0.5)
    assert run.victim.held == 0
    assert run.following()


@pytest.mark.parametrize("run", DRIVERS, indirect=True)
def test_late_answers_above_liveness_fault_then_recover(run: Run) -> None:
    run.victim.latency_s = run.driver.live.liveness_s + 0.15
    t0 = run.inject(SimFault.LATE)
    samples = run.drive(0.5)
    fault = next(s for s in samples if s.state is GatewayState.FAULT)
    assert fault.t - t0 <= reaction_bound(run)
    gap = [s for s in samples if fault.t <= s.t < t0 + run.victim.latency_s]
    assert_safe_from(gap, fault)
    assert f"{victim_text(run)} stopped answering" in run.rig.gw.supervisor.reason
    # The delayed stream flows again and counts as answering: the gateway re-enables.
    run.until(GatewayState.RUNNING, within_s=1.5)
    assert run.victim.held > 0
    run.victim.clear(SimFault.LATE)
    run.drive(1.5)
    assert run.following()


# -- a wheel answers but does not follow ---------------------------------------------------


def assert_tracking_fault(run: Run, samples: list[Sample], start: float) -> None:
    """FAULT with every wheel at zero, the victim named as not following, on socket and CAN."""
    fault = next(s for s in samples if s.state is GatewayState.FAULT)
    tracking_s = run.rig.config.loop.tracking_time_s
    assert start + tracking_s <= fault.t <= start + 4 * tracking_s
    assert_safe_from([s for s in samples if s.t < fault.t + AUTO_RETRY_DELAY_S], fault)
    assert fault.reason.startswith(f"{victim_text(run)} does not follow its "
                                                   "command: ")
    events = [m for m in run.messages() if m.get("event") == "error"]
    assert events and events[0]["code"] == "tracking_error"
    assert victim_text(run) in str(events[0]["message"])
    on_can = [e for e in run.can_errors if e.code is ErrorCode.TRACKING_ERROR]
    assert on_can and on_can[0].wheel == VICTIM


@pytest.mark.parametrize("run", DRIVERS, indirect=True)
def test_wheel_that_stops_following_faults_and_recovers(run: Run) -> None:
    run.pilot.send(op="subscribe", topics=["error"])
    t0 = run.inject(SimFault.STALL)
    samples = run.drive(1.0)  # the fault comes after 0.5 s, the first retry 0.5 s later
    assert run.victim.model.armed, "the device must still read as armed"
    assert_tracking_fault(run, samples, t0)
    run.victim.clear(SimFault.STALL)
    if run.rig.gw.drives.host_speed_loop:
        # DJI: the failed speed loop is wheelgate's own; no automatic re-enable.
        assert all(s.state is GatewayState.FAULT for s in run.drive(2.0))
        run.pilot.send(op="enable")
    run.until(GatewayState.RUNNING, within_s=1.5)
    run.drive(1.0)
    assert run.following()
    assert run.rig.gw.supervisor.counts.faults == 1


@pytest.mark.parametrize("run", [pytest.param(("vesc", {"tracking_time_s": 0.0}), id="vesc")],
                         indirect=True)
def test_tracking_check_off_leaves_a_stalled_wheel_running(run: Run) -> None:
    """The counter-test: with the check disabled, nothing else catches a stalled wheel."""
    run.inject(SimFault.STALL)
    samples = run.drive(1.5)
    assert all(s.state is GatewayState.RUNNING for s in samples)
    assert abs(run.victim.wheel_velocity_rad_s) < 0.1 * abs(run.rig.gw.prev.wheel_rad_s[VICTIM])


@pytest.mark.parametrize("run", ["dji"], indirect=True)
def test_dji_wheel_not_following_on_late_feedback_is_detected_and_released(run: Run) -> None:
    run.pilot.send(op="subscribe", topics=["error"])
    run.victim.latency_s = 0.07  # below liveness_s (0.1 s): the stream never pauses
    t0 = run.inject(SimFault.LATE)
    samples: list[Sample] = []
    for sample in run.drive_iter(4.0):
        samples.append(sample)
        if sample.state is GatewayState.FAULT:
            break
    assert run.rig.gw.supervisor.tracking.worst_ratio > 2.0  # it did oscillate
    samples += run.drive(0.02)
    assert_tracking_fault(run, samples, t0)
    # The host-side speed loop cannot hold zero on this feedback: zero current, and no
    # automatic re-enable into the same loop (it would run away again).
    esc = run.victim
    assert isinstance(esc, DjiSimulator)
    for _ in range(round(3.0 * RATE_HZ)):
        run.drive(1 / RATE_HZ)
        assert run.state is GatewayState.FAULT
        assert esc.command_raw == 0
    run.victim.clear(SimFault.LATE)
    run.pilot.send(op="enable")
    run.until(GatewayState.RUNNING, within_s=1.5)
    run.drive(1.0)
    assert run.following()


@pytest.mark.parametrize("run", ["odrive"], indirect=True)
def test_enable_while_an_odrive_axis_calibrates_keeps_the_loop_alive(run: Run) -> None:
    run.streaming = False
    run.pilot.send(op="disable")
    run.drive(0.5)
    assert run.state is GatewayState.DISABLED
    node = run.victim.motor.node_id
    heartbeat = bytes([0, 0, 0, 0, AxisState.MOTOR_CALIBRATION, 0, 0, 0])  # no error
    send_frames(run.rig.pilot, [Frame(node << 5 | CmdId.HEARTBEAT, heartbeat)])
    run.pilot.send(op="enable")
    run.drive(0.1)
    assert run.rig.gw.supervisor.state is GatewayState.FAULT
    assert run.victim.motor.wheel in run.rig.gw.supervisor.reason


@pytest.mark.parametrize("run", ["odrive"], indirect=True)
def test_an_axis_found_calibrating_when_its_watchdog_setup_ends_is_a_fault(run: Run) -> None:
    # The embedded robot's ODrive 0.6 axes arm only once their watchdog is read back: the
    # arming request comes from the drivers' poll, which meets the calibrating axis there.
    run.streaming = False
    run.pilot.send(op="disable")
    run.drive(0.5)
    node = run.victim.motor.node_id
    heartbeat = bytes([0, 0, 0, 0, AxisState.MOTOR_CALIBRATION, 0, 0, 0])  # no error
    run.pilot.send(op="enable")
    run.drive(2 / RATE_HZ)  # the enable taken, the setup under way
    assert run.rig.gw.supervisor.state is GatewayState.ENABLING
    for _ in range(round(0.5 * RATE_HZ)):
        send_frames(run.rig.pilot, [Frame(node << 5 | CmdId.HEARTBEAT, heartbeat)])
        run.drive(1 / RATE_HZ)
    sup = run.rig.gw.supervisor
    assert sup.state is GatewayState.FAULT
    assert sup.reason.startswith("enable refused: ")
    assert run.victim.motor.wheel in sup.reason and "MOTOR_CALIBRATION" in sup.reason
