"""Tests of the ODrive CANSimple driver and simulator on a virtual bus: drive, fault, recovery and
silence, the watchdog, e-stop, RTR encoder requests, extended IDs, float32 positions."""

from __future__ import annotations

from typing import cast

import pytest

from drivers.odrive import OdriveDriver
from drivers.odrive.enums import (
    InputMode,
)
from drivers.odrive.messages import (
    Heartbeat,
)
from drivers.odrive.sim import OdriveSimulator, simulator_for
from gateway.core.types import DriveFault, DriveState
from gateway.sim.device import SimFault
from tests.drivers.odrive_helpers import ENDPOINTS, TAU, motor, rig


@pytest.mark.parametrize("firmware", ["0.5", "0.6"])
def test_bus_drive_fault_recover_silence(channel: str, firmware: str) -> None:
    sims = [
        OdriveSimulator(motor(3, gear_ratio=4.0, invert=True, firmware=firmware)),
        OdriveSimulator(motor(4, "right", gear_ratio=4.0, firmware=firmware)),
    ]
    with rig(channel, sims) as r:
        r.send(r.drv.enable(r.t))
        r.run(0.3)
        assert [r.state(0), r.state(1)] == [DriveState.ENABLED] * 2
        r.speeds = [3.0, -2.0]
        r.run(1.0)
        for i, sim in enumerate(sims):
            fb = r.drv.feedback(i)
            assert fb is not None
            assert fb.velocity_rad_s == pytest.approx(r.speeds[i], rel=1e-3)
            assert sim.wheel_velocity_rad_s == pytest.approx(r.speeds[i], rel=1e-3)
        r.speeds = [0.0, 0.0]
        r.run(0.3)
        for i, sim in enumerate(sims):
            fb = r.drv.feedback(i)
            assert fb is not None
            assert abs(sim.wheel_position_rad) > 1.9
            assert fb.position_rad == pytest.approx(sim.wheel_position_rad, abs=1e-5)

        sims[0].inject(SimFault.FAULT)
        r.run(0.3)
        (left, right) = r.drv.status(r.t)
        assert (left.state, right.state) == (DriveState.FAULT, DriveState.ENABLED)
        assert DriveFault.MOTOR in left.faults
        if firmware == "0.6":
            assert left.detail == "axis error 0x00000020: DRV_FAULT; disarm reason: DRV_FAULT"
        else:
            assert left.detail.startswith("axis error 0x00000040: MOTOR_FAILED; motor error flag")
            assert left.detail.endswith("motor error 0x8: DRV_FAULT")
        r.send(r.drv.enable(r.t))  # the cause is still there: the axis faults again
        r.run(1.0)
        assert r.state(0) is DriveState.FAULT
        sims[0].clear(SimFault.FAULT)
        r.send(r.drv.enable(r.t))
        r.run(0.3)
        assert [r.state(0), r.state(1)] == [DriveState.ENABLED] * 2

        sims[1].inject(SimFault.SILENT)
        r.run(0.3)
        assert [r.state(0), r.state(1)] == [DriveState.ENABLED, DriveState.OFFLINE]
        r.send(r.drv.disable(r.t))
        r.run(0.2)
        assert r.state(0) is DriveState.DISABLED


@pytest.mark.parametrize(("firmware", "bit"), [("0.5", 0x800), ("0.6", 0x01000000)])
def test_bus_watchdog(channel: str, firmware: str, bit: int) -> None:
    if firmware == "0.5":
        # A 0.5 axis whose watchdog was set and saved with odrivetool, as the block states.
        m = motor(3, firmware=firmware, controller_timeout_s=0.5)
    else:  # the gateway sets it over CAN on an axis at factory settings
        m = motor(3, firmware=firmware, controller_timeout_s=0.5, watchdog_endpoints=ENDPOINTS)
    with rig(channel, [cast("OdriveSimulator", simulator_for(m))]) as r:
        r.send(r.drv.enable(r.t))
        r.speeds = [1.0]
        r.run(1.0)  # velocity commands at 100 Hz keep feeding the watchdog
        assert r.state() is DriveState.ENABLED
        r.run(0.7, talk=False)  # the host stops talking
        (status,) = r.drv.status(r.t)
        assert (status.state, status.faults) == (DriveState.FAULT, DriveFault.WATCHDOG)
        assert status.detail.startswith(f"axis error {bit:#010x}: WATCHDOG_TIMER_EXPIRED")


def test_bus_estop(channel: str) -> None:
    with rig(channel, [OdriveSimulator(motor(3))]) as r:
        r.send(r.drv.enable(r.t))
        r.run(0.2)
        r.send([r.drv.codec.make_estop(3)])
        r.run(0.2)
        assert r.drv.status(r.t)[0].faults == DriveFault.ESTOP


@pytest.mark.parametrize(("request_mode", "expected"), [("rtr", True), ("cyclic", False)])
def test_bus_rtr_encoder_requests(channel: str, request_mode: str, expected: bool) -> None:
    sim = OdriveSimulator(motor(3, encoder_request=request_mode), encoder_period_s=0.0)
    with rig(channel, [sim]) as r:
        r.run(0.3)
        assert (r.drv.feedback(0) is not None) is expected
        assert r.state() is (DriveState.DISABLED if expected else DriveState.OFFLINE)


def test_bus_extended_ids_and_vel_ramp(channel: str) -> None:
    """Needs a kinder device than the factory's: it commands 10 turn/s and expects them
    reached, while the 0.5 factory ``controller.config.vel_limit`` is 2 turn/s (and
    ``vel_ramp_rate`` 1 turn/s^2), in odriverobotics/ODrive
    ``Firmware/MotorControl/controller.hpp``.  A real robot's are set with odrivetool; the
    simulator limits no finite speed and ramps at its own ``vel_ramp_rate_turns_s2`` (20
    turn/s^2 by default)."""
    sim = OdriveSimulator(motor(0xFEDCBA, extended_id=True, input_mode=2))
    with rig(channel, [sim]) as r:
        r.send(r.drv.enable(r.t))
        r.run(0.2)
        assert r.state() is DriveState.ENABLED
        assert sim.input_mode == InputMode.VEL_RAMP
        r.speeds = [10 * TAU]  # 10 turns/s, ramped at 20 turns/s^2
        r.run(0.1)
        assert 1.5 < sim.setpoint_turns_s <= 2.0 + 1e-9
        r.run(0.6)
        assert sim.setpoint_turns_s == pytest.approx(10.0)
    other = OdriveDriver([motor(0x3E)])  # an 11-bit driver on the same bus ignores them
    assert other.on_frame(sim.codec.make_heartbeat(Heartbeat(0x3E, 0, 1))) is False


def test_bus_float32_position_precision(channel: str) -> None:
    """Far from zero the firmware's float32 position costs resolution; nothing else does."""
    start = 2.0**20  # ULP = 2**(20 - 23) = 0.125 turn
    sims = [
        OdriveSimulator(motor(3), initial_position_turns=start),
        OdriveSimulator(motor(4, "right"), initial_position_turns=0.3),
    ]
    with rig(channel, sims) as r:
        r.send(r.drv.enable(r.t))
        r.speeds = [1.37, 1.37]
        r.run(1.0)
        r.speeds = [0.0, 0.0]
        r.run(0.3)
        errors = []
        for i, sim in enumerate(sims):
            fb = r.drv.feedback(i)
            assert fb is not None
            errors.append(abs(fb.position_rad - sim.wheel_position_rad))
        assert errors[0] <= 0.125 * TAU  # at most one ULP (two half-ULP roundings)
        assert errors[0] > 1e-3  # the loss is real at 2**20 turns ...
        assert errors[1] < 1e-6  # ... and negligible near zero
