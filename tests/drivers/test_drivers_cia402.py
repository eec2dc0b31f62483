"""Tests of the CANopen CiA 402 codec, state machine and enable sequence (``_bus``: on a bus).

Golden frames come from CiA 301 / CiA 402 as the canopen library (christiansandberg/canopen)
implements them, "Worked examples
(node 3)" and "Verified on the virtual bus" (frames captured from canopen 2.4.1).  The
``canopen`` library serves as an independent cross-check of our SDO frames, the state table and
the abort-code texts; it is never used by the driver itself.
"""

from __future__ import annotations

import math

import canopen
import pytest
from canopen.profiles.p402 import State402
from canopen.sdo import constants as sdo_constants
from canopen.sdo.exceptions import SdoAbortedError
from hypothesis import given
from hypothesis import strategies as st

from drivers.cia402 import Cia402Codec, Cia402Driver, Cia402Simulator, PdoLayout, enums, faults
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
    velocity_to_raw,
)
from drivers.cia402.driver import wrap_delta
from drivers.cia402.enums import (
    ClientCommand,
    Controlword,
    DataType,
    NmtCommand,
    NmtState,
    ServerCommand,
    State,
    controlword_for,
    state_from_statusword,
)
from drivers.cia402.options import NodeOptions
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
from drivers.cia402.sequence import NodeSequencer, Phase
from drivers.cia402.steps import (
    NmtStep,
    SdoExpectStep,
    SdoVerifyStep,
    SdoWriteStep,
    configuration_steps,
)
from gateway.core.errors import ConfigError, DecodeError, EncodeError, IllegalTransitionError
from gateway.core.types import DriveFault, Frame, MotorConfig
from gateway.drive.registry import get_driver_class

DT = 0.001
U16, I32 = DataType.UNSIGNED16, DataType.INTEGER32
TWO_PI = 2.0 * math.pi


def hexb(text: str) -> bytes:
    return bytes.fromhex(text)


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


def test_golden_rpdo4_from_codec() -> None:
    codec = Cia402Codec({3: PdoLayout()})
    assert codec.encode_command({3: 1000.0}) == (Frame(0x503, hexb("0F 00 E8 03 00 00")),)
    assert codec.encode_command({3: 999.6}) == codec.encode_command({3: 1000.0})  # round()


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


@given(st.floats(-(2.0**31) + 1, 2.0**31 - 2))
def test_velocity_command_round_trip(units: float) -> None:
    frame = Cia402Codec({7: PdoLayout()}).encode_command({7: units})[0]
    word, value = unpack_pdo(frame, "RPDO")
    assert word == Controlword.ENABLE_OPERATION
    assert abs(value - units) <= 0.5


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


# ===================================================================== malformed frames, bad values


@pytest.mark.parametrize(
    ("frame", "reason"),
    [
        (Frame(0x383, hexb("37 02 C0 1D FE")), "5"),  # short TPDO
        (Frame(0x483, hexb("37 02 E6 03 00 00 00")), "7"),  # long TPDO
        (Frame(0x383, is_remote_frame=True, dlc=6), "11-bit"),
        (Frame(0x703, hexb("05 00")), "1 data byte"),
        (Frame(0x703, hexb("03")), "NMT state"),
        (Frame(0x083, hexb("10 23 05")), "8 data bytes"),
        (Frame(0x583, hexb("60 40 60 00")), "8 data bytes"),
        (Frame(0x583, hexb("E0 40 60 00 00 00 00 00")), "command byte 0xE0"),
        (Frame(0x583, hexb("41 00 10 00 20 00 00 00")), "segmented"),
    ],
)
def test_malformed_frames_are_counted(frame: Frame, reason: str) -> None:
    drv = Cia402Driver([MotorConfig("left", "cia402", 3)])
    assert drv.on_frame(frame) is True
    assert sum(drv.rejected.values()) == 1
    assert reason in next(iter(drv.last_rejection.values()))
    with pytest.raises(DecodeError):
        drv.codec.decode(frame)


def test_foreign_frames_are_not_ours() -> None:
    drv = Cia402Driver([MotorConfig("left", "cia402", 3)])
    for frame in (Frame(0x384, bytes(6)), Frame(0x080), Frame(0x603, bytes(8)),
                  Frame(0x183, bytes(2)), Frame(0x503, bytes(6)),
                  # a 29-bit frame with the number of our TPDO3 is another device's
                  Frame(0x383, hexb("37 02 C0 1D FE FF"), is_extended_id=True)):
        assert drv.on_frame(frame) is False
    assert not drv.rejected


def test_unexpected_sdo_response_is_counted() -> None:
    drv = Cia402Driver([MotorConfig("left", "cia402", 3)])
    assert drv.on_frame(make_sdo_download_ack(3, 0x6040, 0))
    assert drv.rejected == {"unexpected SDO response": 1}


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf, 1e3])
def test_command_rejects_bad_speeds(bad: float) -> None:
    drv = Cia402Driver([MotorConfig("left", "cia402", 3, gear_ratio=10.0, max_rpm=5000.0)])
    with pytest.raises(EncodeError, match=r'Expected velocity for node 3 \("left"\) between '
                                          r"-52\.36 and 52\.36 rad/s, but got"):
        drv.command([bad], 0.0)


def test_encode_range_errors() -> None:
    drv = Cia402Driver([MotorConfig("left", "cia402", 3)])
    with pytest.raises(EncodeError, match="Expected 1 wheel speeds, but got 2"):
        drv.command([0.0, 0.0], 0.0)
    with pytest.raises(EncodeError, match="-2147483648 and 2147483647 device units"):
        velocity_to_raw(2.0**31, "target velocity for node 3")
    with pytest.raises(EncodeError, match="0x6060:00"):
        make_sdo_download(3, 0x6060, 0, 200, DataType.INTEGER8)
    with pytest.raises(EncodeError, match="controlword"):
        make_rpdo(0x503, 0x10000, 0)
    with pytest.raises(EncodeError, match="node ID"):
        make_heartbeat(128, NmtState.OPERATIONAL)


def test_config_errors() -> None:
    with pytest.raises(ConfigError, match="unknown key"):
        Cia402Driver([MotorConfig("left", "cia402", 3, options={"bogus": 1})])
    with pytest.raises(ConfigError, match="tpdo_velocity"):
        Cia402Driver([MotorConfig("l", "cia402", 3, options={"tpdo_velocity": 3})])
    with pytest.raises(ConfigError, match=r"1\.\.127, got 0"):
        Cia402Driver([MotorConfig("left", "cia402", 0)])
    with pytest.raises(ConfigError, match=r"node 3 is already used by wheel .a."):
        Cia402Driver([MotorConfig("a", "cia402", 3), MotorConfig("b", "cia402", 3)])
    with pytest.raises(ConfigError, match="velocity_factor"):
        NodeOptions.from_motor(MotorConfig("a", "cia402", 3, options={"velocity_factor": 0}))
    assert get_driver_class("cia402") is Cia402Driver


# ===================================================================== state machine tables

#: CiA 402 transitions, written out independently of the module's table.
EXPECTED = {
    2: (State.SWITCH_ON_DISABLED, State.READY_TO_SWITCH_ON, 0x06),
    3: (State.READY_TO_SWITCH_ON, State.SWITCHED_ON, 0x07),
    4: (State.SWITCHED_ON, State.OPERATION_ENABLED, 0x0F),
    5: (State.OPERATION_ENABLED, State.SWITCHED_ON, 0x07),
    6: (State.SWITCHED_ON, State.READY_TO_SWITCH_ON, 0x06),
    7: (State.READY_TO_SWITCH_ON, State.SWITCH_ON_DISABLED, 0x00),
    8: (State.OPERATION_ENABLED, State.READY_TO_SWITCH_ON, 0x06),
    9: (State.OPERATION_ENABLED, State.SWITCH_ON_DISABLED, 0x00),
    10: (State.SWITCHED_ON, State.SWITCH_ON_DISABLED, 0x00),
    11: (State.OPERATION_ENABLED, State.QUICK_STOP_ACTIVE, 0x02),
    12: (State.QUICK_STOP_ACTIVE, State.SWITCH_ON_DISABLED, 0x00),
    15: (State.FAULT, State.SWITCH_ON_DISABLED, 0x80),
    16: (State.QUICK_STOP_ACTIVE, State.OPERATION_ENABLED, 0x0F),
}
ALLOWED = {(a, b): cw for a, b, cw in EXPECTED.values()}


@pytest.mark.parametrize("current", list(State), ids=lambda s: s.name)
@pytest.mark.parametrize("target", list(State), ids=lambda s: s.name)
def test_every_transition_pair(current: State, target: State) -> None:
    if (current, target) in ALLOWED:
        assert controlword_for(current, target) == ALLOWED[(current, target)]
    else:
        with pytest.raises(IllegalTransitionError, match=f"{current.label} -> {target.label}"):
            controlword_for(current, target)


def test_tables_match_canopen_p402() -> None:
    """Our masks and transitions equal canopen's ``State402`` (its automatic ones left out)."""
    by_label = {s.label: s for s in State}
    assert {s.label: (m, s.value) for s, m in enums.STATUSWORD_MASK.items()} == State402.SW_MASK
    theirs = {(by_label[a], by_label[b]): cw for (a, b), cw in State402.TRANSITIONTABLE.items()
              if a != "START" and (by_label[a], by_label[b]) not in enums.AUTOMATIC_TRANSITIONS}
    assert enums.TRANSITIONS == theirs == ALLOWED


def test_statusword_matches_at_most_one_state() -> None:
    for low in range(0x80):  # the masks only look at bits 0..6
        hits = [s for s, m in enums.STATUSWORD_MASK.items() if low & m == s.value]
        assert len(hits) <= 1
        assert state_from_statusword(low | 0xFF80) == (hits[0] if hits else None)


@pytest.mark.parametrize("start", list(State), ids=lambda s: s.name)
def test_path_toward_enabled(start: State) -> None:
    state, hops = start, 0
    while state is not State.OPERATION_ENABLED:
        nxt = enums.NEXT_TOWARD_ENABLED[state]
        assert (state, nxt) in enums.TRANSITIONS or (state, nxt) in enums.AUTOMATIC_TRANSITIONS
        state, hops = nxt, hops + 1
    assert hops <= 5


@pytest.mark.parametrize(("current", "target"), list(ALLOWED), ids=str)
def test_simulator_obeys_table(current: State, target: State) -> None:
    """Each transition's controlword takes the simulated drive there once the transition's
    delay has passed, as a device confirms a transition when it is done."""
    sim = Cia402Simulator(MotorConfig("x", "cia402", 3))
    if current is State.QUICK_STOP_ACTIVE:
        sim.od.set(0x605A, 6)  # transition 16 only with quick stop option codes 5 to 8
    sim.state = current
    reply = sim.handle(make_sdo_download(3, 0x6040, 0, controlword_for(current, target), U16), 0.0)
    assert reply == [make_sdo_download_ack(3, 0x6040, 0)]
    delay = sim.timing.delay(target)
    assert delay > 0.0
    sim.handle(make_sdo_upload(3, 0x6041, 0), 0.5 * delay)  # (an upload advances its clock)
    assert sim.state is current
    sim.handle(make_sdo_upload(3, 0x6041, 0), delay)
    assert sim.state is target


# ===================================================================== configuration steps


def test_configuration_steps_sync() -> None:
    steps = configuration_steps(3, NodeOptions())
    writes = [(s.index, s.subindex, s.value) for s in steps if isinstance(s, SdoWriteStep)]
    assert steps[0] == NmtStep(NmtCommand.ENTER_PRE_OPERATIONAL)
    assert steps[-1] == NmtStep(NmtCommand.START)
    assert isinstance(steps[-2], SdoExpectStep) and steps[-2].index == 0x6061
    rpdo4 = [w for w in writes if w[0] in (0x1403, 0x1603)]
    assert rpdo4 == [(0x1403, 1, 0x80000503), (0x1603, 0, 0), (0x1603, 1, 0x60400010),
                     (0x1603, 2, 0x60FF0020), (0x1603, 0, 2), (0x1403, 2, 1), (0x1403, 1, 0x503)]
    assert (0x1A02, 2, 0x60640020) in writes and (0x1A03, 2, 0x606C0020) in writes
    assert (0x1800, 1, 0x80000183) in writes and (0x1801, 1, 0x80000283) in writes
    assert (0x1017, 0, 100) in writes and (0x6060, 0, 3) in writes
    assert not any(w[0] in (0x1802, 0x1803) and w[1] == 5 for w in writes)
    # the controller-side protection: written after 0x1017, read back, all before 0x6060
    order = [(type(s).__name__, s.index) for s in steps
             if isinstance(s, (SdoWriteStep, SdoVerifyStep)) and s.index in
             (0x1017, 0x1016, 0x6007, 0x6060)]
    assert order == [("SdoWriteStep", 0x1017), ("SdoWriteStep", 0x1016),
                     ("SdoWriteStep", 0x6007), ("SdoVerifyStep", 0x1016),
                     ("SdoVerifyStep", 0x6007), ("SdoWriteStep", 0x6060)]
    assert (0x1016, 1, 0x007F00C8) in writes and (0x6007, 0, 3) in writes


def test_configuration_steps_event_driven() -> None:
    opts = NodeOptions(sync=False, event_timer_ms=20, layout=PdoLayout(1, 2, 3))
    writes = {(s.index, s.subindex): s.value for s in configuration_steps(9, opts)
              if isinstance(s, SdoWriteStep)}
    assert writes[(0x1400, 2)] == writes[(0x1801, 2)] == writes[(0x1802, 2)] == 255
    assert writes[(0x1801, 5)] == writes[(0x1802, 5)] == 20
    assert writes[(0x1400, 1)] == 0x209 and writes[(0x1803, 1)] == 0x80000489


def _cw(frames: list[Frame]) -> list[int]:
    return [unpack_pdo(f, "RPDO")[0] for f in frames if f.arbitration_id == 0x503]


def _phase(seq: NodeSequencer) -> Phase:  # a call, so mypy does not narrow the attribute
    return seq.phase


def test_scripted_walk_from_fault() -> None:
    """Scripted statuswords in, controlwords out (canopen-style TX/RX script)."""
    seq = NodeSequencer(3, "node 3", Cia402Codec({3: PdoLayout()}), ())
    assert seq.start(0.0) == [] and _phase(seq) is Phase.AWAIT_STATUS
    t = 0.0
    script = [  # statusword the drive reports -> controlwords the sequencer sends meanwhile
        (0x0218, [0x0000, 0x0080, 0x0000]),  # FAULT: bit 7 low first, then the rising edge
        (0x0250, [0x0006]),  # SWITCH ON DISABLED -> shutdown
        (0x0231, [0x0007]),  # READY TO SWITCH ON -> switch on
        (0x0233, [0x000F]),  # SWITCHED ON -> enable operation
    ]
    for statusword, words in script:
        seq.on_status(statusword)
        sent: list[int] = []
        for _ in range(round(2.5 * seq.CW_RESEND_S / DT)):
            t += DT
            sent += _cw(seq.poll(t))
        assert sent[:len(words)] == words, hex(statusword)
    seq.on_status(0x1237)
    assert seq.poll(t + DT) == [] and _phase(seq) is Phase.ARMED


def test_scripted_stop() -> None:
    seq = NodeSequencer(3, "node 3", Cia402Codec({3: PdoLayout()}), ())
    seq.start(0.0)
    seq.on_status(0x0237)  # OPERATION ENABLED, moving
    seq.poll(0.001)
    assert _phase(seq) is Phase.ARMED
    assert _cw(seq.stop(0.002)) == [0x000F]  # keep enabled, target 0
    assert _cw(seq.poll(0.003)) == []
    assert _cw(seq.poll(0.03)) == [0x000F]  # resent
    seq.on_status(0x1237)  # speed 0
    assert _cw(seq.poll(0.031)) == [0x0006]  # shutdown
    seq.on_status(0x1231)  # READY TO SWITCH ON
    assert seq.poll(0.032) == [] and _phase(seq) is Phase.IDLE
    configuring = NodeSequencer(3, "n", Cia402Codec({3: PdoLayout()}),
                                configuration_steps(3, NodeOptions()))
    assert len(configuring.start(0.0)) == 2  # NMT pre-op + the first SDO
    assert configuring.stop(0.01) == [] and _phase(configuring) is Phase.IDLE


# ===================================================================== virtual bus harness
