"""Controller-side protection of CiA 402 drives (:mod:`drivers.cia402.protection`).

What reaches the bus and the simulated drive is checked, not only what the driver believes:
a factory-default drive keeps turning when its master falls silent; the gateway sends its own
heartbeat, writes each drive's heartbeat consumer (CiA 301 0x1016:01) and abort connection
option code (CiA 402 0x6007), reads both back and only then enables the drive; the simulated
drive stops by itself when the heartbeat stops, as 0x6007 and 0x605A say.

Golden frames follow CiA 301 (expedited SDO: ``23`` write 4 bytes, ``2B`` write 2 bytes,
``40`` read, ``60`` write confirmed, ``43``/``4B`` 4/2 bytes read; heartbeat: 0x700 + node,
one byte NMT state, 0x05 OPERATIONAL) and are cross-checked with canopen's SDO constants.
"""

from __future__ import annotations

import dataclasses
import itertools
import logging
import math
from typing import TYPE_CHECKING

import pytest
from canopen.sdo import constants as sdo_constants

from drivers.cia402 import Cia402Driver, Cia402Simulator
from drivers.cia402.codec import make_heartbeat, make_nmt, unpack_pdo
from drivers.cia402.enums import DataType, NmtCommand, NmtState, State
from drivers.cia402.sdo import make_sdo_download, make_sdo_upload, parse_sdo_request
from drivers.cia402.sequence import NodeSequencer, Phase
from gateway.bus.can_bus import drain
from gateway.config import load_config
from gateway.core.errors import ConfigError
from gateway.core.protection import Guard, ProtectionState, WatchdogPolicy
from gateway.core.types import DriveFault, DriveState, Frame, MotorConfig
from gateway.drive.driveset import DriveSet
from gateway.sim.device import SimFault
from tests.conftest import CONFIG_DIR
from tests.drivers.test_drivers_cia402_bus import benches

if TYPE_CHECKING:
    from collections.abc import Callable, Iterator
    from pathlib import Path

    from tests.drivers.test_drivers_cia402_bus import Bench

DT = 0.001
TWO_PI = 2.0 * math.pi
LEFT = MotorConfig("left", "cia402", 3, gear_ratio=10.0)
U16, U32, I16 = DataType.UNSIGNED16, DataType.UNSIGNED32, DataType.INTEGER16


def hexb(text: str) -> bytes:
    return bytes.fromhex(text)


def left(**options: object) -> MotorConfig:
    return dataclasses.replace(LEFT, options=options)


@pytest.fixture
def bench(channel: str) -> Iterator[Callable[..., Bench]]:
    with benches(channel) as make:
        yield make


def protection_sdos(frames: list[Frame], cob: int) -> list[Frame]:
    """The SDO frames on ``cob`` that address 0x1016 or 0x6007, in order."""
    return [f for f in frames if f.arbitration_id == cob
            and int.from_bytes(f.data[1:3], "little") in (0x1016, 0x6007)]


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


# ----------------------------------------------------------------------------- golden frames


def test_the_gateway_heartbeat_golden_and_on_its_grid() -> None:
    drv = Cia402Driver([LEFT])
    beats = []
    for k in range(1001):  # 1 s of 1 ms cycles
        now = k * DT
        beats += [(now, f) for f in drv.poll(now) if f.arbitration_id != 0x080]
    assert {f for _, f in beats} == {Frame(0x77F, hexb("05"))}  # node 127, OPERATIONAL
    assert beats[0][1] == make_heartbeat(127, NmtState.OPERATIONAL)
    times = [t for t, _ in beats]
    assert times[0] == 0.0 and len(times) == 21  # every 50 ms from the first poll
    assert all(abs(b - a - 0.05) < 1e-9 for a, b in itertools.pairwise(times))
    other = Cia402Driver([left(host_node_id=100, host_heartbeat_s=0.02)])
    assert other.poll(0.0)[0] == Frame(0x764, hexb("05"))
    assert [f for f in other.poll(0.019) if f.arbitration_id == 0x764] == []
    assert other.poll(0.0205)[0] == Frame(0x764, hexb("05"))  # a late cycle: on the grid
    assert other.poll(0.04)[0] == Frame(0x764, hexb("05"))


def test_protection_sdos_golden(bench: Callable[..., Bench]) -> None:
    """Node 3, host 127, 200 ms, quick stop: what the gateway writes and reads, and what the
    drive answers."""
    b = bench([LEFT])
    assert b.enable([0.0])
    assert protection_sdos(b.sent, 0x603) == [
        Frame(0x603, hexb("23 16 10 01 C8 00 7F 00")),  # 0x1016:01 = 0x007F00C8
        Frame(0x603, hexb("2B 07 60 00 03 00 00 00")),  # 0x6007 = 3 (INTEGER16)
        Frame(0x603, hexb("40 16 10 01 00 00 00 00")),  # read 0x1016:01
        Frame(0x603, hexb("40 07 60 00 00 00 00 00")),  # read 0x6007
    ]
    assert [f.data for f in protection_sdos(b.seen, 0x583)] == [
        hexb("60 16 10 01 00 00 00 00"), hexb("60 07 60 00 00 00 00 00"),
        hexb("43 16 10 01 C8 00 7F 00"), hexb("4B 07 60 00 03 00 00 00"),
    ]
    assert (127 << 16 | 200) == 0x007F00C8
    # canopen's reading of the command bytes: expedited, size given, 4 and 2 bytes
    for frame, size in zip(protection_sdos(b.sent, 0x603)[:2], (4, 2), strict=True):
        command = frame.data[0]
        assert command & 0xE0 == sdo_constants.REQUEST_DOWNLOAD
        assert command & sdo_constants.EXPEDITED and command & sdo_constants.SIZE_SPECIFIED
        assert 4 - ((command >> 2) & 3) == size
    reads = protection_sdos(b.sent, 0x603)[2:]
    assert all(f.data[0] == sdo_constants.REQUEST_UPLOAD for f in reads)
    sim = b.sims[0]
    assert (sim.object_value(0x1016, 1), sim.object_value(0x6007)) == (0x007F00C8, 3)
    assert b.drv.protection_state(0) is ProtectionState.CONFIRMED


def test_the_drive_is_not_enabled_before_the_read_back(bench: Callable[..., Bench]) -> None:
    """NMT start and the first controlword go out only after the drive has answered both
    read-backs; until then the protection is PENDING."""
    b = bench([LEFT])
    b.send(b.drv.enable(b.t))
    sent: list[tuple[float, Frame]] = []
    states = []
    for _ in range(500):
        start = len(b.sent)
        b.run(DT, [0.0])
        sent += [(b.t, f) for f in b.sent[start:]]
        states.append((b.t, b.drv.protection_state(0)))
        if b.state() is DriveState.ENABLED:
            break
    assert b.state() is DriveState.ENABLED
    answered = max(f.timestamp_s for f in protection_sdos(b.seen, 0x583))  # the last answer
    assert protection_sdos(b.seen, 0x583)[-1].data == hexb("4B 07 60 00 03 00 00 00")
    nmt_start = next(t for t, f in sent if f == make_nmt(NmtCommand.START, 3))
    first_cw = next(t for t, f in sent if f.arbitration_id == 0x503)
    assert answered <= nmt_start < first_cw
    assert {p for t, p in states if t < answered} == {ProtectionState.PENDING}
    assert {p for t, p in states if t >= answered} == {ProtectionState.CONFIRMED}
    between = {parse_sdo_request(f).index for t, f in sent if answered <= t < nmt_start
               and f.arbitration_id == 0x603}
    assert between <= {0x6060, 0x6061}  # only the mode's SDOs after the read-back


# ----------------------------------------------------------------------------- failures


class Mute6007(Cia402Simulator):
    """A drive that takes the writes but never answers the read of 0x6007."""

    def _on_sdo(self, frame: Frame) -> list[Frame]:
        if frame.data[:4] == hexb("40 07 60 00"):
            return []
        return super()._on_sdo(frame)


def controlwords(b: Bench) -> list[int]:
    return [unpack_pdo(f, "RPDO")[0] for f in b.sent if f.arbitration_id == 0x503]


def test_required_a_refused_write_is_a_fault_and_no_enable(bench: Callable[..., Bench]) -> None:
    b = bench([LEFT], missing_objects=(0x1016,))  # a drive without a heartbeat consumer
    b.send(b.drv.enable(b.t))
    assert b.run(1.0, [0.0], until=lambda: b.drv.phase(0) is Phase.FAILED)
    b.run(0.5, [0.0])
    (status,) = b.drv.status(b.t)
    assert (status.state, status.faults) == (DriveState.FAULT, DriveFault.WATCHDOG)
    assert status.detail == (
        "motor 'left' (CiA 402 node 3): controller watchdog not confirmed: SDO write of "
        "8323272 to 0x1016:01 (heartbeat consumer time) aborted: 0x06020000 Object does not "
        "exist; fix: use a drive with a heartbeat consumer (CiA 301 object 0x1016) and the "
        "abort connection option code (CiA 402 object 0x6007), see its EDS file; or set a "
        "command timeout with the vendor's tool and gateway.controller_watchdog: warn")
    assert b.drv.protection_state(0) is ProtectionState.FAILED
    assert controlwords(b) == []  # no controlword reached the drive, and no NMT start
    assert make_nmt(NmtCommand.START, 3) not in b.sent
    sim = b.sims[0]
    assert sim.nmt is NmtState.PRE_OPERATIONAL and sim.state is State.SWITCH_ON_DISABLED
    assert sim.object_value(0x6007) == 1  # nothing more was written
    # a new enable tries again (and fails again: the fault stays until then)
    b.send(b.drv.enable(b.t))
    assert b.drv.status(b.t)[0].faults == DriveFault.NONE
    assert b.run(1.0, [0.0], until=lambda: b.drv.phase(0) is Phase.FAILED)
    assert b.drv.status(b.t)[0].faults == DriveFault.WATCHDOG


@pytest.mark.parametrize(
    ("sim_class", "sim_kwargs", "why"),
    [
        (Cia402Simulator, {"ignored_writes": (0x6007,)},
         "0x6007:00 (abort connection option code) reads 1 after the write of 3"),
        (Mute6007, {},
         "no SDO response within 0.5 s to the read of 0x6007:00 (abort connection option code)"),
    ],
    ids=["read-back-differs", "no-answer"],
)
def test_required_an_unconfirmed_protection_is_a_fault(
    bench: Callable[..., Bench], sim_class: type[Cia402Simulator],
    sim_kwargs: dict[str, object], why: str
) -> None:
    b = bench([LEFT], sim_class=sim_class, **sim_kwargs)
    b.send(b.drv.enable(b.t))
    assert b.run(1.5, [0.0], until=lambda: b.drv.phase(0) is Phase.FAILED)
    (status,) = b.drv.status(b.t)
    assert (status.state, status.faults) == (DriveState.FAULT, DriveFault.WATCHDOG)
    assert f"(CiA 402 node 3): controller watchdog not confirmed: {why}; fix: " in status.detail
    assert b.drv.protection_state(0) is ProtectionState.FAILED
    assert controlwords(b) == [] and b.sims[0].nmt is NmtState.PRE_OPERATIONAL


def test_warn_arms_anyway_with_a_warning(
    bench: Callable[..., Bench], caplog: pytest.LogCaptureFixture
) -> None:
    b = bench([LEFT], missing_objects=(0x1016,))
    b.drv.watchdog_policy = WatchdogPolicy.WARN
    with caplog.at_level(logging.WARNING):
        assert b.enable([2.0])
    assert "motor 'left' (CiA 402 node 3): controller watchdog not confirmed: SDO write" in (
        caplog.text)
    assert "arming it anyway (gateway.controller_watchdog: warn)" in caplog.text
    assert b.drv.protection_state(0) is ProtectionState.FAILED
    b.run(0.3, [2.0])
    assert b.sims[0].wheel_velocity_rad_s == pytest.approx(2.0, abs=0.01)
    assert b.drv.status(b.t)[0].faults == DriveFault.NONE


# ----------------------------------------------------------------------------- the drive stops


def test_a_factory_default_drive_keeps_turning_when_its_master_falls_silent() -> None:
    """The adversary's finding: CiA 402 has no command timeout of its own, and a drive at
    factory settings watches no heartbeat; a master that does not configure one leaves the
    wheel turning at its last target velocity for ever."""
    sim = Cia402Simulator(LEFT)
    assert (sim.object_value(0x1016, 0), sim.object_value(0x1016, 1)) == (1, 0)  # not used
    assert (sim.object_value(0x6007), sim.object_value(0x605A)) == (1, 2)
    t = 0.0

    def sdo(frame: Frame) -> None:
        nonlocal t
        t += DT
        sim.handle(frame, t)
        sim.tick(t)

    sim.tick(t)
    for index, value, dtype in ((0x6060, 3, DataType.INTEGER8), (0x60FF, 1000, DataType.INTEGER32)):
        sdo(make_sdo_download(3, index, 0, value, dtype))
    for word in (0x06, 0x07, 0x0F):  # a master that walks the drive to OPERATION ENABLED
        sdo(make_sdo_download(3, 0x6040, 0, word, U16))
        for _ in range(50):
            sdo(make_heartbeat(127, NmtState.OPERATIONAL))  # it even sends a heartbeat
    assert sim.state is State.OPERATION_ENABLED
    for _ in range(3000):  # then 3 s of silence
        t += DT
        sim.tick(t)
    assert sim.state is State.OPERATION_ENABLED and sim.model.armed
    assert sim.model.velocity_rad_s == pytest.approx(1000 * TWO_PI / 60, rel=1e-3)
    assert sim.consumer.events == 0


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


def test_a_lost_heartbeat_stops_the_drive_though_its_rpdos_go_on(
    bench: Callable[..., Bench], monkeypatch: pytest.MonkeyPatch
) -> None:
    """The heartbeat stops while the loop and its commands go on: the drive quick-stops and
    completes the stop; the ENABLE OPERATION of the RPDOs that still come does not take it
    back (transition 16 only with 0x605A 5 to 8), and the driver reports the fault."""
    b = bench([LEFT])
    assert b.enable([0.0])
    b.run(0.3, [10.0])
    sim = b.sims[0]
    sim.latency_s = 0.05  # its EMCY and statusword reach the driver late: RPDOs go on meanwhile
    sim.inject(SimFault.LATE)
    monkeypatch.setattr(b.drv.host, "poll", lambda now_s: [])
    b.run(1.0, [10.0])
    assert sim.state is State.SWITCH_ON_DISABLED and abs(sim.wheel_velocity_rad_s) < 0.01
    (status,) = b.drv.status(b.t)
    assert status.state is DriveState.FAULT
    assert "EMCY 0x8130 Life guard or heartbeat error" in status.detail


def drive_with_consumer(quick_stop_option: int) -> tuple[Cia402Simulator, list[float]]:
    """A simulated drive set up by SDO (0x605A, consumer watching node 127 for 100 ms, 0x6007
    quick stop), at 1000 RPM, whose master's heartbeat then stops; its speeds afterwards."""
    sim = Cia402Simulator(LEFT)
    t = 0.0
    sim.tick(t)
    setup = ((0x605A, 0, quick_stop_option, I16), (0x1016, 1, 127 << 16 | 100, U32),
             (0x6007, 0, 3, I16), (0x6060, 0, 3, DataType.INTEGER8),
             (0x60FF, 0, 1000, DataType.INTEGER32), (0x6040, 0, 0x06, U16),
             (0x6040, 0, 0x07, U16), (0x6040, 0, 0x0F, U16))
    for index, sub, value, dtype in setup:
        for _ in range(40):  # the master's heartbeat every 1 ms meanwhile
            t += DT
            sim.handle(make_heartbeat(127, NmtState.OPERATIONAL), t)
            sim.tick(t)
        t += DT
        reply = sim.handle(make_sdo_download(3, index, sub, value, dtype), t)
        assert reply[0].data[0] == 0x60, (hex(index), reply)
    for _ in range(400):
        t += DT
        sim.handle(make_heartbeat(127, NmtState.OPERATIONAL), t)
        sim.tick(t)
    assert sim.state is State.OPERATION_ENABLED
    speeds = []
    for _ in range(1000):  # silence
        t += DT
        sim.tick(t)
        speeds.append(sim.model.velocity_rad_s)
    return sim, speeds


@pytest.mark.parametrize(("option", "end"), [(2, State.SWITCH_ON_DISABLED),
                                             (6, State.QUICK_STOP_ACTIVE)])
def test_quick_stop_option_code_end_states(option: int, end: State) -> None:
    sim, speeds = drive_with_consumer(option)
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
                                     (0x1017, 0, 250, U16), (0x6085, 0, 1, U32)):
        (ack,) = sim.handle(make_sdo_download(3, index, sub, value, dtype), 0.0)
        assert ack.data[:4] == bytes([0x60, index & 0xFF, index >> 8, sub])
        (read,) = sim.handle(make_sdo_upload(3, index, sub), 0.0)
        assert int.from_bytes(read.data[4:4 + dtype.size], "little", signed=dtype is I16) == value
    assert (sim.consumer.node_id, sim.consumer.time_s) == (5, 1.0)


# ----------------------------------------------------------------------------- slow states


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


# ----------------------------------------------------------------------------- configuration


def test_protection_as_the_driver_states_it() -> None:
    drv = Cia402Driver([LEFT, MotorConfig("right", "cia402", 5, options={
        "abort_connection_option": 2, "controller_timeout_s": 0.5})])
    assert drv.PROTOCOL == "CiA 402"
    quick, coast = drv.protection(0), drv.protection(1)
    assert (quick.guard, quick.timeout_s, coast.timeout_s) == (Guard.CONFIGURED, 0.2, 0.5)
    assert quick.action.startswith("quick stop (0x605A quick stop option code")
    assert coast.action == "disable voltage (the power stage switches off: the motor coasts)"
    assert quick.how == ("heartbeat consumer 0x1016 watching node 127 every 200 ms and abort "
                         "connection option 0x6007 = 3, written by SDO and read back")
    assert "0x6007 = 2" in coast.how and "every 500 ms" in coast.how
    assert drv.protection_state(0) is ProtectionState.PENDING
    seq = NodeSequencer(3, "node 3", drv.codec, ())  # no protection steps: not applicable
    assert seq.protection is ProtectionState.NOT_APPLICABLE


@pytest.mark.parametrize(
    ("motors", "message"),
    [
        ([left(host_node_id=3)],
         "wheel 'left' (node 3).host_node_id: expected a node ID that no drive on the bus uses "
         "(the gateway's heartbeat goes out on 0x703), got 3, the node ID of wheel 'left'"),
        ([LEFT, MotorConfig("right", "cia402", 127)],
         "wheel 'right' (node 127).host_node_id: expected a node ID that no drive on the bus "
         "uses (the gateway's heartbeat goes out on 0x77F), got 127, the node ID of wheel "
         "'right'"),
        ([LEFT, MotorConfig("right", "cia402", 5, options={"host_node_id": 100})],
         "wheel 'right' (node 5).host_node_id: expected 127 as for wheel 'left' (the gateway "
         "sends one heartbeat per bus), got 100"),
        ([LEFT, MotorConfig("right", "cia402", 5, options={"host_heartbeat_s": 0.02})],
         "wheel 'right' (node 5).host_heartbeat_s: expected 0.05 as for wheel 'left'"),
        ([left(controller_timeout_s=0.09)],
         "wheel 'left' (node 3).controller_timeout_s: expected at least 2 x host_heartbeat_s "
         "(0.1 s), or one late heartbeat of the gateway stops the drive; got 0.09"),
        ([left(controller_timeout_s=0.2005)],
         "wheel 'left' (node 3).controller_timeout_s: expected a whole number of milliseconds"),
        ([left(abort_connection_option=1)],
         "wheel 'left' (node 3).abort_connection_option: expected one of 2, 3, got 1"),
    ],
    ids=["host-is-the-drive", "host-is-another-drive", "two-hosts", "two-periods",
         "timeout-too-short", "timeout-not-ms", "option-1"],
)
def test_configuration_errors(motors: list[MotorConfig], message: str) -> None:
    with pytest.raises(ConfigError) as err:
        Cia402Driver(motors)
    assert message in str(err.value)


def test_the_heartbeat_id_is_declared_against_the_gateways_own_ids(tmp_path: Path) -> None:
    path = tmp_path / "r.yaml"
    path.write_text((CONFIG_DIR / "synchro.yaml").read_text()
                    + "\ngateway:\n  can_ids: {status: 0x77F}\n")
    with pytest.raises(ConfigError, match=r"status 0x77F: also identifiers of the cia402 "):
        load_config(path)


def test_shipped_configs_have_the_protection_and_no_warning() -> None:
    for name in ("synchro.yaml", "tricycle.yaml"):
        cfg = load_config(CONFIG_DIR / name)
        assert not [w for w in cfg.warnings if "controller" in w], cfg.warnings
        protections = DriveSet(cfg).protections()
        assert protections and {p.guard for _, p in protections} == {Guard.CONFIGURED}
