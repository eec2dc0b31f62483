"""The CiA 402 state machine as tables, the simulated drive against them, and the enable and
stop sequences of one node: the configuration steps written into it, then controlwords walked
against scripted statuswords (canopen-style TX/RX scripts).

The tables are checked against an independent transcription of CiA 402 and against
``canopen.profiles.p402.State402`` (https://github.com/canopen-python/canopen).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import pytest
from canopen.profiles.p402 import State402

from drivers.cia402 import Cia402Codec, Cia402Options, PdoLayout, enums
from drivers.cia402.codec import unpack_pdo
from drivers.cia402.enums import NmtCommand, State, controlword_for, state_from_statusword
from drivers.cia402.phase import Phase
from drivers.cia402.sdo import make_sdo_download, make_sdo_download_ack, make_sdo_upload
from drivers.cia402.sequence import NodeSequencer
from drivers.cia402.sim import Cia402Simulator
from drivers.cia402.steps import (
    NmtStep,
    SdoExpectStep,
    SdoVerifyStep,
    SdoWriteStep,
    configuration_steps,
)
from gateway.core.errors import IllegalTransitionError
from tests import factories
from tests.drivers.cia402_bench import DT

if TYPE_CHECKING:
    from gateway.core.types import Frame

U16 = enums.DataType.UNSIGNED16


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
    sim = Cia402Simulator(factories.motor("cia402", 3, "x"))
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
    steps = configuration_steps(3, Cia402Options())
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
    opts = Cia402Options(sync=False, event_timer_ms=20, rpdo=1, tpdo_position=2, tpdo_velocity=3)
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
                                configuration_steps(3, Cia402Options()))
    assert len(configuring.start(0.0)) == 2  # NMT pre-op + the first SDO
    assert configuring.stop(0.01) == [] and _phase(configuring) is Phase.IDLE
