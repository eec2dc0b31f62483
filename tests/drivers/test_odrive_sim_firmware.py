"""Firmware quirks of the simulated ODrive axis (:mod:`drivers.odrive.sim`,
:mod:`drivers.odrive.sim_rules`), on the virtual bus, and what the driver makes of them.

Each behaviour follows the 0.5.6 firmware (odriverobotics/ODrive, tag fw-v0.5.6):
``Firmware/MotorControl/main.cpp`` checks the watchdog in every state;
``Firmware/communication/can/can_simple.cpp`` ignores heartbeat requests;
``Firmware/MotorControl/axis.cpp`` refuses CLOSED_LOOP_CONTROL to an uncalibrated axis; a NaN
input reaches ``foc.cpp``'s MODULATION_IS_NAN through ``controller.cpp``, which clamps an
infinity to ``vel_limit``.
"""

from __future__ import annotations

import math
import struct
import time
from typing import cast

import can
import pytest

from drivers.odrive.codec import OdriveCodec
from drivers.odrive.enums import AxisState, CmdId, Firmware, ProcedureResult
from drivers.odrive.messages import Heartbeat
from drivers.odrive.sim import OdriveSimulator, simulator_for
from drivers.odrive.sim_rules import FACTORY_VEL_LIMIT_TURNS_S
from gateway.bus.can_bus import drain, send_frames
from gateway.core.types import DriveFault, DriveState, Frame
from gateway.sim.bus import SimulatedControllers
from tests.drivers.odrive_helpers import ENDPOINTS, TAU, motor, rig


def nan_vel(node: int) -> Frame:
    """Set_Input_Vel with a NaN speed, as ``cansend`` would put ``pack('<ff', nan, 0)``."""
    return Frame(node << 5 | CmdId.SET_INPUT_VEL, struct.pack("<ff", math.nan, 0.0))


# ----------------------------------------------------------------------------- watchdog


def test_a_saved_0_5_watchdog_latches_in_idle_and_the_enable_clears_it(channel: str) -> None:
    """0.5 ``main.cpp`` runs ``Axis::watchdog_check`` every control loop whatever the state:
    an axis with its watchdog saved, fed at boot and then by nobody, reports 0x800 while IDLE.
    The driver's enable starts with Clear_Errors, which feeds the watchdog before it clears
    (``do_command`` feeds first), so the axis arms."""
    sim = cast("OdriveSimulator", simulator_for(motor(3, firmware="0.5", controller_timeout_s=0.2)))
    with rig(channel, [sim]) as r:
        r.run(0.15, talk=False)
        assert sim.axis_error == 0  # within the timeout of the boot feed
        r.run(0.35, talk=False)  # nobody talks to the axis
        assert (sim.axis_state, sim.axis_error) == (AxisState.IDLE, 0x800)
        (status,) = r.drv.status(r.t)
        assert (status.state, status.faults) == (DriveState.FAULT, DriveFault.WATCHDOG)
        assert status.detail == "axis error 0x00000800: WATCHDOG_TIMER_EXPIRED"
        r.send(r.drv.enable(r.t))
        r.speeds = [1.0]
        r.run(0.5)
        assert (sim.axis_state, sim.axis_error) == (AxisState.CLOSED_LOOP_CONTROL, 0)
        assert r.drv.status(r.t)[0].state is DriveState.ENABLED
        assert sim.wheel_velocity_rad_s == pytest.approx(1.0, rel=1e-3)


# ----------------------------------------------------------------------------- requests


def test_a_0_5_axis_ignores_a_heartbeat_request(channel: str) -> None:
    """``061#R`` (and its DLC 0 form) gets no heartbeat from 0.5 (``do_command``, case
    MSG_ODRIVE_HEARTBEAT: "We don't currently do anything to respond"), while the encoder
    estimates request on the same bus is answered."""
    sim = OdriveSimulator(motor(3, firmware="0.5"), heartbeat_period_s=100.0, encoder_period_s=0.0)
    with rig(channel, [sim]) as r:
        r.ctl.step(0.001)  # the first cyclic heartbeat goes out at start
        assert [f.arbitration_id for f in drain(r.gw)] == [0x061]
        codec = OdriveCodec(Firmware.V0_5)
        send_frames(r.gw, [Frame(0x061, is_remote_frame=True), Frame(0x061, b""),
                           codec.make_request(3, CmdId.GET_ENCODER_ESTIMATES)])
        r.ctl.step(0.002)
        assert [f.arbitration_id for f in drain(r.gw)] == [0x069]


# ----------------------------------------------------------------------------- calibration


@pytest.mark.parametrize(("firmware", "error", "result"), [
    ("0.5", 0x1, ProcedureResult.SUCCESS),  # no procedure result in the 0.5 heartbeat
    ("0.6", 0x0, ProcedureResult.NOT_CALIBRATED),
])
def test_an_uncalibrated_axis_refuses_closed_loop_control(
    channel: str, firmware: str, error: int, result: ProcedureResult
) -> None:
    """The factory axis is not calibrated: 0.5 latches INVALID_STATE (``axis.cpp``), 0.6 says
    NOT_CALIBRATED in the heartbeat's procedure result; both stay in IDLE."""
    sim = OdriveSimulator(motor(3, firmware=firmware), calibrated=False)
    codec = OdriveCodec(Firmware(firmware))
    with rig(channel, [sim]) as r:
        send_frames(r.gw, [codec.make_set_axis_state(3, AxisState.CLOSED_LOOP_CONTROL)])
        heard = []
        for k in range(1, 300):
            r.ctl.step(k / 1000)
            heard += [codec.decode(f) for f in drain(r.gw) if f.arbitration_id == 0x061]
        assert not sim.model.armed
        last = heard[-1]
        assert isinstance(last, Heartbeat)
        assert (last.axis_state, last.axis_error, last.procedure_result) == (
            AxisState.IDLE, error, result)


def test_enabling_an_uncalibrated_0_5_axis_ends_in_a_fault(channel: str) -> None:
    """The driver's enable meets INVALID_STATE: FAULT, never armed, and the detail names the
    firmware's flag and, since the flag does not itself say "not calibrated", what it most
    often means after a closed-loop request."""
    sim = OdriveSimulator(motor(3, firmware="0.5"), calibrated=False)
    with rig(channel, [sim]) as r:
        r.send(r.drv.enable(r.t))
        r.speeds = [1.0]
        r.run(2.0)
        assert sim.axis_state is AxisState.IDLE and not sim.model.armed
        (status,) = r.drv.status(r.t)
        assert (status.state, status.faults) == (DriveState.FAULT, DriveFault.CONTROLLER)
        assert status.detail == (
            "axis error 0x00000001: INVALID_STATE; the axis refused the state requested: for "
            "CLOSED_LOOP_CONTROL most often a motor or encoder not calibrated (with odrivetool: "
            "request FULL_CALIBRATION_SEQUENCE, set motor.config.pre_calibrated and "
            "encoder.config.pre_calibrated, save_configuration())")


def test_enabling_an_uncalibrated_0_6_axis_ends_in_a_fault_that_says_why(channel: str) -> None:
    m = motor(3, firmware="0.6", controller_timeout_s=0.25, watchdog_endpoints=ENDPOINTS)
    sim = cast("OdriveSimulator", simulator_for(m))
    sim.calibrated = False
    with rig(channel, [sim]) as r:
        r.send(r.drv.enable(r.t))
        r.speeds = [1.0]
        r.run(2.5)
        assert sim.axis_state is AxisState.IDLE
        (status,) = r.drv.status(r.t)
        assert status.state is DriveState.FAULT
        assert status.detail == (
            "stayed in IDLE after 3 CLOSED_LOOP_CONTROL requests without an error; procedure "
            "result NOT_CALIBRATED (the motor or encoder is not calibrated: with odrivetool, "
            "request FULL_CALIBRATION_SEQUENCE, then keep the result with pre_calibrated and "
            "save_configuration(), as ODrive's Getting Started guide does)")
        r.run(1.0)  # the axis' healthy heartbeats keep the refusal until the next enable
        assert r.drv.status(r.t)[0].state is DriveState.FAULT
        sim.calibrated = True  # calibrated meanwhile: the next enable arms it
        r.send(r.drv.enable(r.t))
        r.run(1.5)
        assert AxisState(sim.axis_state) is AxisState.CLOSED_LOOP_CONTROL  # (read anew)
        assert r.drv.status(r.t)[0].state is DriveState.ENABLED


# ----------------------------------------------------------------------------- non-finite


@pytest.mark.parametrize(
    ("firmware", "detail"),
    [
        ("0.5", "axis error 0x00000040: MOTOR_FAILED; motor error flag; "
                "motor error 0x10000: MODULATION_IS_NAN"),
        ("0.6", "axis error 0x00000002: SYSTEM_LEVEL; disarm reason: SYSTEM_LEVEL"),
    ],
)
def test_a_nan_speed_faults_the_axis_and_the_simulator_survives(
    channel: str, firmware: str, detail: str
) -> None:
    """A NaN Set_Input_Vel (0x02D for node 1) reaches the armed controller: the axis disarms
    with MODULATION_IS_NAN (0.5; 0.6 assumed), and keeps answering; the next enable (with the
    driver's finite speeds) arms it again."""
    sim = OdriveSimulator(motor(1, firmware=firmware))
    with rig(channel, [sim]) as r:
        r.send(r.drv.enable(r.t))
        r.speeds = [1.0]
        r.run(0.5)
        assert r.state() is DriveState.ENABLED
        r.send([nan_vel(1)])
        r.run(0.5)  # the rig steps the simulators: an exception would end the test here
        assert sim.axis_state is AxisState.IDLE and not sim.model.armed
        (status,) = r.drv.status(r.t)
        assert status.state is DriveState.FAULT
        assert status.detail == detail
        fb = r.drv.feedback(0)
        assert fb is not None and math.isfinite(fb.position_rad) and fb.timestamp_s > r.t - 0.05
        r.send(r.drv.enable(r.t))
        r.run(0.5)
        assert r.state() is DriveState.ENABLED


def test_a_nan_taken_in_idle_faults_the_axis_when_armed(channel: str) -> None:
    """The controller keeps ``input_vel_`` over the arming (only the setpoints are reset):
    a NaN sent to the idle axis faults it at its first closed-loop step."""
    sim = OdriveSimulator(motor(1, firmware="0.5"))
    with rig(channel, [sim]) as r:
        r.send([nan_vel(1)])
        r.run(0.2, talk=False)
        assert (sim.axis_state, sim.axis_error) == (AxisState.IDLE, 0)  # waits in IDLE
        codec = r.drv.codec
        r.send([codec.make_set_controller_mode(1, 2, 1),  # velocity control, passthrough
                codec.make_set_axis_state(1, AxisState.CLOSED_LOOP_CONTROL)])
        r.run(0.2, talk=False)
        assert (sim.axis_state, sim.axis_error, sim.motor_error) == (AxisState.IDLE, 0x40, 0x10000)


def test_an_infinite_speed_runs_at_the_factory_vel_limit(channel: str) -> None:
    """``std::clamp`` to ``vel_limit`` takes an infinity (0.5 ``controller.cpp``): no fault."""
    sim = OdriveSimulator(motor(1, firmware="0.5"))
    with rig(channel, [sim]) as r:
        r.send(r.drv.enable(r.t))
        r.run(0.3)
        r.send([Frame(0x02D, struct.pack("<ff", -math.inf, 0.0))])
        r.run(0.3, talk=False)
        assert (sim.axis_state, sim.axis_error) == (AxisState.CLOSED_LOOP_CONTROL, 0)
        assert sim.model.velocity_rad_s == pytest.approx(-FACTORY_VEL_LIMIT_TURNS_S * TAU)


def test_the_simulator_thread_survives_a_nan_frame(channel: str) -> None:
    """The reported crash, as ``--sim`` runs it: the background thread stepping the axis."""
    sim = OdriveSimulator(motor(1, firmware="0.5"))
    codec = OdriveCodec(Firmware.V0_5)
    host = can.Bus(interface="virtual", channel=channel)
    try:
        with SimulatedControllers([sim], channel).start() as ctl:
            send_frames(host, [codec.make_set_controller_mode(1, 2, 1),
                               codec.make_set_axis_state(1, AxisState.CLOSED_LOOP_CONTROL),
                               codec.make_set_input_vel(1, 1.0)])
            deadline = time.monotonic() + 2.0
            while not ctl.snapshot(lambda: sim.model.armed) and time.monotonic() < deadline:
                time.sleep(0.01)
            send_frames(host, [nan_vel(1)])
            while not ctl.snapshot(lambda: sim.axis_error) and time.monotonic() < deadline:
                time.sleep(0.01)
            time.sleep(0.05)
            assert ctl.is_alive() and ctl.failure is None
            assert ctl.snapshot(lambda: (sim.axis_error, sim.motor_error)) == (0x40, 0x10000)
    finally:
        host.shutdown()
