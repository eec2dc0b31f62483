"""The CiA 402 driver against its simulated drives on a python-can virtual bus
(:mod:`tests.drivers.cia402_bench`): enabling from any state, feedback, SYNC, faults and their
recovery, silence, stopping, and drives that take their time."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import pytest

from drivers.cia402.codec import make_nmt, make_sync, make_tpdo
from drivers.cia402.enums import NmtCommand, NmtState, State
from drivers.cia402.phase import Phase
from gateway.core.types import DriveFault, DriveState, Frame
from gateway.sim.device import SimFault
from tests import factories
from tests.drivers.cia402_bench import (
    COUNT_RAD,
    DT,
    LEFT,
    RIGHT,
    TWO_PI,
    Bench,
    benches,
    hexb,
    left,
)

if TYPE_CHECKING:
    from collections.abc import Callable, Iterator


@pytest.fixture
def bench(channel: str) -> Iterator[Callable[..., Bench]]:
    with benches(channel) as make:
        yield make


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
    motor = factories.motor("cia402", 3, "left", gear_ratio=1.0, options={"counts_per_rev": 4096})
    b = bench([motor], initial_position=(1 << 31) - 3000)
    assert b.enable([0.0])
    b.run(1.5, [6.0])
    b.run(0.3, [0.0])
    assert b.sims[0].position_counts < 0  # wrapped
    fb = b.drv.feedback(0)
    assert fb is not None and fb.position_rad > 8.0
    assert fb.position_rad == pytest.approx(b.sims[0].wheel_position_rad, abs=TWO_PI / 4096)


def test_event_driven_pdos_without_sync(bench: Callable[..., Bench]) -> None:
    motor = factories.motor("cia402", 3, "left", options={"sync": False, "event_timer_ms": 10})
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
    # A SILENT simulator hears nothing either, the gateway's heartbeat included: a consumer
    # time (1 s) longer than the 0.3 s of silence keeps the drive from stopping by itself.
    b = bench([left(controller_timeout_s=1.0)])
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


def test_a_node_silent_from_the_start_is_asked_again_until_it_answers(
        bench: Callable[..., Bench]) -> None:
    """A drive that has not booted yet (powered with the gateway's computer) hears nothing:
    the sequence starts over every ``response_timeout_s`` (NMT pre-operational, the first SDO)
    instead of failing, and goes on once the drive answers."""
    b = bench([LEFT])
    b.sims[0].inject(SimFault.SILENT)
    b.send(b.drv.enable(b.t))
    assert b.state() is DriveState.OFFLINE
    assert not b.run(1.2, until=lambda: b.drv.phase(0) is Phase.FAILED)
    first = [f for f in b.sent if f.arbitration_id == 0x603]
    assert len(first) == 3 and len(set(first)) == 1  # the same first request, 3 times
    assert sum(f.arbitration_id == 0x000 for f in b.sent) == 3  # NMT pre-operational each time
    assert b.drv.phase(0) is Phase.CONFIGURING and b.drv.status(b.t)[0].detail == ""
    b.sims[0].clear(SimFault.SILENT)
    assert b.run(1.0, until=lambda: b.state() is DriveState.ENABLED)


def test_sdo_timeout_of_a_node_that_fell_silent(bench: Callable[..., Bench]) -> None:
    """A drive that answered and then falls silent during the sequence: it fails, naming the
    step that got no answer."""
    b = bench([LEFT])
    b.send(b.drv.enable(b.t))
    assert b.run(0.1, until=lambda: sum(f.arbitration_id == 0x583 for f in b.seen) == 2)
    b.sims[0].inject(SimFault.SILENT)
    assert b.run(1.0, until=lambda: b.drv.phase(0) is Phase.FAILED)
    status = b.drv.status(b.t)[0]
    assert status.faults == DriveFault.COMMUNICATION
    assert "no SDO response within 0.5 s to the write of 0 to 0x1603:00" in status.detail


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


# ===================================================================== drives that take their time


def test_the_statusword_lags_the_controlword_and_the_driver_waits(
    bench: Callable[..., Bench]
) -> None:
    b = bench([LEFT])
    sim = b.sims[0]
    assert sim.timing.enable_s == 0.03  # the default: a device, not an instant double
    enable_sent: list[float] = []  # when ENABLE OPERATION went out during the walk
    b.send(b.drv.enable(b.t))
    for _ in range(500):
        start = len(b.sent)
        b.run(DT, [0.0])
        if any(f.arbitration_id == 0x503 and f.data[0] == 0x0F for f in b.sent[start:]):
            enable_sent.append(b.t)
        if sim.state is State.OPERATION_ENABLED:
            break
    assert sim.state is State.OPERATION_ENABLED
    assert b.t - enable_sent[0] >= 0.03 - 1e-9  # the statusword lagged by the brake's time
    assert len(enable_sent) >= 2  # the driver resent the controlword meanwhile
    assert b.run(0.1, [0.0], until=lambda: b.state() is DriveState.ENABLED)


@pytest.mark.parametrize(("enable_delay_s", "ok"), [(0.3, True), (0.7, False)])
def test_a_slow_drive_is_waited_for_up_to_the_step_timeout(
    bench: Callable[..., Bench], enable_delay_s: float, ok: bool
) -> None:
    b = bench([LEFT], enable_delay_s=enable_delay_s)
    b.send(b.drv.enable(b.t))
    b.run(1.5, [0.0], until=lambda: b.drv.phase(0) in (Phase.ARMED, Phase.FAILED))
    assert (b.drv.phase(0) is Phase.ARMED) is ok
    if not ok:
        assert ("no transition SWITCHED ON -> OPERATION ENABLED within 0.5 s after controlword "
                "0x000F") in b.drv.status(b.t)[0].detail
        b.run(1.0, [0.0])  # the driver's SHUTDOWN overtook the slow transition
        assert b.sims[0].state is State.READY_TO_SWITCH_ON


def test_the_polls_steady_state_shortcut_skips_nothing(
        bench: Callable[..., Bench], monkeypatch: pytest.MonkeyPatch) -> None:
    """Issue 15: the driver's poll skips a node in the steady state.  At every cycle of an
    enable, a run, an EMCY fault, its recovery and a reboot, for every node that the poll
    skipped, the sequence's poll has nothing to send and publishing the node to the base
    changes nothing."""
    b = bench([LEFT, RIGHT])
    drv = b.drv
    polled: list[int] = []
    for i, axis in enumerate(drv._axes):
        def seq_poll(now_s: float, real: Any = axis.seq.poll, i: int = i) -> list[Frame]:
            polled.append(i)
            return real(now_s)  # type: ignore[no-any-return]
        monkeypatch.setattr(axis.seq, "poll", seq_poll)
    poll = drv._poll
    skipped = []

    def checking(now_s: float) -> list[Frame]:
        polled.clear()
        out = poll(now_s)
        for i, axis in enumerate(drv._axes):
            if i not in polled:
                before = (drv.status(now_s)[i], axis.published, drv._armed[i])
                assert axis.seq.poll(now_s) == []
                drv._refresh(i)
                assert (drv.status(now_s)[i], axis.published, drv._armed[i]) == before
                skipped.append(i)
        return out

    monkeypatch.setattr(drv, "_poll", checking)
    assert b.enable([1.0, -1.0])
    b.run(0.2, [1.0, -1.0])
    b.sims[0].inject(SimFault.FAULT)
    assert b.run(0.2, [1.0, -1.0], until=lambda: b.state() is DriveState.FAULT)
    b.sims[0].clear(SimFault.FAULT)
    assert b.enable([1.0, -1.0])
    b.send([make_nmt(NmtCommand.RESET_NODE, 5)])
    assert b.run(0.3, [1.0, -1.0], until=lambda: b.state(1) is DriveState.FAULT)
    b.run(0.1, [1.0, -1.0])
    assert skipped.count(0) > 300 and skipped.count(1) > 200
