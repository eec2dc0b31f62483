"""Controller-side protection of CiA 402 drives, the gateway's side
(:mod:`drivers.cia402.protection`): why (a factory-default drive keeps turning when its master
falls silent); the gateway sends its own heartbeat, writes each drive's
heartbeat consumer (CiA 301 0x1016:01), abort connection option code (CiA 402 0x6007) and error
behaviour (CiA 301 0x1029:01), reads them back and only then enables the drive (then it reads the
quick stop option code 0x605A: ``test_cia402_protection_reads``); what it does when that fails,
under ``gateway.controller_watchdog: required`` and ``warn``; and the keys that configure it.
What the drive then does when the gateway stops: ``test_cia402_drive_stops``.

Golden frames follow CiA 301 (expedited SDO: ``23`` write 4 bytes, ``2B`` write 2 bytes,
``2F`` write 1 byte, ``40`` read, ``60`` write confirmed, ``43``/``4B``/``4F`` 4/2/1 bytes read;
heartbeat: 0x700 + node,
one byte NMT state, 0x05 OPERATIONAL) and are cross-checked with canopen's SDO constants.
"""

from __future__ import annotations

import itertools
import logging
from typing import TYPE_CHECKING

import pytest
from canopen.sdo import constants as sdo_constants

from drivers.cia402 import Cia402Driver
from drivers.cia402.codec import make_heartbeat, make_nmt, unpack_pdo
from drivers.cia402.enums import DataType, NmtCommand, NmtState, State
from drivers.cia402.phase import Phase
from drivers.cia402.sdo import make_sdo_download, parse_sdo_request
from drivers.cia402.sequence import NodeSequencer
from drivers.cia402.sim import Cia402Simulator
from gateway.config import load_config
from gateway.core.errors import ConfigError
from gateway.core.protection import Guard, ProtectionState, WatchdogPolicy
from gateway.core.types import DriveFault, DriveState, Frame, MotorConfig
from gateway.drive.driveset import DriveSet
from tests import factories
from tests.conftest import CONFIG_DIR
from tests.drivers.cia402_bench import DT, LEFT, TWO_PI, Bench, benches, hexb, left

if TYPE_CHECKING:
    from collections.abc import Callable, Iterator
    from pathlib import Path

U16 = DataType.UNSIGNED16


@pytest.fixture
def bench(channel: str) -> Iterator[Callable[..., Bench]]:
    with benches(channel) as make:
        yield make


def protection_sdos(frames: list[Frame], cob: int) -> list[Frame]:
    """The SDO frames on ``cob`` that address 0x1016, 0x6007, 0x1029 or 0x605A, in order."""
    return [f for f in frames if f.arbitration_id == cob
            and int.from_bytes(f.data[1:3], "little") in (0x1016, 0x6007, 0x1029, 0x605A)]


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
    drive answers (its 0x605A is the factory 2)."""
    b = bench([LEFT])
    assert b.enable([0.0])
    assert protection_sdos(b.sent, 0x603) == [
        Frame(0x603, hexb("23 16 10 01 C8 00 7F 00")),  # 0x1016:01 = 0x007F00C8
        Frame(0x603, hexb("2B 07 60 00 03 00 00 00")),  # 0x6007 = 3 (INTEGER16)
        Frame(0x603, hexb("2F 29 10 01 00 00 00 00")),  # 0x1029:01 = 0 (UNSIGNED8)
        Frame(0x603, hexb("40 16 10 01 00 00 00 00")),  # read 0x1016:01
        Frame(0x603, hexb("40 07 60 00 00 00 00 00")),  # read 0x6007
        Frame(0x603, hexb("40 29 10 01 00 00 00 00")),  # read 0x1029:01
        Frame(0x603, hexb("40 5A 60 00 00 00 00 00")),  # read 0x605A
    ]
    assert [f.data for f in protection_sdos(b.seen, 0x583)] == [
        hexb("60 16 10 01 00 00 00 00"), hexb("60 07 60 00 00 00 00 00"),
        hexb("60 29 10 01 00 00 00 00"), hexb("43 16 10 01 C8 00 7F 00"),
        hexb("4B 07 60 00 03 00 00 00"), hexb("4F 29 10 01 00 00 00 00"),
        hexb("4B 5A 60 00 02 00 00 00"),
    ]
    assert (127 << 16 | 200) == 0x007F00C8
    # canopen's reading of the command bytes: expedited, size given, 4, 2 and 1 bytes
    for frame, size in zip(protection_sdos(b.sent, 0x603)[:3], (4, 2, 1), strict=True):
        command = frame.data[0]
        assert command & 0xE0 == sdo_constants.REQUEST_DOWNLOAD
        assert command & sdo_constants.EXPEDITED and command & sdo_constants.SIZE_SPECIFIED
        assert 4 - ((command >> 2) & 3) == size
    reads = protection_sdos(b.sent, 0x603)[3:]
    assert all(f.data[0] == sdo_constants.REQUEST_UPLOAD for f in reads)
    sim = b.sims[0]
    assert (sim.object_value(0x1016, 1), sim.object_value(0x6007)) == (0x007F00C8, 3)
    assert sim.object_value(0x1029, 1) == 0
    assert b.drv.protection_state(0) is ProtectionState.CONFIRMED


def test_the_drive_is_not_enabled_before_the_read_back(bench: Callable[..., Bench]) -> None:
    """NMT start and the first controlword go out only after the drive has answered the
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
    readbacks = [f for f in protection_sdos(b.seen, 0x583) if f.data[0] != 0x60][:3]
    answered = readbacks[-1].timestamp_s  # the last read-back's answer
    assert readbacks[-1].data == hexb("4F 29 10 01 00 00 00 00")
    nmt_start = next(t for t, f in sent if f == make_nmt(NmtCommand.START, 3))
    first_cw = next(t for t, f in sent if f.arbitration_id == 0x503)
    assert answered <= nmt_start < first_cw
    assert {p for t, p in states if t < answered} == {ProtectionState.PENDING}
    assert {p for t, p in states if t >= answered} == {ProtectionState.CONFIRMED}
    between = {parse_sdo_request(f).index for t, f in sent if answered <= t < nmt_start
               and f.arbitration_id == 0x603}
    assert between <= {0x605A, 0x6060, 0x6061}  # what the quick stop does, the mode


# ----------------------------------------------------------------------------- the finding


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
        "8323272 (0x007F00C8) to 0x1016:01 (heartbeat consumer time) aborted: 0x06020000 "
        "Object does not "
        "exist; fix: use a drive with a heartbeat consumer (CiA 301 object 0x1016), the "
        "abort connection option code (CiA 402 object 0x6007) and, if it has the error "
        "behaviour object 0x1029, its value 0 (PRE-OPERATIONAL) in 0x1029:01, see its EDS "
        "file; or set a command timeout with the vendor's tool and "
        "gateway.controller_watchdog: warn")
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


# ----------------------------------------------------------------------------- configuration


def test_protection_as_the_driver_states_it() -> None:
    drv = Cia402Driver([LEFT, factories.motor("cia402", 5, "right", options={
        "abort_connection_option": 2, "controller_timeout_s": 0.5})])
    assert drv.PROTOCOL == "CiA 402"
    quick, coast = drv.protection(0), drv.protection(1)
    assert (quick.guard, quick.timeout_s, coast.timeout_s) == (Guard.CONFIGURED, 0.2, 0.5)
    assert quick.action.startswith("quick stop (0x605A quick stop option code")
    assert coast.action == "disable voltage (the power stage switches off: the motor coasts)"
    assert quick.how == ("heartbeat consumer 0x1016 watching node 127 every 200 ms, abort "
                         "connection option 0x6007 = 3 and error behaviour 0x1029:01 = 0 (NMT "
                         "PRE-OPERATIONAL, where the drive has the object), written by SDO and "
                         "read back")
    assert "not read yet; assumed 2" in quick.action  # (until the enable reads 0x605A)
    assert "0x6007 = 2" in coast.how and "every 500 ms" in coast.how
    assert drv.protection_state(0) is ProtectionState.PENDING
    seq = NodeSequencer(3, "node 3", drv.codec, ())  # no protection steps: not applicable
    assert seq.protection is ProtectionState.NOT_APPLICABLE


@pytest.mark.parametrize(
    ("motors", "message"),
    [
        ([left(host_node_id=3)],
         "motor 'left'.host_node_id: expected a node ID that no drive on the bus uses (the "
         "gateway's heartbeat goes out on 0x703), got 3, the node ID of wheel 'left'"),
        ([LEFT, factories.motor("cia402", 127, "right")],
         "motor 'right'.host_node_id: expected a node ID that no drive on the bus uses (the "
         "gateway's heartbeat goes out on 0x77F), got 127, the node ID of wheel 'right'"),
        ([LEFT, factories.motor("cia402", 5, "right", options={"host_node_id": 100})],
         "motor 'right'.host_node_id: expected 127 like motor 'left' on the same CiA 402 bus, "
         "got 100"),
        ([LEFT, factories.motor("cia402", 5, "right", options={"host_heartbeat_s": 0.02})],
         "motor 'right'.host_heartbeat_s: expected 0.05 like motor 'left' on the same CiA 402 "
         "bus, got 0.02"),
        ([left(validate=False, controller_timeout_s=0.09)],
         "motor 'left'.controller_timeout_s: expected at least 2 x host_heartbeat_s (0.1 s), "
         "or one late heartbeat of the gateway stops the drive; got 0.09"),
        ([left(validate=False, controller_timeout_s=0.2005)],
         "motor 'left'.controller_timeout_s: expected a whole number of milliseconds"),
        ([left(validate=False, abort_connection_option=1)],
         "motor 'left'.abort_connection_option: expected one of 2, 3, got 1"),
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
