"""What a CiA 402 drive does when the gateway stops (:mod:`drivers.cia402.protection`), checked
on the simulated drive and not only in what the driver believes (a factory-default drive keeps
turning when its master falls silent: ``test_cia402_protection``): configured by the gateway,
it stops by itself when the gateway's heartbeat stops, as its abort connection option code
(CiA 402 0x6007) and quick stop option code (0x605A) say, and its NMT state goes where its error
behaviour (CiA 301 0x1029:01) says, PRE-OPERATIONAL from the factory: its PDOs stop; its
heartbeat consumer (CiA 301 0x1016) watches from the first heartbeat after it is written; the
simulated drive refuses what CiA 301 makes it refuse.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import pytest

from drivers.cia402.codec import make_heartbeat, make_nmt
from drivers.cia402.enums import DataType, NmtCommand, NmtState, State
from drivers.cia402.sdo import make_sdo_download, make_sdo_upload
from drivers.cia402.sim import Cia402Simulator
from gateway.bus.can_bus import drain
from gateway.core.types import DriveState, Frame
from gateway.sim.device import SimFault
from tests.drivers.cia402_bench import DT, LEFT, TWO_PI, Bench, benches, hexb, left

if TYPE_CHECKING:
    from collections.abc import Callable, Iterator

U8, U16, U32, I16 = DataType.UNSIGNED8, DataType.UNSIGNED16, DataType.UNSIGNED32, DataType.INTEGER16
#: The feedback TPDOs of LEFT (node 3) as the driver maps them: TPDO3 and TPDO4.
TPDOS = (0x383, 0x483)


@pytest.fixture
def bench(channel: str) -> Iterator[Callable[..., Bench]]:
    with benches(channel) as make:
        yield make


def run_gateway(b: Bench, seconds: float, speeds: list[float]) -> float:
    """Run the gateway and its drives for ``seconds``; the time of its last heartbeat."""
    last = math.nan
    for _ in range(round(seconds / DT)):
        start = len(b.sent)
        b.run(DT, speeds)
        if any(f.arbitration_id == 0x77F for f in b.sent[start:]):
            last = b.t
    return last


def gateway_dead(b: Bench, seconds: float, each: Callable[[], None] | None = None) -> None:
    """The gateway is gone: nothing more comes from it (no heartbeat, no SYNC, no RPDO), the
    drives run on; what they send is kept in ``b.seen``."""
    for _ in range(round(seconds / DT)):
        b.t += DT
        b.ctl.step(b.t)
        b.seen += [f.stamped(b.t) for f in drain(b.gw)]
        if each is not None:
            each()


def test_quick_stop_when_the_heartbeat_stops(bench: Callable[..., Bench]) -> None:
    b = bench([LEFT])
    assert b.enable([0.0])
    last = run_gateway(b, 0.6, [20.0])  # 200 rad/s = 1910 RPM at the motor
    sim = b.sims[0]
    assert sim.wheel_velocity_rad_s == pytest.approx(20.0, abs=0.01)
    ramp_s = 200.0 * 60 / TWO_PI / 10000.0  # 0x6085 = 10000 RPM/s: 0.191 s
    speeds: list[tuple[float, float, State, bool]] = []
    gateway_dead(b, 0.8, lambda: speeds.append(
        (b.t - last, sim.wheel_velocity_rad_s, sim.state, sim.model.armed)))

    def at(dt: float) -> tuple[float, float, State, bool]:
        return next(s for s in speeds if s[0] >= dt)

    assert at(0.195)[1] == pytest.approx(20.0, abs=0.01)  # within the consumer time: on
    assert at(0.195)[2] is State.OPERATION_ENABLED
    half = at(0.2 + 0.5 * ramp_s)  # on the quick-stop ramp: braked, not coasting
    assert half[2] is State.QUICK_STOP_ACTIVE and half[3]
    assert 0.35 * 20.0 < half[1] < 0.65 * 20.0
    stopped = next(s for s in speeds if abs(s[1]) < 0.01)
    assert stopped[0] <= 0.2 + ramp_s + 0.1  # (+ the motor's lag behind the ramp)
    assert speeds[-1][2] is State.SWITCH_ON_DISABLED and not speeds[-1][3]  # 0x605A = 2
    assert all(s[2] is State.QUICK_STOP_ACTIVE for s in speeds if 0.21 < s[0] < 0.2 + ramp_s)
    assert abs(speeds[-1][1]) < 1e-3
    emcy = [f for f in b.seen if f.arbitration_id == 0x083 and f.timestamp_s > last]
    assert emcy and emcy[0].data == hexb("30 81 11 00 00 00 00 00")  # 0x8130, heartbeat
    assert sim.consumer.events == 1


def test_disable_voltage_coasts_when_the_heartbeat_stops(bench: Callable[..., Bench]) -> None:
    motor = left(abort_connection_option=2, controller_timeout_s=0.3)
    b = bench([motor])
    assert b.enable([0.0])
    sim = b.sims[0]
    assert (sim.object_value(0x6007), sim.object_value(0x1016, 1)) == (2, 127 << 16 | 300)
    last = run_gateway(b, 0.6, [20.0])
    states: list[tuple[float, State, bool]] = []
    gateway_dead(b, 0.5, lambda: states.append((b.t - last, sim.state, sim.model.armed)))
    assert all(st is State.OPERATION_ENABLED for dt, st, _ in states if dt < 0.295)
    after = [(st, armed) for dt, st, armed in states if dt > 0.305]
    assert after and all(s == (State.SWITCH_ON_DISABLED, False) for s in after)  # coasts
    assert State.QUICK_STOP_ACTIVE not in {st for _, st, _ in states}  # no ramp


def test_a_lost_heartbeat_stops_the_drive_and_its_pdos(
    bench: Callable[..., Bench], monkeypatch: pytest.MonkeyPatch
) -> None:
    """The heartbeat stops while the loop and its commands go on.  As a real drive does, the
    drive quick-stops (0x6007 = 3, 0x605A = 2) and goes PRE-OPERATIONAL (0x1029:01 = 0, the
    CiA 301 default the driver writes): from then on no TPDO shows the stop and the RPDOs that
    still come are ignored; its heartbeat says PRE-OPERATIONAL, and the driver reports the
    fault.  Once the gateway's heartbeat is back, an enable configures the drive again, NMT
    start included, and the wheel follows."""
    b = bench([LEFT])
    assert b.enable([0.0])
    b.run(0.3, [10.0])
    sim = b.sims[0]
    assert (sim.object_value(0x1029, 1), sim.nmt) == (0, NmtState.OPERATIONAL)
    sim.latency_s = 0.05  # its EMCY and heartbeat reach the driver late: RPDOs go on meanwhile
    sim.inject(SimFault.LATE)
    with monkeypatch.context() as patch:
        patch.setattr(b.drv.host, "poll", lambda now_s: [])
        seen: list[tuple[float, NmtState, int, float, int]] = []
        for _ in range(1000):
            b.run(DT, [10.0])
            seen.append((b.t, sim.nmt, sim.rpdos, sim.wheel_velocity_rad_s, len(b.sent)))
    event = next(s for s in seen if s[1] is not NmtState.OPERATIONAL)
    assert event[1] is NmtState.PRE_OPERATIONAL and sim.consumer.events == 1
    assert abs(event[3]) > 9.0  # the stop starts at the event: the TPDOs stop at full speed
    assert sim.state is State.SWITCH_ON_DISABLED and abs(sim.wheel_velocity_rad_s) < 0.01
    assert {s[1] for s in seen if s[0] >= event[0]} == {NmtState.PRE_OPERATIONAL}
    late = event[0] + sim.latency_s + 2 * DT  # what the drive sent before has arrived
    assert not [f for f in b.seen if f.arbitration_id in TPDOS and f.timestamp_s > late]
    assert [f for f in b.sent[event[4]:] if f.arbitration_id == 0x503]  # RPDOs went on
    assert seen[-1][2] == event[2]  # the RPDOs sent after the event were not taken
    beats = {f.data for f in b.seen if f.arbitration_id == 0x703 and f.timestamp_s > late}
    assert beats == {bytes([NmtState.PRE_OPERATIONAL])}
    (status,) = b.drv.status(b.t)
    assert status.state is DriveState.FAULT
    assert "EMCY 0x8130 Life guard or heartbeat error" in status.detail
    sim.clear(SimFault.LATE)
    restart = len(b.sent)
    assert b.enable([0.0], seconds=1.0)
    assert sim.nmt is NmtState.OPERATIONAL
    assert make_nmt(NmtCommand.START, 3) in b.sent[restart:]
    b.run(0.3, [10.0])
    assert sim.wheel_velocity_rad_s == pytest.approx(10.0, abs=0.01)


@pytest.mark.parametrize("speed", [10.0, 0.0])
def test_a_restart_of_an_unheard_drive_stops_it_before_its_pdos_go_off(
    bench: Callable[..., Bench], speed: float
) -> None:
    """A running drive whose frames no longer reach the gateway (its transmissions lost) but
    that still hears the bus: an enable restarts its sequence, whose NMT PRE-OPERATIONAL turns
    its PDOs off.  QUICK STOP goes first, so the drive stops (as 0x605A says) and does not keep
    its last target out of reach of the disable that follows (it kept turning at 10 rad/s,
    in OPERATION ENABLED, with the driver's phase IDLE)."""
    b = bench([LEFT])
    assert b.enable([0.0])
    b.run(0.3, [10.0])
    sim = b.sims[0]
    sim.inject(SimFault.MUTE)  # it sends nothing more, and hears everything
    b.run(0.5, [speed])  # 0.0: the loop's FAULT zero (fault_action: zero)
    assert b.drv.status(b.t)[0].state is DriveState.OFFLINE
    b.send(b.drv.enable(b.t))
    b.run(0.5, [speed])
    assert sim.nmt is NmtState.PRE_OPERATIONAL
    assert sim.state is State.SWITCH_ON_DISABLED
    assert abs(sim.wheel_velocity_rad_s) < 0.01
    b.send(b.drv.disable(b.t))
    b.run(1.0, None)
    assert sim.state is State.SWITCH_ON_DISABLED and abs(sim.wheel_velocity_rad_s) < 0.01


def drive_with_consumer(
    quick_stop_option: int, error_behaviour: int | None = None, *, start: bool = False
) -> tuple[Cia402Simulator, list[float], list[Frame]]:
    """A simulated drive set up by SDO (0x605A, consumer watching node 127 for 100 ms, 0x6007
    quick stop; with ``error_behaviour``, 0x1029:01; with ``start``, then NMT start), at 1000
    RPM, whose master's heartbeat then stops; its speeds and the frames it sends afterwards."""
    sim = Cia402Simulator(LEFT)
    t = 0.0
    sim.tick(t)
    setup: list[tuple[int, int, int, DataType]] = [
        (0x605A, 0, quick_stop_option, I16), (0x1016, 1, 127 << 16 | 100, U32),
        (0x6007, 0, 3, I16), (0x6060, 0, 3, DataType.INTEGER8),
        (0x60FF, 0, 1000, DataType.INTEGER32), (0x6040, 0, 0x06, U16),
        (0x6040, 0, 0x07, U16), (0x6040, 0, 0x0F, U16)]
    if error_behaviour is not None:
        setup.insert(0, (0x1029, 1, error_behaviour, U8))
    for index, sub, value, dtype in setup:
        for _ in range(40):  # the master's heartbeat every 1 ms meanwhile
            t += DT
            sim.handle(make_heartbeat(127, NmtState.OPERATIONAL), t)
            sim.tick(t)
        t += DT
        reply = sim.handle(make_sdo_download(3, index, sub, value, dtype), t)
        assert reply[0].data[0] == 0x60, (hex(index), reply)
    if start:
        sim.handle(make_nmt(NmtCommand.START, 3), t)
    for _ in range(400):
        t += DT
        sim.handle(make_heartbeat(127, NmtState.OPERATIONAL), t)
        sim.tick(t)
    assert sim.state is State.OPERATION_ENABLED
    speeds, frames = [], []
    for _ in range(1000):  # silence
        t += DT
        frames += [f.stamped(t) for f in sim.tick(t)]
        speeds.append(sim.model.velocity_rad_s)
    return sim, speeds, frames


@pytest.mark.parametrize(("option", "end"), [(2, State.SWITCH_ON_DISABLED),
                                             (6, State.QUICK_STOP_ACTIVE)])
def test_quick_stop_option_code_end_states(option: int, end: State) -> None:
    sim, speeds, _ = drive_with_consumer(option)
    start = 1000 * TWO_PI / 60
    assert speeds[90] == pytest.approx(start, rel=1e-3)  # within the 100 ms consumer time
    # 0x6085 = 10000 RPM/s: 1000 RPM in 0.1 s, on the ramp the same for 2 and 6
    assert speeds[150] == pytest.approx(0.5 * start, abs=0.1 * start)
    assert abs(speeds[-1]) < 1e-3
    assert sim.state is end
    assert sim.model.armed is (end is State.QUICK_STOP_ACTIVE)  # 6 holds the motor at 0
    # ENABLE OPERATION: back to OPERATION ENABLED from 6 (transition 16), not from 2
    sim.handle(make_sdo_download(3, 0x6040, 0, 0x0F, U16), 2.0)
    sim.tick(2.1)
    assert (sim.state is State.OPERATION_ENABLED) is (option == 6)


@pytest.mark.parametrize(("behaviour", "nmt"), [(None, NmtState.PRE_OPERATIONAL),
                                                (0, NmtState.PRE_OPERATIONAL),
                                                (1, NmtState.OPERATIONAL),
                                                (2, NmtState.STOPPED)],
                         ids=["factory", "0", "1", "2"])
def test_error_behaviour_at_the_heartbeat_event(behaviour: int | None, nmt: NmtState) -> None:
    """CiA 301 0x1029:01 says where the NMT state goes at the heartbeat event, a communication
    error (0 PRE-OPERATIONAL, the factory value; 1 no change; 2 STOPPED), while 0x6007 stops
    the drive in every case.  Only OPERATIONAL goes on with PDOs: TPDOs show the stop, an RPDO
    is taken; only STOPPED answers no SDO and sends no EMCY (CiA 301: NMT and heartbeat only)."""
    sim, speeds, frames = drive_with_consumer(2, error_behaviour=behaviour, start=True)
    assert sim.nmt is nmt and sim.consumer.events == 1
    assert abs(speeds[-1]) < 1e-3 and sim.state is State.SWITCH_ON_DISABLED
    tpdos = [f for f in frames if f.arbitration_id in (0x183, 0x283, 0x383)]
    assert bool(tpdos) is (nmt is NmtState.OPERATIONAL)  # statusword changes, event-driven
    emcy = [f for f in frames if f.arbitration_id == 0x083]
    assert bool(emcy) is (nmt is not NmtState.STOPPED)
    rpdos = sim.rpdos
    sim.handle(Frame(0x403, hexb("0F 00 E8 03 00 00")), 2.0)  # RPDO3: 6040 + 60FF
    assert sim.rpdos == rpdos + (nmt is NmtState.OPERATIONAL)
    answers = sim.handle(make_sdo_upload(3, 0x1029, 1), 2.0)
    assert bool(answers) is (nmt is not NmtState.STOPPED)


def test_an_rpdo_is_not_kept_for_after_pre_operational() -> None:
    """A synchronous RPDO received in OPERATIONAL and not yet acted on (no SYNC yet) is dropped
    when the node leaves OPERATIONAL, as CANopenNode's ``CO_RPDO_process`` clears its receive
    flags outside OPERATIONAL: the next NMT start does not act on a stale command."""
    sim = Cia402Simulator(LEFT)
    sim.tick(0.0)
    (ack,) = sim.handle(make_sdo_download(3, 0x1402, 2, 1, U8), 0.001)  # RPDO3: every SYNC
    assert ack.data[0] == 0x60
    sim.handle(make_nmt(NmtCommand.START, 3), 0.002)
    sim.handle(Frame(0x403, hexb("0F 00 E8 03 00 00")), 0.003)  # pending until SYNC
    sim.handle(make_nmt(NmtCommand.ENTER_PRE_OPERATIONAL, 3), 0.004)
    sim.handle(make_nmt(NmtCommand.START, 3), 0.005)
    sim.handle(Frame(0x080, b""), 0.006)
    assert (sim.rpdos, sim.object_value(0x60FF)) == (0, 0)
    sim.handle(Frame(0x403, hexb("0F 00 E8 03 00 00")), 0.007)
    sim.handle(Frame(0x080, b""), 0.008)  # (a fresh one is taken at the next SYNC)
    assert (sim.rpdos, sim.object_value(0x60FF)) == (1, 1000)


def test_factory_abort_option_fault_signal() -> None:
    """0x6007 at its factory value 1: the heartbeat event is a fault (the motor coasts)."""
    sim = Cia402Simulator(LEFT)
    sim.tick(0.0)
    sim.handle(make_sdo_download(3, 0x1016, 1, 127 << 16 | 50, U32), 0.001)
    sim.handle(make_heartbeat(127, NmtState.OPERATIONAL), 0.01)
    assert [sim.tick(t) for t in (0.05, 0.059)] == [[], []]
    frames = sim.tick(0.061)  # 51 ms after the heartbeat
    assert Frame(0x083, hexb("30 81 11 00 00 00 00 00")) in frames
    sim.tick(0.062)
    assert sim.state is State.FAULT and not sim.model.armed


def test_the_consumer_watches_from_the_first_heartbeat_after_the_write() -> None:
    """CiA 301: the consumer starts with the first heartbeat after its entry is written (a
    drive configured before its master talks does not trip); a boot-up starts it afresh."""
    sim = Cia402Simulator(LEFT)
    sim.tick(0.0)
    sim.handle(make_heartbeat(127, NmtState.OPERATIONAL), 0.001)  # before the entry
    sim.handle(make_sdo_download(3, 0x1016, 1, 127 << 16 | 50, U32), 0.002)
    for k in range(1, 500):  # 0.5 s without a heartbeat
        sim.tick(0.002 + k * DT)
    assert (sim.consumer.events, sim.consumer.watching) == (0, False)
    sim.handle(make_heartbeat(126, NmtState.OPERATIONAL), 0.55)  # another node's
    sim.handle(make_heartbeat(127, NmtState.BOOT_UP), 0.56)  # a boot-up is no heartbeat
    assert not sim.consumer.watching
    sim.handle(make_heartbeat(127, NmtState.PRE_OPERATIONAL), 0.6)
    assert sim.consumer.watching
    sim.tick(0.649)
    assert sim.consumer.events == 0 and sim.state is State.SWITCH_ON_DISABLED
    sim.tick(0.652)  # 52 ms of silence: a heartbeat event, and 0x6007 = 1 faults the drive
    assert sim.consumer.events == 1 and not sim.consumer.watching
    sim.tick(0.653)
    assert sim.state is State.FAULT


@pytest.mark.parametrize(
    ("index", "sub", "value", "dtype", "code"),
    [
        (0x1016, 1, 0x01_7F_00C8, U32, 0x06090030),  # reserved bits 31..24 set
        (0x1016, 1, 128 << 16 | 200, U32, 0x06090030),  # node 128
        (0x1016, 1, 200, U32, 0x06090030),  # node 0 with a time
        (0x1016, 1, 200, U16, 0x06070013),  # 2 bytes for an UNSIGNED32
        (0x1016, 2, 0x007F00C8, U32, 0x06090011),  # one entry only
        (0x1016, 0, 2, DataType.UNSIGNED8, 0x06010002),  # read only
        (0x6007, 0, 4, I16, 0x06090030),
        (0x6007, 0, -1, I16, 0x06090030),  # no manufacturer-specific codes here
        (0x605A, 0, 9, I16, 0x06090030),
        (0x1029, 1, 3, U8, 0x06090030),  # 3..127 reserved; no manufacturer-specific ones
        (0x1029, 0, 2, U8, 0x06010002),  # one error class, read only
        (0x6085, 0, 0, U32, 0x06090032),
    ],
)
def test_sdo_aborts_of_the_protection_objects(
    index: int, sub: int, value: int, dtype: DataType, code: int
) -> None:
    sim = Cia402Simulator(LEFT)
    (reply,) = sim.handle(make_sdo_download(3, index, sub, value, dtype), 0.0)
    assert reply.arbitration_id == 0x583 and reply.data[0] == 0x80
    assert int.from_bytes(reply.data[4:], "little") == code


def test_sdo_reads_and_writes_of_the_protection_objects() -> None:
    sim = Cia402Simulator(LEFT)
    for index, sub, value, dtype in ((0x1016, 1, 0, U32), (0x1016, 1, 5 << 16 | 1000, U32),
                                     (0x6007, 0, 0, I16), (0x6007, 0, 2, I16),
                                     (0x605A, 0, 0, I16), (0x605A, 0, 8, I16),
                                     (0x1029, 1, 2, U8), (0x1029, 1, 1, U8),
                                     (0x1017, 0, 250, U16), (0x6085, 0, 1, U32)):
        (ack,) = sim.handle(make_sdo_download(3, index, sub, value, dtype), 0.0)
        assert ack.data[:4] == bytes([0x60, index & 0xFF, index >> 8, sub])
        (read,) = sim.handle(make_sdo_upload(3, index, sub), 0.0)
        assert int.from_bytes(read.data[4:4 + dtype.size], "little", signed=dtype is I16) == value
    assert (sim.consumer.node_id, sim.consumer.time_s) == (5, 1.0)
