"""What the CiA 402 driver learns of a drive's own stop while enabling, and what it reports
(:mod:`drivers.cia402.protection`, :mod:`drivers.cia402.quick_stop`): the quick stop option
code (CiA 402 0x605A) read and stated as the protection's action, with a warning where the motor
would coast or the action is not known; the error behaviour (CiA 301 0x1029:01), written 0 (NMT
PRE-OPERATIONAL at the heartbeat event) and read back, skipped where the drive has none (the CiA
301 default) and a failed protection where the drive keeps another value; and a drive that went
PRE-OPERATIONAL unheard (no heartbeat producer, its EMCY lost) is configured again by the next
enable, NMT start included.
"""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING

import pytest

from drivers.cia402.codec import make_nmt
from drivers.cia402.enums import NmtCommand, NmtState
from drivers.cia402.phase import Phase
from drivers.cia402.sim import Cia402Simulator
from gateway.core.protection import ProtectionState, WatchdogPolicy
from gateway.core.types import DriveFault, DriveState
from tests.drivers.cia402_bench import LEFT, Bench, benches, hexb, left

if TYPE_CHECKING:
    from collections.abc import Callable, Iterator


@pytest.fixture
def bench(channel: str) -> Iterator[Callable[..., Bench]]:
    with benches(channel) as make:
        yield make


def sdo_requests(b: Bench, index: int) -> list[bytes]:
    """The SDO requests to node 3 on ``index``, in order."""
    return [f.data for f in b.sent
            if f.arbitration_id == 0x603 and int.from_bytes(f.data[1:3], "little") == index]


@pytest.mark.parametrize(
    ("option", "action", "warned"),
    [
        (2, "= 2, read from the drive: slow down on the quick-stop ramp (0x6085 quick stop "
            "deceleration) to standstill, then SWITCH ON DISABLED)", False),
        (6, "= 6, read from the drive: slow down on the quick-stop ramp (0x6085 quick stop "
            "deceleration) to standstill, then stays in QUICK STOP ACTIVE", False),
        (1, "= 1, read from the drive: slow down on the slow-down ramp (0x6084", False),
        (0, "= 0, read from the drive: disable drive function: the power stage switches off "
            "at once, the motor coasts)", True),
        (-3, "= -3, read from the drive: manufacturer-specific: see the drive's manual)", True),
        (None, "not known, its read was aborted with 0x06020000 Object does not exist; "
               "assumed 2, the profile's usual default: slow down on the quick-stop ramp", True),
    ],
    ids=["2-ramp", "6-stays", "1-slow-down", "0-coasts", "manufacturer", "absent"],
)
def test_the_quick_stop_action_is_the_drives(
    bench: Callable[..., Bench], caplog: pytest.LogCaptureFixture,
    option: int | None, action: str, warned: bool,
) -> None:
    """0x605A is the drive's (the driver does not write it): read while enabling, it is the
    action reported; a value without braking to standstill, or none to read, is a warning.
    The enable goes on in every case (what the drive does is stated, not refused)."""
    b = bench([LEFT], missing_objects=(0x605A,) if option is None else ())
    if option is not None:
        b.sims[0].od.set(0x605A, option)  # the drive's saved value
    before = b.drv.protection(0).action
    assert "not read yet; assumed 2" in before
    with caplog.at_level(logging.INFO):
        assert b.enable([0.0])
    assert sdo_requests(b, 0x605A) == [hexb("40 5A 60 00 00 00 00 00")]  # read, never written
    stated = b.drv.protection(0).action
    assert stated.startswith("quick stop (0x605A quick stop option code ") and action in stated
    warnings = [r for r in caplog.records if r.levelno >= logging.WARNING and "0x605A" in r.message]
    assert bool(warnings) is warned
    assert b.drv.protection_state(0) is ProtectionState.CONFIRMED


def test_disable_voltage_reads_no_quick_stop_option(bench: Callable[..., Bench]) -> None:
    b = bench([left(abort_connection_option=2)])
    assert b.enable([0.0])
    assert sdo_requests(b, 0x605A) == []
    assert b.drv.protection(0).action.startswith("disable voltage")


def test_a_drive_without_error_behaviour_has_the_cia301_default(
    bench: Callable[..., Bench], caplog: pytest.LogCaptureFixture
) -> None:
    """0x1029 is optional (CiA 301): a drive without it answers the write with 0x06020000 and
    goes PRE-OPERATIONAL at a communication error by default; its read-back is skipped and the
    protection is confirmed."""
    b = bench([LEFT], missing_objects=(0x1029,))
    with caplog.at_level(logging.INFO):
        assert b.enable([0.0])
    assert sdo_requests(b, 0x1029) == [hexb("2F 29 10 01 00 00 00 00")]  # no read-back
    assert b.drv.protection_state(0) is ProtectionState.CONFIRMED
    assert ("0x1029:01 (error behaviour, communication error): the drive has none (0x06020000 "
            "Object does not exist): CiA 301's default applies") in caplog.text


@pytest.mark.parametrize("policy", [WatchdogPolicy.REQUIRED, WatchdogPolicy.WARN])
def test_a_drive_that_keeps_no_state_change_is_a_failed_protection(
    bench: Callable[..., Bench], policy: WatchdogPolicy
) -> None:
    """A drive whose saved 0x1029:01 is 1 (no state change) and that does not take the write:
    after a heartbeat event it would go on taking RPDOs.  Under ``required`` it is not enabled."""
    b = bench([LEFT], ignored_writes=(0x1029,))
    b.sims[0].od.set(0x1029, 1, 1)
    b.drv.watchdog_policy = policy
    b.send(b.drv.enable(b.t))
    b.run(1.0, [0.0], until=lambda: b.drv.phase(0) in (Phase.FAILED, Phase.ARMED))
    assert b.drv.protection_state(0) is ProtectionState.FAILED
    (status,) = b.drv.status(b.t)
    assert ("0x1029:01 (error behaviour, communication error) reads 1 after the write of 0"
            in (status.detail if policy is WatchdogPolicy.REQUIRED
                else b.drv.protection_failure(0)))
    if policy is WatchdogPolicy.REQUIRED:
        assert (status.state, status.faults) == (DriveState.FAULT, DriveFault.WATCHDOG)
        assert b.sims[0].nmt is NmtState.PRE_OPERATIONAL
    else:
        assert b.run(0.5, [0.0], until=lambda: b.state() is DriveState.ENABLED)


def nmt_of(sim: Cia402Simulator) -> NmtState:  # a call, so mypy does not narrow the attribute
    return sim.nmt


class EmcyLost(Cia402Simulator):
    """A drive whose EMCY of the heartbeat event does not reach the gateway."""

    def _connection_lost(self) -> None:
        super()._connection_lost()
        self._emcy_out.clear()


def test_an_armed_drive_gone_pre_operational_unheard_is_configured_again(
    bench: Callable[..., Bench], monkeypatch: pytest.MonkeyPatch
) -> None:
    """No producer heartbeat (``heartbeat_ms: 0``) and the EMCY lost: the driver does not hear
    the drive go PRE-OPERATIONAL, only its TPDOs stop (OFFLINE, still armed as far as the
    sequence knows).  An enable then runs the whole sequence again, NMT start included,
    instead of keeping the armed node as it is."""
    b = bench([left(heartbeat_ms=0)], sim_class=EmcyLost)
    assert b.enable([0.0])
    b.run(0.2, [5.0])
    sim = b.sims[0]
    with monkeypatch.context() as patch:
        patch.setattr(b.drv.host, "poll", lambda now_s: [])
        b.run(0.6, [5.0])
    assert nmt_of(sim) is NmtState.PRE_OPERATIONAL and abs(sim.wheel_velocity_rad_s) < 0.01
    assert (b.state(), b.drv.phase(0)) == (DriveState.OFFLINE, Phase.ARMED)
    start = len(b.sent)
    assert b.enable([0.0], seconds=1.0)
    assert make_nmt(NmtCommand.ENTER_PRE_OPERATIONAL, 3) in b.sent[start:]
    assert make_nmt(NmtCommand.START, 3) in b.sent[start:]
    assert nmt_of(sim) is NmtState.OPERATIONAL
    b.run(0.3, [5.0])
    assert sim.wheel_velocity_rad_s == pytest.approx(5.0, abs=0.01)
