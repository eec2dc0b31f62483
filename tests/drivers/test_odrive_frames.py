"""Tests of the ODrive CANSimple codec: golden frames, agreement with the official DBC, round
trips and bad values.

Golden frames are the worked examples of the ODrive CAN protocol documentation
(docs.odriverobotics.com, can-protocol) (checked there
against the official DBC and the firmware's struct formats).
"""

from __future__ import annotations

import logging
import math
from pathlib import Path
from typing import Any

import cantools
import pytest
from hypothesis import given
from hypothesis import strategies as st

from drivers.odrive.codec import OdriveCodec
from drivers.odrive.commands import (
    ClearErrors,
    Request,
    SetAxisState,
    SetControllerMode,
    SetInputVel,
    decode_command,
)
from drivers.odrive.enums import (
    AxisState,
    CmdId,
    ProcedureResult,
)
from drivers.odrive.messages import (
    ENCODER_ESTIMATES,
    SET_CONTROLLER_MODE,
    SET_INPUT_VEL,
    EncoderEstimates,
    ErrorStatus,
    Heartbeat,
    MotorErrorStatus,
)
from gateway.core.errors import DecodeError, EncodeError
from gateway.core.types import Frame
from tests.drivers.odrive_helpers import C5, C6, hx

DBC_PATH = Path(__file__).resolve().parent.parent / "data" / "odrive-cansimple-0.5.6.dbc"
f32 = st.floats(width=32, allow_nan=False, allow_infinity=False)
u32 = st.integers(0, 0xFFFFFFFF)
std_node = st.integers(0, 0x3F)
ext_node = st.integers(0, 0xFFFFFF)


@pytest.fixture(scope="module")
def dbc() -> Any:
    """The official 0.5.6 DBC, node-agnostic (quirk 4: only Axis0..7 are defined)."""
    logging.getLogger("cantools").setLevel(logging.ERROR)  # "Overwriting message" warnings
    return cantools.database.load_file(str(DBC_PATH), frame_id_mask=0x1F)


# ----------------------------------------------------------------------------- golden frames


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
    cmd = decode_command(codec, codec.make_set_input_vel(node, vel, torque))
    assert isinstance(cmd, SetInputVel)
    assert cmd.node_id == node
    assert _close32(cmd.vel_turns_s, vel)
    assert _close32(cmd.torque_ff_nm, torque)


@given(node=std_node, state=u32, control=u32, inp=u32, identify=st.booleans())
def test_round_trip_commands(node: int, state: int, control: int, inp: int, identify: bool) -> None:
    got = decode_command(C6, C6.make_set_axis_state(node, state))
    assert isinstance(got, SetAxisState)
    assert (got.node_id, got.state) == (node, state)
    assert decode_command(C6, C6.make_set_controller_mode(node, control, inp)) == (
        SetControllerMode(node, control, inp)
    )
    assert decode_command(C6, C6.make_clear_errors(node, identify)) == ClearErrors(node, identify)
    assert decode_command(C5, C5.make_clear_errors(node, identify)) == ClearErrors(node, False)
    assert decode_command(C6, C6.make_request(node, CmdId.HEARTBEAT)) == Request(
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
    assert decode_command(C5, Frame(0x069, b"")) == Request(3, CmdId.GET_ENCODER_ESTIMATES)
    assert C6.decode(Frame(0x06A, bytes(8))) is None  # Get_Encoder_Count: not used
    assert C6.decode(C6.make_set_input_vel(3, 1.0)) is None  # a command, not a reply
    unknown = C6.decode(Frame(0x061, hx("00000000 2A 10 00 00")))
    assert unknown == Heartbeat(3, 0, 42, procedure_result=16)  # newer firmware values


def test_decode_command_dlc() -> None:
    assert decode_command(C6, Frame(0x067, hx("08000000"))) == SetAxisState(3, AxisState(8))
    with pytest.raises(DecodeError, match="Expected 8 or 4 data bytes in Set_Axis_State"):
        decode_command(C6, Frame(0x067, hx("080000")))
    with pytest.raises(DecodeError, match="Expected 8 data bytes in Set_Input_Vel"):
        decode_command(C6, Frame(0x06D, hx("00002041")))
