"""Tests of the ODrive CANSimple driver: codec, transition table, driver and simulator.

Golden frames are the worked examples of the ODrive CAN protocol documentation
(docs.odriverobotics.com, can-protocol) (checked there
against the official DBC and the firmware's struct formats).
"""

from __future__ import annotations

import contextlib
import itertools
import logging
import math
import struct
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import can
import cantools
import pytest
from hypothesis import given
from hypothesis import strategies as st

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
    Firmware,
    InputMode,
    ProcedureResult,
    error_faults,
)
from drivers.odrive.messages import (
    ENCODER_ESTIMATES,
    SET_CONTROLLER_MODE,
    SET_INPUT_VEL,
    ClearErrors,
    EncoderEstimates,
    ErrorStatus,
    Heartbeat,
    MotorErrorStatus,
    Request,
    SetAxisState,
    SetControllerMode,
    SetInputVel,
)
from drivers.odrive.sim import OdriveSimulator, simulator_for
from gateway.bus.can_bus import drain, send_frames
from gateway.core.errors import ConfigError, DecodeError, EncodeError, IllegalTransitionError
from gateway.core.types import DriveFault, DriveState, Frame, MotorConfig
from gateway.drive.claims import FrameClaim
from gateway.drive.registry import get_driver_class
from gateway.sim.bus import SimulatedControllers
from gateway.sim.device import SimFault
from tests import factories

if TYPE_CHECKING:
    from collections.abc import Iterator, Sequence

DBC_PATH = Path(__file__).resolve().parent.parent / "data" / "odrive-cansimple-0.5.6.dbc"
TAU = 2.0 * math.pi
V05, V06 = Firmware.V0_5, Firmware.V0_6
f32 = st.floats(width=32, allow_nan=False, allow_infinity=False)
u32 = st.integers(0, 0xFFFFFFFF)
std_node = st.integers(0, 0x3F)
ext_node = st.integers(0, 0xFFFFFF)


def hx(text: str) -> bytes:
    return bytes.fromhex(text.replace(" ", ""))


def motor(
    node: int = 3,
    wheel: str = "left",
    *,
    gear_ratio: float = 1.0,
    invert: bool = False,
    max_rpm: float = 3000.0,
    validate: bool = True,
    **options: object,
) -> MotorConfig:
    """An ODrive motor block of the factory (:func:`tests.factories.motor`)."""
    return factories.motor("odrive", node, wheel, gear_ratio=gear_ratio, invert=invert,
                           max_rpm=max_rpm, validate=validate, options=options)


@pytest.fixture(scope="module")
def dbc() -> Any:
    """The official 0.5.6 DBC, node-agnostic (quirk 4: only Axis0..7 are defined)."""
    logging.getLogger("cantools").setLevel(logging.ERROR)  # "Overwriting message" warnings
    return cantools.database.load_file(str(DBC_PATH), frame_id_mask=0x1F)


# ----------------------------------------------------------------------------- golden frames

C5, C6 = OdriveCodec(V05), OdriveCodec(V06)


@pytest.mark.parametrize(
    ("frame", "expected"),
    [
        (C6.make_set_input_vel(3, 10.0), Frame(0x06D, hx("00 00 20 41 00 00 00 00"))),
        (C6.make_set_axis_state(3, 8), Frame(0x067, hx("08 00 00 00 00 00 00 00"))),
        (C6.make_set_axis_state(3, 1), Frame(0x067, hx("01 00 00 00 00 00 00 00"))),
        (C6.make_set_controller_mode(1, 2, 2), Frame(0x02B, hx("02 00 00 00 02 00 00 00"))),
        (C5.make_clear_errors(3), Frame(0x078, b"")),
        (C6.make_clear_errors(3), Frame(0x078, hx("00"))),
        (C6.make_request(3, CmdId.GET_ENCODER_ESTIMATES), Frame(0x069, is_remote_frame=True)),
        (C6.make_estop(3), Frame(0x062, b"")),
        (  # extended node 0xfedcba, as in the official can_test.py
            OdriveCodec(extended_id=True).make_set_input_vel(0xFEDCBA, 10.0),
            Frame(0x1FDB974D, hx("00 00 20 41 00 00 00 00"), is_extended_id=True),
        ),
    ],
    ids=["vel", "closed_loop", "idle", "mode", "clear05", "clear06", "rtr", "estop", "ext"],
)
def test_golden_encode(frame: Frame, expected: Frame) -> None:
    assert frame == expected
    assert frame.dlc == expected.dlc


def test_golden_decode() -> None:
    est = C6.decode(Frame(0x069, hx("00 00 48 41 00 00 10 C0")))
    assert est == EncoderEstimates(3, 12.5, -2.25)
    hb5 = C5.decode(Frame(0x061, hx("00 00 00 00 08 00 00 80")))
    assert hb5 == Heartbeat(3, 0, AxisState.CLOSED_LOOP_CONTROL, trajectory_done=True)
    hb6 = C6.decode(Frame(0x061, hx("00 00 00 00 08 00 01 00")))
    assert hb6 == Heartbeat(3, 0, AxisState.CLOSED_LOOP_CONTROL, trajectory_done=True)
    # The same 0.6 bytes read as 0.5 are an encoder error flag, not "trajectory done".
    assert C5.decode(Frame(0x061, hx("00 00 00 00 08 00 01 00"))) == Heartbeat(
        3, 0, AxisState.CLOSED_LOOP_CONTROL, encoder_error=True
    )


# ----------------------------------------------------------------------------- official DBC


def test_dbc_quirks(dbc: Any) -> None:
    """The 0.5.6 DBC quirks (spec section 1) that the cross-checks below work around."""
    vel = dbc.get_message_by_frame_id(0x06D)
    # Quirk 1: units swapped; the firmware takes Input_Vel in rev/s and Input_Torque_FF in Nm.
    assert vel.get_signal_by_name("Input_Vel").unit == "rev"
    assert vel.get_signal_by_name("Input_Torque_FF").unit == "rev/s"
    # Quirk 3: Get_Motor_Error declared 32 bits; the firmware sends 64 (we decode all 64).
    frame = C5.make_error_status(MotorErrorStatus(3, 0x2_0000_0001))
    assert _dbc_decode(dbc, frame) == {"Motor_Error": 1}
    assert C5.decode(frame) == MotorErrorStatus(3, 0x2_0000_0001)
    # Clear_Errors is DLC 0 in this (0.5) DBC; 0.6 adds the Identify byte.
    assert dbc.get_message_by_frame_id(0x078).length == len(C5.make_clear_errors(3).data) == 0
    # The DBC only knows 11-bit IDs: look extended frames up by their command bits.
    assert not vel.is_extended_frame


def _dbc_decode(dbc: Any, frame: Frame) -> dict[str, Any]:
    msg = dbc.get_message_by_frame_id(frame.arbitration_id & 0x1F)
    assert msg.length == frame.dlc
    return dict(msg.decode(frame.data, decode_choices=False))


@given(node=std_node, vel=f32, torque=f32, ext=st.booleans())
def test_dbc_decodes_set_input_vel(
    dbc: Any, node: int, vel: float, torque: float, ext: bool
) -> None:
    codec = OdriveCodec(extended_id=ext)
    frame = codec.make_set_input_vel(node, vel, torque)
    assert _dbc_decode(dbc, frame) == dict(zip(SET_INPUT_VEL.signals, (vel, torque), strict=True))


@given(node=std_node, state=u32, control=u32, inp=u32)
def test_dbc_decodes_state_and_mode(
    dbc: Any, node: int, state: int, control: int, inp: int
) -> None:
    assert _dbc_decode(dbc, C6.make_set_axis_state(node, state)) == {"Axis_Requested_State": state}
    frame = C6.make_set_controller_mode(node, control, inp)
    expected = dict(zip(SET_CONTROLLER_MODE.signals, (control, inp), strict=True))
    assert _dbc_decode(dbc, frame) == expected


@given(
    node=std_node, pos=f32, vel=f32, error=u32, state=st.integers(0, 255), flags=st.integers(0, 15)
)
def test_dbc_agrees_on_replies(
    dbc: Any, node: int, pos: float, vel: float, error: int, state: int, flags: int
) -> None:
    est = C5.make_encoder_estimates(node, pos, vel)
    assert _dbc_decode(dbc, est) == dict(zip(ENCODER_ESTIMATES.signals, (pos, vel), strict=True))
    hb = Heartbeat(
        node,
        error,
        state,
        trajectory_done=bool(flags & 1),
        motor_error=bool(flags & 2),
        encoder_error=bool(flags & 4),
        controller_error=bool(flags & 8),
    )
    ref = _dbc_decode(dbc, C5.make_heartbeat(hb))
    assert ref == {
        "Axis_Error": error,
        "Axis_State": state,
        "Trajectory_Done_Flag": int(hb.trajectory_done),
        "Motor_Error_Flag": int(hb.motor_error),
        "Encoder_Error_Flag": int(hb.encoder_error),
        "Controller_Error_Flag": int(hb.controller_error),
    }
    assert C5.decode(C5.make_heartbeat(hb)) == hb


# ----------------------------------------------------------------------------- round trips


def _close32(got: float, want: float) -> bool:
    """Within half a float32 ULP (one unit of resolution)."""
    return abs(got - want) <= max(abs(want) * 2.0**-24, 2.0**-149)


@given(node=ext_node, vel=st.floats(-1e30, 1e30), torque=st.floats(-1e3, 1e3))
def test_round_trip_set_input_vel(node: int, vel: float, torque: float) -> None:
    codec = OdriveCodec(extended_id=True)
    cmd = codec.decode_command(codec.make_set_input_vel(node, vel, torque))
    assert isinstance(cmd, SetInputVel)
    assert cmd.node_id == node
    assert _close32(cmd.vel_turns_s, vel)
    assert _close32(cmd.torque_ff_nm, torque)


@given(node=std_node, state=u32, control=u32, inp=u32, identify=st.booleans())
def test_round_trip_commands(node: int, state: int, control: int, inp: int, identify: bool) -> None:
    got = C6.decode_command(C6.make_set_axis_state(node, state))
    assert isinstance(got, SetAxisState)
    assert (got.node_id, got.state) == (node, state)
    assert C6.decode_command(C6.make_set_controller_mode(node, control, inp)) == (
        SetControllerMode(node, control, inp)
    )
    assert C6.decode_command(C6.make_clear_errors(node, identify)) == ClearErrors(node, identify)
    assert C5.decode_command(C5.make_clear_errors(node, identify)) == ClearErrors(node, False)
    assert C6.decode_command(C6.make_request(node, CmdId.HEARTBEAT)) == Request(
        node, CmdId.HEARTBEAT
    )


@given(
    node=std_node,
    error=u32,
    state=st.sampled_from(AxisState),
    result=st.sampled_from(ProcedureResult),
    done=st.booleans(),
    pos=st.floats(-1e9, 1e9),
    vel=st.floats(-1e4, 1e4),
    active=u32,
    reason=u32,
    motor_error=st.integers(0, 2**64 - 1),
)
def test_round_trip_replies(
    node: int,
    error: int,
    state: AxisState,
    result: ProcedureResult,
    done: bool,
    pos: float,
    vel: float,
    active: int,
    reason: int,
    motor_error: int,
) -> None:
    hb = Heartbeat(node, error, state, done, procedure_result=result)
    assert C6.decode(C6.make_heartbeat(hb)) == hb
    est = C6.decode(C6.make_encoder_estimates(node, pos, vel))
    assert isinstance(est, EncoderEstimates)
    assert _close32(est.pos_turns, pos)
    assert _close32(est.vel_turns_s, vel)
    assert C6.decode(C6.make_error_status(ErrorStatus(node, active, reason))) == (
        ErrorStatus(node, active, reason)
    )
    status = MotorErrorStatus(node, motor_error)
    assert C5.decode(C5.make_error_status(status)) == status


# ----------------------------------------------------------------------------- bad values


@pytest.mark.parametrize("value", [math.nan, math.inf, -math.inf, 3.5e38, -1e39])
def test_encode_rejects_non_float32(value: float) -> None:
    with pytest.raises(EncodeError, match=r"^Expected Input_Vel for node 3 between .* turns/s"):
        C6.make_set_input_vel(3, value)


def test_encode_rejects_bad_ids_and_ints() -> None:
    with pytest.raises(
        EncodeError, match=r"between 0 and 0x3f with 11-bit identifiers, but got 64"
    ):
        C6.make_set_input_vel(0x40, 1.0)
    with pytest.raises(EncodeError, match=r"0xffffff with 29-bit"):
        OdriveCodec(extended_id=True).make_set_axis_state(0x1000000, 8)
    for bad in (-1, 2**32):
        with pytest.raises(EncodeError, match="Axis_Requested_State"):
            C6.make_set_axis_state(3, bad)


@pytest.mark.parametrize(
    ("codec", "frame"),
    [
        (C6, Frame(0x061, bytes(7))),  # heartbeat DLC 7
        (C6, Frame(0x069, bytes(4))),  # estimates DLC 4
        (C6, Frame(0x063, bytes(0))),  # 0.6 Get_Error DLC 0 (0.6 requests are RTR only)
        (C5, Frame(0x063, bytes(4))),  # 0.5 Get_Motor_Error is 64 bits
        (C6, Frame(0x069, hx("0000C07F 00000000"))),  # NaN position
        (C6, Frame(0x069, hx("00000000 000080FF"))),  # -inf velocity
    ],
)
def test_decode_rejects_malformed(codec: OdriveCodec, frame: Frame) -> None:
    with pytest.raises(DecodeError, match=r"ODrive node 3"):
        codec.decode(frame)


def test_decode_ignores_what_is_not_a_reply() -> None:
    data = hx("00 00 48 41 00 00 10 C0")
    assert C6.decode(Frame(0x069, data, is_extended_id=True)) is None  # other ID type
    assert OdriveCodec(extended_id=True).decode(Frame(0x069, data)) is None
    assert C6.decode(Frame(0x069, is_remote_frame=True, dlc=8)) is None  # a request
    assert C5.decode(Frame(0x069, b"")) is None  # 0.5 answers DLC 0 data frames too
    assert C5.decode_command(Frame(0x069, b"")) == Request(3, CmdId.GET_ENCODER_ESTIMATES)
    assert C6.decode(Frame(0x06A, bytes(8))) is None  # Get_Encoder_Count: not used
    assert C6.decode(C6.make_set_input_vel(3, 1.0)) is None  # a command, not a reply
    unknown = C6.decode(Frame(0x061, hx("00000000 2A 10 00 00")))
    assert unknown == Heartbeat(3, 0, 42, procedure_result=16)  # newer firmware values


def test_decode_command_dlc() -> None:
    assert C6.decode_command(Frame(0x067, hx("08000000"))) == SetAxisState(3, AxisState(8))
    with pytest.raises(DecodeError, match="Expected 8 or 4 data bytes in Set_Axis_State"):
        C6.decode_command(Frame(0x067, hx("080000")))
    with pytest.raises(DecodeError, match="Expected 8 data bytes in Set_Input_Vel"):
        C6.decode_command(Frame(0x06D, hx("00002041")))


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
    ],
)
def test_config_errors(motors: list[MotorConfig], message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        OdriveDriver(motors)


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
    assert drv.state(0, t) is DriveState.DISABLED


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


# ----------------------------------------------------------------------------- virtual bus


class Rig:
    """Driver + simulators on a virtual bus, stepped at 1 kHz of simulated time."""

    def __init__(self, gw: can.BusABC, ctl: SimulatedControllers, drv: OdriveDriver) -> None:
        self.gw, self.ctl, self.drv, self.t = gw, ctl, drv, 0.0
        self.speeds = [0.0] * len(drv.motors)

    def send(self, frames: Sequence[Frame]) -> None:
        send_frames(self.gw, frames)

    def run(self, seconds: float, talk: bool = True, cmd_period_steps: int = 10) -> None:
        for k in range(round(seconds * 1000)):
            self.t = round(self.t + 0.001, 6)
            self.ctl.step(self.t)
            for f in drain(self.gw):
                self.drv.on_frame(f.stamped(self.t))
            if talk and k % cmd_period_steps == 0:
                self.send(self.drv.poll(self.t) + self.drv.command(self.speeds, self.t))

    def state(self, i: int = 0) -> DriveState:
        return self.drv.state(i, self.t)


@contextlib.contextmanager
def rig(channel: str, sims: Sequence[OdriveSimulator]) -> Iterator[Rig]:
    drv = OdriveDriver([s.motor for s in sims])
    gw = can.Bus(interface="virtual", channel=channel)
    try:
        with SimulatedControllers(sims, channel) as ctl:
            yield Rig(gw, ctl, drv)
    finally:
        gw.shutdown()


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


#: The watchdog's endpoint IDs the 0.6 tests name (the simulator's; real ones come from the
#: firmware's flat_endpoints.json).
ENDPOINTS = {"fw_version": "0.6.10", "enable_watchdog": 201, "watchdog_timeout": 200}


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
