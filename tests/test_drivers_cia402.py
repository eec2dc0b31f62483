"""Tests of the CANopen CiA 402 driver: codec, state machine, enable sequence, simulator.

Golden frames come from ``/work/shared/specs/can-protocols.md`` section 3, "Worked examples
(node 3)" and "Verified on the virtual bus" (frames captured from canopen 2.4.1).  The
``canopen`` library serves as an independent cross-check of our SDO frames, the state table and
the abort-code texts; it is never used by the driver itself.
"""

from __future__ import annotations

import dataclasses
import math
from typing import TYPE_CHECKING

import can
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
from drivers.cia402.steps import NmtStep, SdoExpectStep, SdoWriteStep, configuration_steps
from gateway.bus import drain, send_frames
from gateway.errors import ConfigError, DecodeError, EncodeError, IllegalTransitionError
from gateway.registry import get_driver_class
from gateway.sim import SimFault
from gateway.simbus import SimulatedControllers
from gateway.types import DriveFault, DriveState, Frame, MotorConfig

if TYPE_CHECKING:
    from collections.abc import Callable, Iterator, Sequence

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
    sim = Cia402Simulator(MotorConfig("x", "cia402", 3))
    sim.state = current
    reply = sim.handle(make_sdo_download(3, 0x6040, 0, controlword_for(current, target), U16), 0.0)
    assert reply == [make_sdo_download_ack(3, 0x6040, 0)]
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


@dataclasses.dataclass
class Bench:
    drv: Cia402Driver
    sims: Sequence[Cia402Simulator]
    gw: can.BusABC
    ctl: SimulatedControllers
    t: float = 0.0
    seen: list[Frame] = dataclasses.field(default_factory=list)
    sent: list[Frame] = dataclasses.field(default_factory=list)

    def send(self, frames: Sequence[Frame]) -> None:
        send_frames(self.gw, frames)
        self.sent += frames

    def run(self, seconds: float, speeds: Sequence[float] | None = None,
            until: Callable[[], bool] | None = None) -> bool:
        """Step simulated time; ``speeds`` None means the loop does not call command()."""
        for _ in range(round(seconds / DT)):
            self.t += DT
            self.ctl.step(self.t)
            for raw in drain(self.gw):
                f = raw.stamped(self.t)
                self.seen.append(f)
                self.drv.on_frame(f)
            out = self.drv.poll(self.t)
            if speeds is not None:
                out += self.drv.command(speeds, self.t)
            self.send(out)
            if until is not None and until():
                return True
        return until is None

    def state(self, i: int = 0) -> DriveState:
        return self.drv.state(i, self.t)

    def enable(self, speeds: Sequence[float] | None = None, seconds: float = 0.5) -> bool:
        self.send(self.drv.enable(self.t))
        return self.run(seconds, speeds, until=lambda: all(
            self.state(i) is DriveState.ENABLED for i in range(len(self.sims))))


@pytest.fixture
def bench(channel: str) -> Iterator[Callable[..., Bench]]:
    made: list[Bench] = []

    def make(motors: Sequence[MotorConfig], **sim_kwargs: object) -> Bench:
        drv = Cia402Driver(motors)
        sims = [Cia402Simulator(m, **sim_kwargs) for m in motors]  # type: ignore[arg-type]
        ctl = SimulatedControllers(sims, channel)
        try:
            gw = can.Bus(interface="virtual", channel=channel)
        except Exception:
            ctl.shutdown()
            raise
        made.append(Bench(drv, sims, gw, ctl))
        return made[-1]

    yield make
    for b in made:
        b.gw.shutdown()
        b.ctl.shutdown()


LEFT = MotorConfig("left", "cia402", 3, gear_ratio=10.0)
RIGHT = MotorConfig("right", "cia402", 5, gear_ratio=10.0, invert=True)
COUNT_RAD = TWO_PI / 4096 / 10.0  # one position count at the wheel


def test_enable_drive_and_read_position(bench: Callable[..., Bench]) -> None:
    b = bench([LEFT, RIGHT])
    assert b.enable([0.0, 0.0])
    for sim in b.sims:  # the gateway's layout, not the simulator's defaults
        assert sim.object_value(0x1603, 1) == 0x60400010
        assert sim.object_value(0x1603, 2) == 0x60FF0020
        assert sim.object_value(0x1A02, 2) == 0x60640020
        assert sim.object_value(0x1A03, 2) == 0x606C0020
        assert sim.object_value(0x1800, 1) & 0x80000000
        assert sim.object_value(0x6061) == 3 and sim.object_value(0x1017) == 100
        assert sim.state is State.OPERATION_ENABLED and sim.aborts == 0
    start = len(b.sent)
    b.run(1.0, [4.0, -2.5])
    cycles = 1000
    assert sum(f.arbitration_id == 0x080 for f in b.sent[start:]) == cycles  # one SYNC per bus
    for i, (sim, want) in enumerate(zip(b.sims, (4.0, -2.5), strict=True)):
        fb = b.drv.feedback(i)
        assert fb is not None
        assert fb.velocity_rad_s == pytest.approx(want, abs=TWO_PI / 60 / 10)  # 1 RPM motor
        assert sim.wheel_velocity_rad_s == pytest.approx(want, abs=0.01)
    b.run(0.3, [0.0, 0.0])
    for i, sim in enumerate(b.sims):
        fb = b.drv.feedback(i)
        assert fb is not None
        assert fb.position_rad == pytest.approx(sim.wheel_position_rad, abs=1.01 * COUNT_RAD)
    assert b.drv.feedback(0).position_rad > 3.5  # type: ignore[union-attr]
    assert b.drv.feedback(1).position_rad < -2.0  # type: ignore[union-attr]
    assert not any(f.arbitration_id in (0x183, 0x283, 0x185, 0x285) for f in b.seen)
    assert not b.drv.rejected


def test_position_wraps_int32_end_to_end(bench: Callable[..., Bench]) -> None:
    motor = MotorConfig("left", "cia402", 3, gear_ratio=1.0, options={"counts_per_rev": 4096})
    b = bench([motor], initial_position=(1 << 31) - 3000)
    assert b.enable([0.0])
    b.run(1.5, [6.0])
    b.run(0.3, [0.0])
    assert b.sims[0].position_counts < 0  # wrapped
    fb = b.drv.feedback(0)
    assert fb is not None and fb.position_rad > 8.0
    assert fb.position_rad == pytest.approx(b.sims[0].wheel_position_rad, abs=TWO_PI / 4096)


def test_event_driven_pdos_without_sync(bench: Callable[..., Bench]) -> None:
    motor = MotorConfig("left", "cia402", 3, options={"sync": False, "event_timer_ms": 10})
    b = bench([motor])
    assert b.enable([0.0])
    sim = b.sims[0]
    assert sim.object_value(0x1403, 2) == 255 and sim.object_value(0x1802, 5) == 10
    b.run(0.5, [20.0])
    assert not any(f.arbitration_id == 0x080 for f in b.sent)
    assert sim.syncs == 0 and sim.wheel_velocity_rad_s == pytest.approx(20.0, abs=0.1)
    beats = [f for f in b.seen if f.arbitration_id == 0x703 and f.timestamp_s > b.t - 0.5]
    assert len(beats) == 5 and beats[-1].data == b"\x05"  # 100 ms, OPERATIONAL
    fb = b.drv.feedback(0)
    assert fb is not None and fb.velocity_rad_s == pytest.approx(20.0, abs=0.11)


def test_poll_alone_produces_sync_every_10_ms(bench: Callable[..., Bench]) -> None:
    b = bench([LEFT])
    b.run(0.1)
    assert sum(f.arbitration_id == 0x080 for f in b.sent) in (10, 11)


@pytest.mark.parametrize("start", [s for s in State if s is not State.FAULT_REACTION_ACTIVE],
                         ids=lambda s: s.name)
def test_enable_from_any_drive_state(bench: Callable[..., Bench], start: State) -> None:
    b = bench([LEFT])
    b.sims[0].state = start
    assert b.enable()
    assert b.drv.drive_state(0) is State.OPERATION_ENABLED


def test_emcy_fault_and_recover(bench: Callable[..., Bench]) -> None:
    b = bench([LEFT])
    assert b.enable([1.0])
    b.run(0.2, [1.0])
    b.sims[0].inject(SimFault.FAULT)
    assert b.run(0.1, [1.0], until=lambda: b.state() is DriveState.FAULT)
    status = b.drv.status(b.t)[0]
    assert DriveFault.OVER_CURRENT in status.faults
    assert "EMCY 0x2310 Continuous over-current" in status.detail
    assert 'node 3 ("left")' in status.detail
    assert b.drv.command([1.0], b.t) == [make_sync()]  # no RPDO while faulted
    # the fault is still active in the drive: the fault reset does not take
    b.send(b.drv.enable(b.t))
    assert b.run(1.0, until=lambda: b.drv.phase(0) is Phase.FAILED)
    status = b.drv.status(b.t)[0]
    assert "no transition FAULT -> SWITCH ON DISABLED" in status.detail
    assert "EMCY 0x2310" in status.detail and DriveFault.OVER_CURRENT in status.faults
    # cleared in the drive: enable resets the fault and arms again
    b.sims[0].clear(SimFault.FAULT)
    assert b.enable([1.0])
    status = b.drv.status(b.t)[0]
    assert (status.faults, status.detail) == (DriveFault.NONE, "")
    b.run(0.2, [1.0])
    assert b.sims[0].wheel_velocity_rad_s == pytest.approx(1.0, abs=0.01)


def test_statusword_fault_without_emcy(bench: Callable[..., Bench]) -> None:
    b = bench([LEFT])
    assert b.enable([0.0])
    b.drv.on_frame(Frame(0x383, make_tpdo(0x383, 0x0218, 0).data, timestamp_s=b.t))
    assert b.state() is DriveState.FAULT
    status = b.drv.status(b.t)[0]
    assert status.faults == DriveFault.CONTROLLER
    assert "statusword 0x0218 reports FAULT" in status.detail


def test_silence_goes_offline_and_back(bench: Callable[..., Bench]) -> None:
    b = bench([LEFT])
    assert b.enable([0.0])
    b.sims[0].inject(SimFault.SILENT)
    b.run(0.2, [0.0])
    assert b.state() is DriveState.ENABLED  # within liveness_s = 0.25 s
    b.run(0.1, [0.0])
    assert b.state() is DriveState.OFFLINE
    b.sims[0].clear(SimFault.SILENT)
    b.run(0.05, [0.0])
    assert b.state() is DriveState.ENABLED


@pytest.mark.parametrize(
    ("sim_kwargs", "expected"),
    [
        ({"missing_objects": (0x1017,)},
         "SDO write of 100 to 0x1017:00 (producer heartbeat time) aborted: "
         "0x06020000 Object does not exist"),
        ({"supported_modes": 0x01},
         "SDO write of 3 to 0x6060:00 (modes of operation = profile velocity) aborted: "
         "0x06090030 Value range of parameter exceeded"),
        ({"mode_switch_delay_s": 5.0},
         "0x6061:00 (modes of operation display) reads 1, expected 3 within 0.5 s"),
    ],
)
def test_enable_failure_names_the_cause(
    bench: Callable[..., Bench], sim_kwargs: dict[str, object], expected: str
) -> None:
    b = bench([LEFT], **sim_kwargs)
    b.send(b.drv.enable(b.t))
    assert b.run(1.0, until=lambda: b.drv.phase(0) is Phase.FAILED)
    status = b.drv.status(b.t)[0]
    assert status.state is DriveState.FAULT
    assert status.detail == f'node 3 ("left"): {expected}'
    assert b.sims[0].nmt is NmtState.PRE_OPERATIONAL  # never started


def test_slow_mode_switch_is_waited_for(bench: Callable[..., Bench]) -> None:
    b = bench([LEFT], mode_switch_delay_s=0.05)
    b.send(b.drv.enable(b.t))
    b.run(0.04)
    assert b.state() is DriveState.ENABLING and b.drv.phase(0) is Phase.CONFIGURING
    assert b.run(0.5, until=lambda: b.state() is DriveState.ENABLED)
    assert b.drv.enable(b.t) == []  # already armed: nothing to do


def test_sdo_timeout_of_a_silent_node(bench: Callable[..., Bench]) -> None:
    b = bench([LEFT])
    b.sims[0].inject(SimFault.SILENT)
    b.send(b.drv.enable(b.t))
    assert b.state() is DriveState.OFFLINE
    assert b.run(1.0, until=lambda: b.drv.phase(0) is Phase.FAILED)
    status = b.drv.status(b.t)[0]
    assert status.faults == DriveFault.COMMUNICATION
    assert "no SDO response within 0.5 s to the write of 2147484931 to 0x1403:01" in status.detail


def test_transition_timeout(bench: Callable[..., Bench], monkeypatch: pytest.MonkeyPatch) -> None:
    b = bench([LEFT])
    monkeypatch.setattr(b.sims[0], "_apply_controlword", lambda cw: None)
    b.send(b.drv.enable(b.t))
    assert b.run(1.5, until=lambda: b.drv.phase(0) is Phase.FAILED)
    assert b.drv.status(b.t)[0].detail.endswith(
        "no transition SWITCH ON DISABLED -> READY TO SWITCH ON within 0.5 s after "
        "controlword 0x0006 (statusword 0x1260)")


def test_disable_brakes_then_shuts_down(bench: Callable[..., Bench]) -> None:
    b = bench([LEFT])
    assert b.enable([0.0])
    b.run(0.3, [30.0])
    frames = b.drv.disable(b.t)
    assert frames == [Frame(0x503, hexb("0F 00 00 00 00 00")), make_sync()]
    b.send(frames)
    sim, speed_at_shutdown = b.sims[0], None
    for _ in range(600):
        b.run(DT, [30.0])  # the loop keeps calling command(): ignored once disarmed
        if speed_at_shutdown is None and sim.state is not State.OPERATION_ENABLED:
            speed_at_shutdown = sim.model.velocity_rad_s
    assert sim.state is State.READY_TO_SWITCH_ON
    assert speed_at_shutdown is not None and abs(speed_at_shutdown) < TWO_PI / 60
    assert b.state() is DriveState.DISABLED and b.drv.phase(0) is Phase.IDLE


def test_drive_watchdog_fault(bench: Callable[..., Bench]) -> None:
    b = bench([LEFT], command_timeout_s=0.05)
    assert b.enable([0.0])
    assert b.run(0.2, None, until=lambda: b.state() is DriveState.FAULT)  # no command()
    status = b.drv.status(b.t)[0]
    assert DriveFault.WATCHDOG in status.faults and "RPDO timeout" in status.detail


@pytest.mark.parametrize(
    ("command", "expected"),
    [(NmtCommand.RESET_NODE, "rebooted (boot-up message)"),
     (NmtCommand.ENTER_PRE_OPERATIONAL, "heartbeat reports NMT PRE_OPERATIONAL")],
)
def test_nmt_change_while_armed(
    bench: Callable[..., Bench], command: NmtCommand, expected: str
) -> None:
    b = bench([LEFT])
    assert b.enable([0.0])
    b.send([make_nmt(command, 3)])
    assert b.run(0.3, [0.0], until=lambda: b.state() is DriveState.FAULT)
    status = b.drv.status(b.t)[0]
    assert expected in status.detail and DriveFault.COMMUNICATION in status.faults


# ===================================================================== canopen cross-checks


def _od(*entries: tuple[int, int, int]) -> canopen.ObjectDictionary:
    od = canopen.ObjectDictionary()  # type: ignore[no-untyped-call]
    for index, dtype, default in entries:
        var = canopen.objectdictionary.ODVariable(f"x{index:04X}", index, 0)
        var.data_type, var.access_type, var.default = dtype, "rw", default
        od.add_object(var)
    return od


def _recv(bus: can.BusABC, cob: int) -> Frame:
    for _ in range(200):
        msg = bus.recv(0.02)
        if msg is not None and msg.arbitration_id == cob:
            return Frame(cob, bytes(msg.data))
    raise AssertionError(f"no frame 0x{cob:03X}")


def test_our_sdo_client_frames_against_canopen_server(channel: str) -> None:
    net = canopen.Network()
    net.NOTIFIER_CYCLE = 0.02
    node = canopen.LocalNode(3, _od((0x6060, canopen.objectdictionary.INTEGER8, 1),
                                    (0x60FF, canopen.objectdictionary.INTEGER32, 0)))
    net.add_node(node)
    net.connect(interface="virtual", channel=channel)
    gw = can.Bus(interface="virtual", channel=channel)
    try:
        send_frames(gw, [make_sdo_download(3, 0x60FF, 0, -1000, DataType.INTEGER32)])
        ack = parse_sdo_response(_recv(gw, 0x583))
        assert (ack.command, ack.index) == (ServerCommand.INITIATE_DOWNLOAD, 0x60FF)
        assert node.get_data(0x60FF, 0) == (-1000).to_bytes(4, "little", signed=True)
        send_frames(gw, [make_sdo_upload(3, 0x6060, 0)])
        assert parse_sdo_response(_recv(gw, 0x583)).value(DataType.INTEGER8) == 1
        send_frames(gw, [make_sdo_upload(3, 0x2000, 0)])
        abort = parse_sdo_response(_recv(gw, 0x583))
        assert abort.abort_code == 0x06020000
    finally:
        gw.shutdown()
        net.disconnect()


def test_canopen_client_against_our_simulator(channel: str) -> None:
    sim = Cia402Simulator(LEFT)
    net = canopen.Network()
    net.NOTIFIER_CYCLE = 0.02
    with SimulatedControllers([sim], channel) as ctl:
        ctl.start()
        node = canopen.RemoteNode(3, canopen.ObjectDictionary())  # type: ignore[no-untyped-call]
        net.add_node(node)
        net.connect(interface="virtual", channel=channel)
        try:
            node.sdo.RESPONSE_TIMEOUT = 2.0
            node.sdo.download(0x6060, 0, b"\x03")
            assert node.sdo.upload(0x6061, 0) == b"\x03"
            assert node.sdo.upload(0x6502, 0) == (0x6D).to_bytes(4, "little")
            node.sdo.download(0x6040, 0, b"\x06\x00")
            assert node.sdo.upload(0x6041, 0)[0] & 0x6F == State.READY_TO_SWITCH_ON
            with pytest.raises(SdoAbortedError) as err:
                node.sdo.upload(0x2000, 0)
            assert err.value.code == 0x06020000
            with pytest.raises(SdoAbortedError) as err:
                node.sdo.download(0x6041, 0, b"\x00\x00")
            assert err.value.code == 0x06010002
            with pytest.raises(SdoAbortedError) as err:  # remap while the PDO is valid
                node.sdo.download(0x1A00, 0, b"\x00")
            assert err.value.code == 0x08000022
        finally:
            net.disconnect()
