"""Tests of the CANopen CiA 402 codec: golden frames and decodes, round trips of every frame
the gateway builds or parses, the error tables.

Golden frames come from CiA 301 / CiA 402 as the canopen library (christiansandberg/canopen)
implements them, "Worked examples (node 3)" and "Verified on the virtual bus" (frames captured
from canopen 2.4.1).  The ``canopen`` library serves as an independent cross-check of our SDO
frames, the EMCY reading and the abort-code texts; it is never used by the driver itself.
"""

from __future__ import annotations

import canopen
import pytest
from canopen.sdo import constants as sdo_constants
from canopen.sdo.exceptions import SdoAbortedError
from hypothesis import given
from hypothesis import strategies as st

from drivers.cia402 import Cia402Codec, Cia402Driver, PdoLayout, faults
from drivers.cia402.codec import (
    Emergency,
    FeedbackKind,
    Heartbeat,
    PdoFeedback,
    make_emcy,
    make_heartbeat,
    make_nmt,
    make_rpdo,
    make_sync,
    make_tpdo,
    unpack_pdo,
)
from drivers.cia402.enums import (
    ClientCommand,
    Controlword,
    DataType,
    NmtCommand,
    NmtState,
    ServerCommand,
    State,
    state_from_statusword,
)
from drivers.cia402.sdo import (
    SdoResponse,
    make_sdo_abort,
    make_sdo_download,
    make_sdo_download_ack,
    make_sdo_upload,
    make_sdo_upload_response,
    parse_sdo_request,
    parse_sdo_response,
)
from drivers.cia402.targets import wrap_delta
from gateway.core.errors import DecodeError
from gateway.core.types import DriveFault, Frame
from tests import factories
from tests.drivers.cia402_bench import TWO_PI, hexb

U16, I32 = DataType.UNSIGNED16, DataType.INTEGER32


# ===================================================================== golden frames (spec §3)


@pytest.mark.parametrize(
    ("frame", "cob", "data"),
    [
        (make_nmt(NmtCommand.START, 3), 0x000, "01 03"),
        (make_nmt(NmtCommand.START), 0x000, "01 00"),
        (make_nmt(NmtCommand.ENTER_PRE_OPERATIONAL, 3), 0x000, "80 03"),
        (make_nmt(NmtCommand.STOP, 3), 0x000, "02 03"),
        (make_nmt(NmtCommand.RESET_NODE, 3), 0x000, "81 03"),
        (make_nmt(NmtCommand.RESET_COMMUNICATION, 3), 0x000, "82 03"),
        (make_sdo_download(3, 0x6040, 0, 0x80, U16), 0x603, "2B 40 60 00 80 00 00 00"),
        (make_sdo_download(3, 0x6040, 0, 0x06, U16), 0x603, "2B 40 60 00 06 00 00 00"),
        (make_sdo_download(3, 0x6040, 0, 0x07, U16), 0x603, "2B 40 60 00 07 00 00 00"),
        (make_sdo_download(3, 0x6040, 0, 0x0F, U16), 0x603, "2B 40 60 00 0F 00 00 00"),
        (make_sdo_download(3, 0x6060, 0, 3, DataType.INTEGER8), 0x603, "2F 60 60 00 03 00 00 00"),
        (make_sdo_download(3, 0x60FF, 0, 1000, I32), 0x603, "23 FF 60 00 E8 03 00 00"),
        (make_sdo_upload(3, 0x6502, 0), 0x603, "40 02 65 00 00 00 00 00"),
        (make_sdo_upload_response(3, 0x6502, 0, 0x6D, DataType.UNSIGNED32), 0x583,
         "43 02 65 00 6D 00 00 00"),
        (make_sdo_upload_response(3, 0x606C, 0, 998, DataType.INTEGER32), 0x583,
         "43 6C 60 00 E6 03 00 00"),
        (make_sdo_download_ack(3, 0x6040, 0), 0x583, "60 40 60 00 00 00 00 00"),
        (make_rpdo(0x503, 0x000F, 1000), 0x503, "0F 00 E8 03 00 00"),
        (make_tpdo(0x483, 0x0237, 998), 0x483, "37 02 E6 03 00 00"),
        (make_tpdo(0x383, 0x0237, -123456), 0x383, "37 02 C0 1D FE FF"),
        (make_heartbeat(3, NmtState.OPERATIONAL), 0x703, "05"),
        (make_sync(), 0x080, ""),
        (make_sync(5), 0x080, "05"),
        (make_emcy(3, 0x2310, 0x05), 0x083, "10 23 05 00 00 00 00 00"),
    ],
)
def test_golden_frames(frame: Frame, cob: int, data: str) -> None:
    assert frame == Frame(cob, hexb(data))


def test_golden_rpdo4_from_codec_and_driver() -> None:
    codec = Cia402Codec({3: PdoLayout(), 5: PdoLayout(rpdo=1)})
    assert codec.rpdo(3, Controlword.ENABLE_OPERATION, 1000) == Frame(0x503,
                                                                     hexb("0F 00 E8 03 00 00"))
    assert codec.rpdo(5, Controlword.SHUTDOWN, -1) == Frame(0x205, hexb("06 00 FF FF FF FF"))
    # 999.6 RPM at the motor (gear 1): round(), never truncation
    drv = Cia402Driver([factories.motor("cia402", 3, "left")])
    assert drv.preview_command([999.6 * TWO_PI / 60]) == [
        Frame(0x503, hexb("0F 00 E8 03 00 00")), Frame(0x080)]


def test_golden_decodes() -> None:
    codec = Cia402Codec({3: PdoLayout()})
    tpdo4 = codec.decode(Frame(0x483, hexb("37 02 E6 03 00 00")))
    assert tpdo4 == PdoFeedback(3, FeedbackKind.VELOCITY, 0x0237, 998)
    assert state_from_statusword(0x0237) is State.OPERATION_ENABLED
    tpdo3 = codec.decode(Frame(0x383, hexb("37 02 C0 1D FE FF")))
    assert tpdo3 == PdoFeedback(3, FeedbackKind.POSITION, 0x0237, -123456)
    assert codec.decode(Frame(0x703, hexb("05"))) == Heartbeat(3, NmtState.OPERATIONAL)
    emcy = codec.decode(Frame(0x083, hexb("10 23 05 00 00 00 00 00")))
    assert emcy == Emergency(3, 0x2310, 0x05, bytes(5))
    assert faults.emcy_faults(0x2310, 0x05) == DriveFault.OVER_CURRENT
    resp = codec.decode(Frame(0x583, hexb("43 6C 60 00 E6 03 00 00")))
    assert isinstance(resp, SdoResponse)
    assert resp.value(DataType.INTEGER32) == 998
    ack = parse_sdo_response(Frame(0x583, hexb("60 40 60 00 00 00 00 00")))
    assert (ack.command, ack.index, ack.subindex) == (ServerCommand.INITIATE_DOWNLOAD, 0x6040, 0)
    assert codec.decode(Frame(0x080)) is None  # SYNC is nobody's feedback
    assert codec.decode(Frame(0x384, hexb("37 02 C0 1D FE FF"))) is None  # another node


def test_a_velocity_tpdo_refreshes_the_speed_and_keeps_the_positions_time() -> None:
    # The odometry integrates a position at its feedback's time: a velocity TPDO that came
    # later must not make an old position look new (CiA 402 sends them in two TPDOs).
    drv = Cia402Driver([factories.motor("cia402", 3, "left")])
    drv.on_frame(Frame(0x383, hexb("37 02 00 10 00 00"), timestamp_s=1.0))  # 4096 counts
    drv.on_frame(Frame(0x483, hexb("37 02 E8 03 00 00"), timestamp_s=1.004))  # 1000 RPM
    fb = drv.feedback(0)
    assert fb is not None
    assert fb.timestamp_s == 1.0
    assert fb.velocity_rad_s == pytest.approx(1000 * TWO_PI / 60)
    assert drv.live.times[0] == [1.004]  # (heard at the velocity TPDO's time all the same)
    drv.on_frame(Frame(0x383, hexb("37 02 00 20 00 00"), timestamp_s=1.01))
    fb = drv.feedback(0)
    assert fb is not None and fb.timestamp_s == 1.01
    assert fb.position_rad == pytest.approx(TWO_PI)  # counts_per_rev 4096: one turn on


def test_an_upload_of_more_bytes_than_the_object_takes_its_first_when_that_is_safe() -> None:
    """An expedited upload without its size (0x42: "an unspecified number of bytes", CiA 301)
    or with zero bytes beyond the object (a device that sends every value as 32 bits) gives
    the object's first bytes, as ``canopen``'s ``SdoClient.upload`` does; a sized one whose
    extra bytes are not zero would change the value, and is refused (before, both failed
    the enable: "Expected 2 bytes (INTEGER16) in the SDO upload of 0x605A:00 ...")."""
    unsized = parse_sdo_response(Frame(0x583, hexb("42 5A 60 00 02 00 00 00")))
    assert unsized.value(DataType.INTEGER16) == 2
    padded = parse_sdo_response(Frame(0x583, hexb("43 5A 60 00 FE FF 00 00")))
    assert padded.value(DataType.INTEGER16) == -2
    wide = parse_sdo_response(Frame(0x583, hexb("43 5A 60 00 02 00 01 00")))
    with pytest.raises(DecodeError, match=r"Expected 2 bytes \(INTEGER16\) in the SDO upload "
                                          r"of 0x605A:00 from node 3, but got 4"):
        wide.value(DataType.INTEGER16)
    short = parse_sdo_response(Frame(0x583, hexb("4B 5A 60 00 02 00 00 00")))  # 2 bytes
    with pytest.raises(DecodeError, match="but got 2"):
        short.value(DataType.UNSIGNED32)


# ===================================================================== hypothesis round trips

u16 = st.integers(0, 0xFFFF)
i32 = st.integers(-(1 << 31), (1 << 31) - 1)
node_ids = st.integers(1, 127)


@given(u16, i32, st.integers(0x181, 0x57F))
def test_pdo_round_trip(word: int, value: int, cob: int) -> None:
    assert unpack_pdo(make_rpdo(cob, word, value), "x") == (word, value)
    assert unpack_pdo(make_tpdo(cob, word, value), "x") == (word, value)


@given(node_ids, u16, i32, st.sampled_from(list(FeedbackKind)))
def test_tpdo_decode_round_trip(node: int, word: int, value: int, kind: FeedbackKind) -> None:
    lay = PdoLayout()
    codec = Cia402Codec({node: lay})
    number = lay.tpdo_position if kind is FeedbackKind.POSITION else lay.tpdo_velocity
    cob = 0x180 + (number - 1) * 0x100 + node
    assert codec.decode(make_tpdo(cob, word, value)) == PdoFeedback(node, kind, word, value)


@given(st.floats(-1.0, 1.0), st.floats(0.01, 1000.0), st.booleans())
def test_velocity_command_round_trip(fraction: float, factor: float, invert: bool) -> None:
    """A wheel speed up to max_rpm -> the RPDO's target velocity, rounded to device units."""
    motor = factories.motor("cia402", 7, "left", gear_ratio=12.5, max_rpm=6000.0, invert=invert,
                        options={"velocity_factor": factor})
    speed = fraction * motor.max_wheel_rad_s
    frame = Cia402Driver([motor]).preview_command([speed])[0]
    word, value = unpack_pdo(frame, "RPDO")
    assert (frame.arbitration_id, word) == (0x507, Controlword.ENABLE_OPERATION)
    units = motor.wheel_to_motor_rad_s(speed) * 60 / TWO_PI * factor
    assert abs(value - units) <= 0.5 + 1e-9 * abs(units)


@st.composite
def typed_values(draw: st.DrawFn) -> tuple[DataType, int]:
    dtype = draw(st.sampled_from(list(DataType)))
    lo, hi = dtype.bounds
    return dtype, draw(st.integers(lo, hi))


@given(node_ids, u16, st.integers(0, 255), typed_values())
def test_sdo_round_trips(node: int, index: int, sub: int, tv: tuple[DataType, int]) -> None:
    dtype, value = tv
    req = parse_sdo_request(make_sdo_download(node, index, sub, value, dtype))
    assert (req.node_id, req.command, req.index, req.subindex) == (
        node, ClientCommand.INITIATE_DOWNLOAD, index, sub)
    assert dtype.codec.unpack(req.data)[0] == value
    up = parse_sdo_request(make_sdo_upload(node, index, sub))
    assert (up.command, up.index, up.subindex) == (ClientCommand.INITIATE_UPLOAD, index, sub)
    resp = parse_sdo_response(make_sdo_upload_response(node, index, sub, value, dtype))
    assert resp.value(dtype) == value
    assert parse_sdo_response(make_sdo_download_ack(node, index, sub)).command is (
        ServerCommand.INITIATE_DOWNLOAD)


@given(node_ids, u16, st.integers(0, 255), st.integers(0, 0xFFFFFFFF))
def test_sdo_abort_round_trip(node: int, index: int, sub: int, code: int) -> None:
    resp = parse_sdo_response(make_sdo_abort(node, index, sub, code))
    assert (resp.command, resp.index, resp.subindex, resp.abort_code) == (
        ServerCommand.ABORT, index, sub, code)
    req = parse_sdo_request(make_sdo_abort(node, index, sub, code, from_server=False))
    assert (req.command, req.abort_code) == (ClientCommand.ABORT, code)


@given(node_ids, u16, st.integers(0, 255), st.binary(min_size=5, max_size=5))
def test_emcy_round_trip(node: int, code: int, register: int, data: bytes) -> None:
    msg = Cia402Codec({node: PdoLayout()}).decode(make_emcy(node, code, register, data))
    assert msg == Emergency(node, code, register, data)
    # canopen's EMCY consumer reads the same frame the same way.
    consumer = canopen.emcy.EmcyConsumer()  # type: ignore[no-untyped-call]
    payload = make_emcy(node, code, register, data).data
    consumer.on_emcy(0x80 + node, payload, 0.0)  # type: ignore[no-untyped-call]
    assert (consumer.log[0].code, consumer.log[0].register) == (code, register)
    assert (not consumer.active) == faults.is_error_reset(code)
    assert (faults.emcy_faults(code, register) == DriveFault.NONE) == faults.is_error_reset(code)


@given(typed_values(), u16, st.integers(0, 255))
def test_sdo_download_matches_canopen_structures(
    tv: tuple[DataType, int], index: int, sub: int
) -> None:
    dtype, value = tv
    data = make_sdo_download(5, index, sub, value, dtype).data
    command, idx, subidx = sdo_constants.SDO_STRUCT.unpack_from(data)
    assert (idx, subidx) == (index, sub)
    assert command & 0xE0 == sdo_constants.REQUEST_DOWNLOAD
    assert command & sdo_constants.EXPEDITED and command & sdo_constants.SIZE_SPECIFIED
    size = 4 - ((command >> 2) & 0x3)
    assert size == dtype.size
    assert dtype.codec.unpack(data[4:4 + size])[0] == value


@given(i32, st.integers(-(1 << 31), (1 << 31) - 1))
def test_wrap_delta(start: int, delta: int) -> None:
    end = (start + delta + (1 << 31)) % (1 << 32) - (1 << 31)
    assert wrap_delta(start, end) == delta


def test_wrap_delta_across_int32_limit() -> None:  # spec §8.4: 0x7FFFFFFF -> 0x80000000 = +1
    assert wrap_delta(0x7FFFFFFF, -0x80000000) == 1
    assert wrap_delta(-0x80000000, 0x7FFFFFFF) == -1


def test_sdo_abort_texts_match_canopen() -> None:
    for code, text in faults.SDO_ABORT_TEXT.items():
        assert SdoAbortedError.CODES.get(int(code), text) == text
    assert faults.sdo_abort_text(0x06020000) == "0x06020000 Object does not exist"
    assert faults.sdo_abort_text(0x12345678) == "0x12345678 unknown abort code"


def test_describe_emcy() -> None:
    assert faults.describe_emcy(0x2310, 0x03) == (
        "EMCY 0x2310 Continuous over-current (error register 0x03 GENERIC|CURRENT)")
    assert faults.describe_emcy(0x8250, 0x11, b"\x01\0\0\0\0").endswith("data 01 00 00 00 00)")
    assert faults.emcy_faults(0x8250, 0x11) == DriveFault.WATCHDOG | DriveFault.COMMUNICATION
    assert faults.emcy_faults(0xFF01, 0x01) == DriveFault.OTHER
    assert faults.emcy_faults(0x3220, 0x05) == DriveFault.UNDER_VOLTAGE
