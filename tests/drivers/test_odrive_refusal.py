"""The ODrive driver's refusal fault (:meth:`drivers.odrive.axis.Axis.refused`): an axis that
stays IDLE without an error through its CLOSED_LOOP_CONTROL requests becomes a CONTROLLER fault
that says why, until the next enable.

It must never outlive what it claims: the driver gives up only on a heartbeat sent after its
last request (a slow heartbeat must not turn an axis that armed into a refused one), an axis
seen in CLOSED_LOOP_CONTROL is no longer refused, and a real device error that follows is
logged and asked about (Get_Error) like any other, replacing the refusal's text.
"""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING

import pytest

from drivers.odrive import OdriveDriver
from drivers.odrive.axis import Axis
from drivers.odrive.enums import AxisError, AxisState, error_faults
from drivers.odrive.messages import Heartbeat
from drivers.odrive.sim import OdriveSimulator
from gateway.core.types import DriveFault, DriveState
from gateway.sim.device import SimFault
from tests.drivers.odrive_helpers import C6, V06, motor, rig

if TYPE_CHECKING:
    from gateway.core.types import Frame

REFUSAL = (
    "stayed in IDLE after 3 CLOSED_LOOP_CONTROL requests without an error; procedure result "
    "NOT_CALIBRATED (the motor or encoder is not calibrated: with odrivetool, request "
    "FULL_CALIBRATION_SEQUENCE, then keep the result with pre_calibrated and "
    "save_configuration(), as ODrive's Getting Started guide does)"
)


def _hb(state: AxisState, t: float) -> Frame:
    return C6.make_heartbeat(Heartbeat(3, 0, state)).stamped(t)


def _est(t: float) -> Frame:
    return C6.make_encoder_estimates(3, 0.0, 0.0).stamped(t)


# ----------------------------------------------------------------------------- slow heartbeat


def test_a_slow_heartbeat_axis_that_arms_is_never_reported_refused(channel: str) -> None:
    """Heartbeats every 2 s (liveness 5 s): the axis arms at the first request, and the
    driver waits for a heartbeat sent after it instead of retrying and giving up on the one
    from before the enable."""
    sim = OdriveSimulator(motor(3, firmware="0.6", liveness_s=5.0), heartbeat_period_s=2.0)
    with rig(channel, [sim]) as r:
        r.run(0.1)  # the first heartbeat: IDLE
        r.send(r.drv.enable(r.t))
        r.speeds = [1.0]
        seen = []
        for _ in range(45):
            r.run(0.1)
            (status,) = r.drv.status(r.t)
            seen.append((r.t, status.state, status.detail))
        assert AxisState(sim.axis_state) is AxisState.CLOSED_LOOP_CONTROL and sim.model.armed
        assert sim.wheel_velocity_rad_s == pytest.approx(1.0, rel=1e-3)
        faulted = [f"{t:.1f} s: {detail!r}" for t, state, detail in seen
                   if state is DriveState.FAULT]
        assert not faulted, f"FAULT while the axis armed: {faulted[:2]}"
        (status,) = r.drv.status(r.t)
        assert (status.state, status.faults, status.detail) == (
            DriveState.ENABLED, DriveFault.NONE, "")
        assert r.drv.is_armed(0)


def test_retries_and_the_give_up_wait_for_a_heartbeat_after_the_request() -> None:
    """Without a fresh heartbeat the driver neither retries nor gives up; each IDLE heartbeat
    sent after the grace of the last request (not one a few ms after it, which the axis may
    have sent before taking the request) allows the next step."""
    drv = OdriveDriver([motor(3, firmware="0.6", liveness_s=5.0)])
    arm = list(C6.make_transition(3, AxisState.IDLE, AxisState.CLOSED_LOOP_CONTROL))
    drv.on_frame(_hb(AxisState.IDLE, 0.0))
    assert drv.enable(0.0) == arm
    drv.on_frame(_hb(AxisState.IDLE, 0.001))  # sent before the axis took the request
    t = 0.0
    while t < 4.0:  # the encoder estimates keep coming, the heartbeat does not
        t = round(t + 0.01, 2)
        drv.on_frame(_est(t))
        assert drv.poll(t) == [], f"sent at {t} s without a heartbeat after the request"
    assert drv.state(0, t) is DriveState.ENABLING
    for attempt_s in (4.0, 6.0):  # a heartbeat after the request: the next attempt
        drv.on_frame(_hb(AxisState.IDLE, attempt_s))
        drv.on_frame(_est(attempt_s))
        assert drv.poll(attempt_s) == arm
        assert drv.poll(attempt_s + 1.0) == []
    drv.on_frame(_hb(AxisState.IDLE, 8.0))
    drv.on_frame(_est(8.0))
    assert drv.poll(8.0) == []  # the third request was not answered: give up
    assert (drv.state(0, 8.0), drv.detail(0)) == (
        DriveState.FAULT,
        f"stayed in IDLE after {Axis.ENABLE_ATTEMPTS} CLOSED_LOOP_CONTROL requests without "
        f"an error")


def test_an_axis_seen_armed_after_a_refusal_is_no_longer_refused(channel: str) -> None:
    """The refusal says the axis stayed IDLE: a heartbeat in CLOSED_LOOP_CONTROL (armed by
    another host after a calibration, say) ends it, and the motor reports ENABLED."""
    sim = OdriveSimulator(motor(3, firmware="0.6"), calibrated=False)
    with rig(channel, [sim]) as r:
        r.send(r.drv.enable(r.t))
        r.run(2.5)
        (status,) = r.drv.status(r.t)
        assert (status.state, status.faults, status.detail) == (
            DriveState.FAULT, DriveFault.CONTROLLER, REFUSAL)
        sim.calibrated = True  # calibrated with odrivetool, which also arms the axis
        r.send([r.drv.codec.make_set_axis_state(3, AxisState.CLOSED_LOOP_CONTROL)])
        r.run(0.3)
        assert AxisState(sim.axis_state) is AxisState.CLOSED_LOOP_CONTROL
        (status,) = r.drv.status(r.t)
        assert (status.state, status.faults, status.detail) == (
            DriveState.ENABLED, DriveFault.NONE, "")


# ----------------------------------------------------------------------------- a real fault


def test_a_device_fault_after_a_refusal_is_logged_and_asked_about(
    channel: str, caplog: pytest.LogCaptureFixture
) -> None:
    """The refused (uncalibrated) axis then latches DRV_FAULT: the driver warns, asks for
    Get_Error, and the detail is the device's error and disarm reason, not the refusal (which
    said "without an error")."""
    sim = OdriveSimulator(motor(3, firmware="0.6"), calibrated=False)
    with rig(channel, [sim]) as r:
        r.send(r.drv.enable(r.t))
        r.run(2.5)
        assert r.drv.status(r.t)[0].detail == REFUSAL
        caplog.clear()
        with caplog.at_level(logging.WARNING, logger="drivers.odrive"):
            sim.inject(SimFault.FAULT)
            r.run(1.0)
        assert (AxisState(sim.axis_state), sim.axis_error) == (
            AxisState.IDLE, int(AxisError.DRV_FAULT))
        (status,) = r.drv.status(r.t)
        assert status.state is DriveState.FAULT
        assert status.faults == error_faults(V06, AxisError.DRV_FAULT)
        assert status.detail == "axis error 0x00000020: DRV_FAULT; disarm reason: NONE"
        assert [m.getMessage() for m in caplog.records] == [
            'ODrive node 3 ("left") reports axis error 0x00000020: DRV_FAULT']
