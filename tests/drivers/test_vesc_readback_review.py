"""The VESC's timeout read (drivers/vesc/readback.py, appconf.py) as the driver reports it
afterwards: what a disable keeps, what a lost frame costs, and which fix it offers.

The VESCs are simulated (drivers/vesc/sim.py) and their replies handed to the driver frame by
frame, some of them lost or corrupted on the way (``mangle``).
"""

from __future__ import annotations

import re
from typing import TYPE_CHECKING

import pytest

from drivers.vesc import VescDriver
from drivers.vesc.appconf import BufferPacket, Reassembly, make_get_appconf
from drivers.vesc.readback import Outcome
from drivers.vesc.sim import simulator_for
from drivers.vesc.sim_appconf import AppconfResponder, send_buffer
from gateway.core.errors import DecodeError
from gateway.core.protection import Guard, ProtectionState
from gateway.core.status import ControllerStop
from gateway.core.types import Frame
from tests.drivers.test_drivers_vesc import motor
from tests.drivers.test_vesc_helpers import enabled

if TYPE_CHECKING:
    from collections.abc import Callable

    from drivers.vesc.sim import VescSimulator

GAP = "FILL_RX_BUFFER: expected offset 70 (the bytes so far), got 77: a frame was lost"


def drivers(*stated: float, **sim_kwargs: object) -> tuple[VescDriver, list[VescSimulator]]:
    """VESCs 23, 24... stating these controller_timeout_s, and their simulators."""
    drv = VescDriver([motor(23 + i, wheel=f"w{i}", controller_timeout_s=s)
                      for i, s in enumerate(stated)])
    sims = [simulator_for(m) for m in drv.motors]
    for sim in sims:
        for key, value in sim_kwargs.items():
            setattr(sim, key, value)
    return drv, sims


def run(drv: VescDriver, sims: list[VescSimulator], requests: list[Frame], t: float,
        until: float, mangle: Callable[[list[Frame], int], list[Frame]] | None = None,
        ) -> float:
    """Answer the requests and the polls' requests every 10 ms from ``t`` to ``until``, each
    COMM_GET_APPCONF reply through ``mangle`` (with its number in the run, from 0)."""
    replies = 0
    while t < until:
        for f in requests:
            for sim in sims:
                reply = sim.handle(f, t)
                if reply and f.arbitration_id >> 8 == BufferPacket.PROCESS_SHORT_BUFFER:
                    reply = mangle(reply, replies) if mangle else reply
                    replies += 1
                for r in reply:
                    drv.on_frame(r.stamped(t))
        t = round(t + 0.01, 6)
        requests = drv.poll(t)
    return t


def stop_of(drv: VescDriver, i: int = 0) -> ControllerStop:
    """What ``wheelgate status`` reports of motor ``i``'s controller stop."""
    prot = drv.protection(i)
    return ControllerStop(prot.guard, prot.timeout_s, drv.protection_state(i))


# ================================================================ a disable keeps the reads


@pytest.mark.parametrize(("sim_timeout_s", "responder", "stop", "how"), [
    (0.0, None, ControllerStop(Guard.STATED, None, ProtectionState.FAILED),
     "read back from the VESC other than it must be: the VESC's timeout (App Settings > "
     "General > Timeout, timeout_msec) reads 0 ms"),
    (1.0, None, ControllerStop(Guard.STATED, 1.0, ProtectionState.CONFIRMED),
     "set in VESC Tool; stated by controller_timeout_s and read back from the VESC "
     "(timeout_msec 1000 ms)"),
    (1.0, AppconfResponder(answers=False),
     ControllerStop(Guard.STATED, 1.0, ProtectionState.NOT_APPLICABLE),
     "set in VESC Tool; stated by controller_timeout_s; could not be read back from the VESC: "
     "no reply to COMM_GET_APPCONF"),
])
def test_a_disable_keeps_what_was_read_until_the_next_enable(
        sim_timeout_s: float, responder: AppconfResponder | None, stop: ControllerStop,
        how: str) -> None:
    drv, sims = drivers(1.0, timeout_s=sim_timeout_s)
    if responder is not None:
        sims[0].appconf = responder
    t = run(drv, sims, drv.enable(0.0), 0.0, 1.0)
    assert stop_of(drv) == stop
    prot, why, detail = drv.protection(0), drv.protection_failure(0), drv.detail(0)
    assert prot.how.startswith(how)
    for disable in (1, 2):  # fault_action disarm, an e-stop, the user's disable; twice
        drv.disable(t + disable)
        assert stop_of(drv) == stop  # not the stated 1 s, PENDING, of a VESC never read
        assert drv.protection(0) == prot
        assert (drv.protection_failure(0), drv.detail(0)) == (why, detail)
    # The next enable forgets it and reads again.
    requests = drv.enable(t + 3.0)
    assert drv.protection_state(0) is ProtectionState.PENDING
    assert requests == [make_get_appconf(23)]
    sims[0].timeout_s, sims[0].appconf = 1.0, AppconfResponder()
    run(drv, sims, requests, t + 3.0, t + 3.1)
    assert stop_of(drv) == ControllerStop(Guard.STATED, 1.0, ProtectionState.CONFIRMED)


def test_a_disable_during_the_reads_keeps_those_done_and_cancels_the_rest() -> None:
    drv, sims = drivers(1.0, 1.0)
    sims[1].timeout_s = 0.0
    first = drv.enable(0.0)
    for r in sims[0].handle(first[0], 0.0):
        drv.on_frame(r.stamped(0.0))
    second = drv.poll(0.01)
    assert make_get_appconf(24) in second
    drv.disable(0.02)  # before VESC 24 answers
    assert [stop_of(drv, i) for i in (0, 1)] == [
        ControllerStop(Guard.STATED, 1.0, ProtectionState.CONFIRMED),
        ControllerStop(Guard.STATED, 1.0, ProtectionState.PENDING),  # not read: as never read
    ]
    assert "read back from the VESC while enabling" in drv.protection(1).how
    for r in sims[1].handle(second[0], 0.03):  # its reply, after the disable
        assert drv.on_frame(r.stamped(0.03))
    assert drv.poll(0.3) == [] and drv.poll(3.0) == []  # disabled: no request, no give-up
    assert [drv.protection_state(i) for i in (0, 1)] == [
        ProtectionState.CONFIRMED, ProtectionState.PENDING]
    assert not drv.rejected
    run(drv, sims, drv.enable(4.0), 4.0, 4.1)
    assert [drv.protection_state(i) for i in (0, 1)] == [
        ProtectionState.CONFIRMED, ProtectionState.FAILED]


def test_a_vesc_never_enabled_is_pending_as_the_contract_says() -> None:
    drv, _ = drivers(1.0)
    assert stop_of(drv) == ControllerStop(Guard.STATED, 1.0, ProtectionState.PENDING)
    drv.disable(0.0)
    assert stop_of(drv) == ControllerStop(Guard.STATED, 1.0, ProtectionState.PENDING)


# ================================================================ a lost frame is one error


def lose(index: int, *, replies: tuple[int, ...] = (0, 1, 2)) -> Callable[
        [list[Frame], int], list[Frame]]:
    """Lose the frame at ``index`` of these replies (10: FILL_RX_BUFFER at offset 70)."""
    def mangle(frames: list[Frame], reply: int) -> list[Frame]:
        return frames[:index] + frames[index + 1:] if reply in replies else frames
    return mangle


def test_one_lost_frame_per_reply_is_one_rejection_each_and_the_gap_is_the_reason() -> None:
    drv, sims = drivers(1.0)
    run(drv, sims, drv.enable(0.0), 0.0, 1.0, lose(10))
    assert dict(drv.rejected) == {"malformed": 3}  # three replies, one frame lost of each
    assert drv.last_rejection["malformed"] == GAP
    result = drv.readback.results[0] if drv.readback else None
    assert result is not None and result.outcome is Outcome.NOT_READ
    assert result.why == f"the reply was malformed: {GAP}"
    assert drv.protection(0).how.endswith(f"could not be read back from the VESC: {result.why}")
    assert stop_of(drv) == ControllerStop(Guard.STATED, 1.0, ProtectionState.NOT_APPLICABLE)


@pytest.mark.parametrize("lost", [1, 40, 76, 77])  # a FILL, a _LONG, the last _LONG, the end
def test_the_retry_after_a_lost_frame_is_read(lost: int) -> None:
    drv, sims = drivers(1.0)
    run(drv, sims, drv.enable(0.0), 0.0, 0.5, lose(lost, replies=(0,)))
    assert drv.protection_state(0) is ProtectionState.CONFIRMED
    assert sum(drv.rejected.values()) == (0 if lost == 77 else 1)  # a lost end: silence


def test_the_first_error_of_a_read_stays_its_reason() -> None:
    def mangle(frames: list[Frame], reply: int) -> list[Frame]:
        if reply == 0:
            return lose(10)(frames, reply)
        if reply == 1:  # then a reply whose CRC is wrong
            end = frames[-1]
            crc = bytes((end.data[4] ^ 1, end.data[5]))
            return [*frames[:-1], Frame(end.arbitration_id, bytes(end.data[:4]) + crc, True)]
        return []  # then none

    drv, sims = drivers(1.0)
    run(drv, sims, drv.enable(0.0), 0.0, 1.0, mangle)
    assert dict(drv.rejected) == {"malformed": 2}
    assert drv.last_rejection["malformed"].startswith("PROCESS_RX_BUFFER: expected crc16")
    assert drv.readback is not None
    assert drv.readback.results[0].why == f"the reply was malformed: {GAP}"


def test_after_a_gap_the_rest_of_that_reply_is_dropped_without_another_error() -> None:
    data = bytes(range(40))
    frames = send_buffer(254, 23, data)  # offsets 0, 7, ... 35, then the end
    rx = Reassembly()
    rx.feed(frames[0])
    with pytest.raises(DecodeError, match=re.escape(
            "FILL_RX_BUFFER: expected offset 7 (the bytes so far), got 14: a frame was lost")):
        rx.feed(frames[2])
    assert [rx.feed(f) for f in frames[3:]] == [None] * len(frames[3:])  # no error
    reply = None
    for f in frames:  # the next reply, whole
        reply = rx.feed(f)
    assert reply is not None and reply.payload == data
    # After the end of the reply that went wrong, the next one's loss is an error again.
    rx.feed(frames[0])
    with pytest.raises(DecodeError, match=r"expected offset 7 .* got 21"):
        rx.feed(frames[3])
    assert [rx.feed(f) for f in frames[4:]] == [None] * len(frames[4:])
    with pytest.raises(DecodeError, match=r"expected offset 0 .* got 7"):
        rx.feed(frames[1])
    # A reply joined in the middle is one error too.
    rx = Reassembly()
    with pytest.raises(DecodeError, match=r"expected offset 0 .* got 7"):
        rx.feed(frames[1])
    assert [rx.feed(f) for f in frames[2:]] == [None] * len(frames[2:])


# ================================================================ a fix the config takes


@pytest.mark.parametrize(("read_ms", "period_s"), [
    (30, 0.02), (40, 0.02), (41, 0.02), (100, 0.02), (2000, 0.02), (150, 0.1), (200, 0.1),
    (201, 0.1),
])
def test_the_fix_for_a_differing_timeout_is_one_the_configuration_takes(
        read_ms: int, period_s: float) -> None:
    drv = VescDriver([motor(23, controller_timeout_s=1.0, command_period_s=period_s)])
    enabled(drv, 0.0, read_ms={23: read_ms})
    assert drv.protection_state(0) is ProtectionState.FAILED
    fix = drv.protection(0).fix
    assert f"fix: {fix}" in drv.detail(0)
    assert "set App Settings > General > Timeout in VESC Tool to 1000 ms" in fix
    offered = re.search(r"controller_timeout_s: ([0-9.]+)", fix)
    if period_s < read_ms / 2000.0:
        assert offered is not None and float(offered.group(1)) == read_ms / 1000.0
        VescDriver([motor(23, controller_timeout_s=float(offered.group(1)),
                          command_period_s=period_s)])  # the configuration takes it
    else:
        assert offered is None
        assert f"the VESC's {read_ms} ms cannot be stated" in fix
        assert (f"command_period_s {period_s:g} s, must be less than half the VESC's timeout "
                f"({read_ms / 2000.0:g} s)") in fix
