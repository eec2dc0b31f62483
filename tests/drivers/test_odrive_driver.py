"""Tests of the ODrive CANSimple driver without a bus: the transition table, error flags,
configuration, command conversion, frames in, liveness, the enable sequence and faults."""

from __future__ import annotations

import itertools
import math
import struct
from typing import Any

import pytest

from drivers.odrive import OdriveDriver
from drivers.odrive.axis import Axis
from drivers.odrive.codec import OdriveCodec
from drivers.odrive.enums import (
    AXIS_ERROR_05_FAULTS,
    AXIS_ERROR_FAULTS,
    AxisError,
    AxisError05,
    AxisState,
    CmdId,
    InputMode,
    error_faults,
)
from drivers.odrive.messages import (
    ErrorStatus,
    Heartbeat,
    MotorErrorStatus,
)
from drivers.odrive.sim import OdriveSimulator, simulator_for
from gateway.core.errors import ConfigError, EncodeError, IllegalTransitionError
from gateway.core.types import DriveFault, DriveState, Frame, MotorConfig
from gateway.drive.claims import FrameClaim
from gateway.drive.registry import get_driver_class
from tests import factories
from tests.drivers.odrive_helpers import C5, C6, TAU, V05, V06, hx, motor

# ----------------------------------------------------------------------------- tables


ARMABLE = {AxisState.UNDEFINED, AxisState.IDLE, AxisState.CLOSED_LOOP_CONTROL}


@pytest.mark.parametrize(("current", "requested"), list(itertools.product(AxisState, AxisState)))
def test_transition_table(current: AxisState, requested: AxisState) -> None:
    codec = OdriveCodec(V06)
    if requested is AxisState.IDLE:
        assert codec.make_transition(5, current, requested) == (
            Frame(0x0AD, bytes(8)),
            Frame(0x0A7, hx("01000000 00000000")),
        )
    elif requested is AxisState.CLOSED_LOOP_CONTROL and current in ARMABLE:
        assert codec.make_transition(5, current, requested, InputMode.VEL_RAMP) == (
            Frame(0x0B8, hx("00")),
            Frame(0x0AB, hx("02000000 02000000")),
            Frame(0x0A7, hx("08000000 00000000")),
        )
    else:
        with pytest.raises(IllegalTransitionError, match=f"node 5 .* in {current.name}"):
            codec.make_transition(5, current, requested)


def test_transition_from_unknown_state() -> None:
    assert len(C6.make_transition(5, 42, AxisState.IDLE)) == 2
    with pytest.raises(IllegalTransitionError, match="it is in 42"):
        C6.make_transition(5, 42, AxisState.CLOSED_LOOP_CONTROL)


def test_error_flags_map_onto_drive_faults() -> None:
    assert set(AXIS_ERROR_FAULTS) == {f for f in AxisError if f}
    assert set(AXIS_ERROR_05_FAULTS) == {f for f in AxisError05 if f}
    assert error_faults(V06, AxisError.WATCHDOG_TIMER_EXPIRED) == DriveFault.WATCHDOG
    assert error_faults(V06, 0x02000000) == DriveFault.ESTOP
    assert error_faults(V05, 0x800) == DriveFault.WATCHDOG
    assert error_faults(V06, 0x800) == DriveFault.OVER_CURRENT  # same bit, other meaning
    assert error_faults(V06, 0x20000000 | 0x20) == DriveFault.OTHER | DriveFault.MOTOR
    assert error_faults(V05, 0) == DriveFault.NONE


# ----------------------------------------------------------------------------- driver (no bus)


def test_registry_and_config() -> None:
    assert get_driver_class("odrive") is OdriveDriver
    drv = OdriveDriver([motor(3), motor(4, "right")])
    assert (drv.codec.firmware, drv.codec.extended_id, drv.live.liveness_s) == (V06, False, 0.25)
    assert OdriveDriver([motor(3, liveness_s=0.5)]).live.liveness_s == 0.5
    assert OdriveDriver([motor(0xFEDCBA, extended_id=True)]).codec.max_node_id == 0xFFFFFF
    OdriveDriver.validate_node_id(0xFFFFFF, "x", {"extended_id": True})
    with pytest.raises(ConfigError, match=r"^x: expected int 0..16777215, got 16777216$"):
        OdriveDriver.validate_node_id(0x1000000, "x", {"extended_id": True})
    sim = simulator_for(motor(3, firmware="0.5"))
    assert isinstance(sim, OdriveSimulator)
    assert sim.codec.firmware is V05
    assert (sim.heartbeat_period_s, sim.encoder_period_s) == (0.1, 0.01)  # the factory's
    sim = simulator_for(motor(3, heartbeat_msg_rate_ms=50, encoder_msg_rate_ms=0,
                              encoder_request="rtr"))
    assert isinstance(sim, OdriveSimulator)
    assert (sim.heartbeat_period_s, sim.encoder_period_s) == (0.05, 0.0)  # as the block states
    assert OdriveDriver([motor(3, heartbeat_msg_rate_ms=200, liveness_s=0.4)]).opts[0] \
        .heartbeat_msg_rate_ms == 200
    with pytest.raises(ConfigError, match=r"firmware: expected one of '0.5', '0.6', got 5"):
        OdriveSimulator(motor(3, validate=False, firmware=5))


@pytest.mark.parametrize(
    ("motors", "message"),
    [
        (
            [motor(3, validate=False, firmware="0.7")],
            r"motor 'left'.firmware: expected one of '0.5', '0.6'",
        ),
        ([motor(3, validate=False, speed=1)], r"motor 'left'.speed: unknown key"),
        ([motor(3, validate=False, input_mode=3)], r"input_mode: expected one of 1, 2, got 3"),
        (
            [motor(3), motor(4, "right", firmware="0.5")],
            r"^motor 'right'.firmware: expected '0.6' like motor 'left' on the same ODrive bus, "
            r"got '0.5'$",
        ),
        (
            [motor(3), motor(4, "right", extended_id=True)],
            r"'right'.extended_id: expected False like motor 'left' .* got True$",
        ),
        (  # one liveness per bus: the second motor's would be ignored
            [motor(3), motor(4, "right", liveness_s=0.5)],
            r"'right'.liveness_s: expected 0.25 like motor 'left' .* got 0.5$",
        ),
        (
            [motor(3, firmware="0.5", watchdog_endpoints={"fw_version": "0.5.6",
                                                          "enable_watchdog": 1,
                                                          "watchdog_timeout": 2})],
            r"flat_endpoints/watchdog_endpoints: expected firmware 0.6 .* got firmware 0.5$",
        ),
        ([motor(0x3F)], r"node_id: expected int 0..62, got 63"),
        ([motor(0xFEDCBA)], r"node_id: expected int 0..62, got 16702650"),
        (
            [motor(3), motor(3, "right")],
            r"'right'.node_id: node 3 is already used by wheel 'left'",
        ),
        (  # the cyclic estimates the driver reads, turned off
            [motor(3, validate=False, encoder_msg_rate_ms=0)],
            r"^motor 'left'.encoder_msg_rate_ms: expected the period \(ms\) of the cyclic "
            r"estimates the driver reads \(encoder_request: cyclic\), or encoder_request: rtr; "
            r"got 0$",
        ),
        (  # a heartbeat every 200 ms: the default liveness_s (0.25 s) would flap
            [motor(3, validate=False, heartbeat_msg_rate_ms=200)],
            r"^motor 'left'.liveness_s: expected at least two periods of the heartbeat "
            r"\(200 ms\) and the estimates \(10 ms\), 0.4 s, or one late frame makes the "
            r"motor OFFLINE; got 0.25$",
        ),
        (
            [motor(3, validate=False, encoder_request="rtr", encoder_msg_rate_ms=0,
                   liveness_s=0.15)],
            r"liveness_s: expected at least two periods of the heartbeat \(100 ms\), 0.2 s",
        ),
    ],
)
def test_config_errors(motors: list[MotorConfig], message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        OdriveDriver(motors)


def test_the_periods_are_checked_with_the_block_that_states_them() -> None:
    # As the loader checks a motor block (every problem of the file, each at its key path).
    with pytest.raises(ConfigError, match=r"^robot.yaml: motors.left.liveness_s: expected at "
                                          r"least two periods of the heartbeat \(500 ms\)"):
        OdriveDriver.validate_options({"heartbeat_msg_rate_ms": 500}, "robot.yaml: motors.left")
    assert OdriveDriver.validate_options(
        {"heartbeat_msg_rate_ms": 500, "liveness_s": 1.0}, "x")["heartbeat_msg_rate_ms"] == 500


def test_a_speed_beyond_float32_is_an_encode_error_not_an_overflow() -> None:
    drv = OdriveDriver([factories.motor("odrive", 3, max_rpm=1e300)])
    with pytest.raises(EncodeError, match=r"^Expected Input_Vel within float32 in turns/s"):
        drv.command([1e40], 0.0)
    assert drv.command([1.0], 0.0)[0].data[:4] == struct.pack("<f", 1.0 / TAU)


def test_command_conversion_and_limits() -> None:
    drv = OdriveDriver([motor(3, gear_ratio=4.0, invert=True), motor(4, "right")])
    # 5*pi rad/s at the wheel * 4 * -1 / (2*pi) = -10 turns/s at the motor.
    assert drv.command([5 * math.pi, 0.0], 0.0) == [
        Frame(0x06D, hx("00 00 20 C1 00 00 00 00")),
        Frame(0x08D, bytes(8)),
    ]
    with pytest.raises(EncodeError) as err:
        drv.command([0.0, 400.0], 0.0)
    expected = (
        'Expected a wheel speed for ODrive node 4 ("right") between -314.159 and 314.159 rad/s '
        "(max_rpm 3000), but got 400.0."
    )
    assert str(err.value) == expected
    with pytest.raises(EncodeError, match="but got nan"):
        drv.command([math.nan, 0.0], 0.0)
    with pytest.raises(
        EncodeError, match=r"^Expected 2 setpoints for the ODrive motors \(left, right\), but got 1"
    ):
        drv.command([0.0], 0.0)


def _hb(codec: OdriveCodec, state: AxisState, error: int = 0, t: float = 0.0, **kw: Any) -> Frame:
    frame = codec.make_heartbeat(Heartbeat(3, error, state, **kw))
    return frame.stamped(t)


def _est(codec: OdriveCodec, pos: float, t: float) -> Frame:
    return codec.make_encoder_estimates(3, pos, 0.0).stamped(t)


def test_on_frame_ownership_and_rejects() -> None:
    drv = OdriveDriver([motor(3)])
    assert drv.on_frame(C6.make_heartbeat(Heartbeat(4, 0, AxisState.IDLE))) is False
    assert drv.on_frame(Frame(0x061, bytes(8), is_extended_id=True)) is False  # e.g. VESC
    assert drv.on_frame(C6.make_set_input_vel(3, 1.0)) is True  # another master: ignored
    assert not drv.rejected
    assert drv.on_frame(Frame(0x061, bytes(7))) is True
    assert drv.on_frame(Frame(0x069, is_remote_frame=True)) is True
    assert sum(drv.rejected.values()) == 2
    assert drv.rejected["remote frame where data expected"] == 1
    assert drv.state(0, 0.0) is DriveState.OFFLINE
    rtr = OdriveDriver([motor(3, encoder_request="rtr")])
    for cmd in (CmdId.GET_ENCODER_ESTIMATES, CmdId.GET_ERROR):  # echoes of its own requests
        assert rtr.on_frame(C6.make_request(3, cmd)) is True
    assert not rtr.rejected


def test_claims_and_message_names() -> None:
    """Every CANSimple identifier of our nodes (the command bits open), by motor; the names
    the monitor shows (the command's name, or its number)."""
    drv = OdriveDriver([motor(3), motor(4, "right")])
    assert drv.claims() == (
        FrameClaim(0x060, 0x7E0, False, 0),
        FrameClaim(0x080, 0x7E0, False, 1),
    )
    assert [str(f) for f in drv.receive_filters()] == ["060/7E0", "080/7E0"]
    assert drv.message_name(0x069, False) == "Get_Encoder_Estimates"
    assert drv.message_name(0x081, False) == "Heartbeat"
    assert drv.message_name(0x064, False) == "cmd 0x04"  # RxSdo: no CmdId of its own
    assert drv.message_name(0x0A9, False) is None  # node 5 is not ours
    assert drv.message_name(0x069, True) is None  # nor the other ID type
    ext = OdriveDriver([motor(0xFEDCBA, extended_id=True)])
    assert ext.claims() == (FrameClaim(0xFEDCBA << 5, 0x1FFFFFE0, True, 0),)
    assert ext.claims()[0].matches(0x1FDB974D, True)  # its Set_Input_Vel (golden "ext")
    assert ext.message_name(0x1FDB974D, True) == "Set_Input_Vel"


def test_state_liveness_and_enable_handshake() -> None:
    drv = OdriveDriver([motor(3)])
    drv.on_frame(_hb(C6, AxisState.IDLE, t=1.0))
    assert drv.state(0, 1.0) is DriveState.OFFLINE  # no encoder estimates yet
    drv.on_frame(_est(C6, 7.25, 1.0))
    drv.on_frame(_est(C6, 7.75, 1.01))
    assert drv.state(0, 1.01) is DriveState.DISABLED
    fb = drv.feedback(0)
    assert fb is not None
    assert (fb.position_rad, fb.timestamp_s) == (0.5 * TAU, 1.01)
    assert len(drv.enable(1.02)) == 3
    assert drv.state(0, 1.02) is DriveState.ENABLING
    drv.on_frame(_hb(C6, AxisState.CLOSED_LOOP_CONTROL, t=1.1))
    assert drv.state(0, 1.1) is DriveState.ENABLED
    assert drv.state(0, 1.27) is DriveState.OFFLINE  # estimates 0.26 s old
    assert drv.live.silent(0, 1.27) == ["encoder estimates"]
    drv.on_frame(_est(C6, 7.75, 1.3))
    assert drv.state(0, 1.3) is DriveState.ENABLED
    assert drv.state(0, 1.36) is DriveState.OFFLINE  # the heartbeat is 0.26 s old
    assert drv.live.silent(0, 1.36) == ["heartbeat"]
    assert drv.disable(1.3) == list(C6.make_transition(3, AxisState.IDLE, AxisState.IDLE))


def test_fault_detail_and_error_query_06() -> None:
    drv = OdriveDriver([motor(3)])
    drv.on_frame(_est(C6, 0.0, 0.0))
    drv.on_frame(_hb(C6, AxisState.IDLE, AxisError.WATCHDOG_TIMER_EXPIRED))
    (st_,) = drv.status(0.0)
    assert (st_.state, st_.faults) == (DriveState.FAULT, DriveFault.WATCHDOG)
    assert st_.detail == "axis error 0x01000000: WATCHDOG_TIMER_EXPIRED"
    assert drv.poll(0.0) == [Frame(0x063, is_remote_frame=True)]
    assert drv.poll(0.01) == []  # asked once per fault
    drv.on_frame(C6.make_error_status(ErrorStatus(3, 0x01000000, 0x03000000)))
    assert drv.status(0.0)[0].detail.endswith(
        "; disarm reason: WATCHDOG_TIMER_EXPIRED|ESTOP_REQUESTED"
    )
    drv.on_frame(_hb(C6, AxisState.IDLE))
    assert drv.status(0.0)[0].detail == ""
    assert drv.state(0, 0.0) is DriveState.DISABLED


def test_fault_detail_05_motor_error() -> None:
    drv = OdriveDriver([motor(3, firmware="0.5")])
    drv.on_frame(_est(C5, 0.0, 0.0))
    drv.on_frame(_hb(C5, AxisState.IDLE, AxisError05.MOTOR_FAILED, motor_error=True))
    assert drv.status(0.0)[0].faults == DriveFault.MOTOR
    assert drv.poll(0.0) == [Frame(0x063, is_remote_frame=True)]
    drv.on_frame(C5.make_error_status(MotorErrorStatus(3, 0x1_0000_0008)))
    assert drv.status(0.0)[0].detail == (
        "axis error 0x00000040: MOTOR_FAILED; motor error flag; "
        "motor error 0x100000008: DRV_FAULT|UNKNOWN_VOLTAGE_COMMAND"
    )


def test_enable_refused_during_calibration() -> None:
    drv = OdriveDriver([motor(3)])
    drv.on_frame(_est(C6, 0.0, 0.0))
    drv.on_frame(_hb(C6, AxisState.FULL_CALIBRATION_SEQUENCE))
    with pytest.raises(IllegalTransitionError, match=r'wheel "left".*FULL_CALIBRATION_SEQUENCE'):
        drv.enable(0.0)
    assert drv.state(0, 0.0) is DriveState.DISABLED
    assert len(drv.disable(0.0)) == 2  # stopping a calibration is always allowed


def test_enable_retries_then_gives_up() -> None:
    drv = OdriveDriver([motor(3)])
    arm = list(C6.make_transition(3, AxisState.IDLE, AxisState.CLOSED_LOOP_CONTROL))
    assert drv.enable(0.0) == arm
    t, sent = 0.0, 1
    while t < 3.0:
        t = round(t + 0.01, 2)
        drv.on_frame(_hb(C6, AxisState.IDLE, t=t))  # the axis never arms, reports no error
        drv.on_frame(_est(C6, 0.0, t))
        frames = drv.poll(t)
        assert frames in ([], arm)
        sent += bool(frames)
    assert sent == Axis.ENABLE_ATTEMPTS
    # A fault that says why (the heartbeats report no error and no procedure result), until
    # the next enable.
    assert drv.state(0, t) is DriveState.FAULT
    assert drv.detail(0) == (
        "stayed in IDLE after 3 CLOSED_LOOP_CONTROL requests without an error")
    drv.enable(t)
    assert drv.state(0, t) is DriveState.ENABLING


def test_enable_grace_for_stale_error_heartbeat() -> None:
    drv = OdriveDriver([motor(3)])
    drv.on_frame(_est(C6, 0.0, 0.0))
    drv.on_frame(_hb(C6, AxisState.IDLE, AxisError.DRV_FAULT, t=0.0))
    drv.enable(0.0)
    drv.on_frame(_hb(C6, AxisState.IDLE, AxisError.DRV_FAULT, t=0.1))  # sent before the clear
    drv.on_frame(_hb(C6, AxisState.CLOSED_LOOP_CONTROL, t=0.2))
    assert drv.state(0, 0.2) is DriveState.ENABLED
    drv.enable(1.0)
    drv.on_frame(_est(C6, 0.0, 1.4))
    drv.on_frame(_hb(C6, AxisState.IDLE, AxisError.DRV_FAULT, t=1.4))  # the axis refused
    assert drv.state(0, 1.4) is DriveState.FAULT
    drv.on_frame(_hb(C6, AxisState.IDLE, t=1.5))  # cleared elsewhere: no automatic re-arm
    assert drv.state(0, 1.5) is DriveState.DISABLED
    assert drv.poll(1.6) == []
    drv.enable(2.0)
    drv.on_frame(_hb(C6, AxisState.IDLE, AxisError.DRV_FAULT, t=2.1))  # then the axis goes quiet
    assert drv.poll(2.5) == [Frame(0x063, is_remote_frame=True)]  # gives up, asks for the reason
    drv.on_frame(_est(C6, 0.0, 2.6))
    drv.on_frame(_hb(C6, AxisState.IDLE, t=2.6))
    assert drv.state(0, 2.6) is DriveState.DISABLED
    assert drv.poll(3.2) == []
