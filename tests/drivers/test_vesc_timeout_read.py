"""The VESC's timeout read back while enabling (drivers/vesc/readback.py), over the virtual bus
with the simulator answering COMM_GET_APPCONF as firmware 6.00 does (drivers/vesc/sim_appconf.py).

The policy: read as stated: CONFIRMED, armed; other than stated: FAILED under
``gateway.controller_watchdog`` (required: not armed, warn: armed with a warning); no reply or
another layout: armed as before, with a warning saying why.
"""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING

import can
import pytest

from drivers.vesc import VescDriver
from drivers.vesc.appconf import BufferPacket, make_get_appconf
from drivers.vesc.codec import CanPacketId, make_set_rpm
from drivers.vesc.readback import Outcome, TimeoutReadback, Wanted
from drivers.vesc.sim import simulator_for
from drivers.vesc.sim_appconf import AppconfResponder
from gateway.bus.can_bus import drain
from gateway.core.protection import Guard, ProtectionState, WatchdogPolicy
from gateway.core.types import DriveFault, DriveState, Frame
from tests.drivers.test_drivers_vesc import motor
from tests.drivers.test_drivers_vesc_sim import Rig, rig

if TYPE_CHECKING:
    from drivers.vesc.sim import VescSimulator
    from gateway.core.types import MotorConfig

REQUIRED_ARM = "not arming it (gateway.controller_watchdog: required)"


def wheels(*stated: float, **sim_kwargs: object) -> tuple[list[MotorConfig], list[VescSimulator]]:
    """VESCs 23, 24... with these controller_timeout_s, and simulators of factory VESCs (1 s),
    status on so that they can be ENABLED."""
    motors = [motor(23 + i, wheel=f"w{i}", controller_timeout_s=s, status_rate_hz=50.0)
              for i, s in enumerate(stated)]
    sims = [simulator_for(motor(m.node_id, wheel=m.wheel, status_rate_hz=50.0))
            for m in motors]  # the factory timeout, whatever the block states
    for sim in sims:
        for key, value in sim_kwargs.items():
            setattr(sim, key, value)
    return motors, sims


def frames_of(spy: can.BusABC) -> list[Frame]:
    return [Frame(m.arbitration_id, bytes(m.data), m.is_extended_id) for m in drain(spy)]


def enable_and_run(r: Rig, seconds: float, speeds: list[float] | None = None) -> None:
    r.send(r.drv.enable(r.t))
    r.run(seconds, speeds)


def test_a_factory_vesc_read_as_stated_is_confirmed_and_armed(channel: str) -> None:
    motors, sims = wheels(1.0)
    spy = can.Bus(interface="virtual", channel=channel)
    try:
        with rig(channel, motors, sims) as r:
            r.run(0.02, None)
            drain(spy)
            r.send(r.drv.enable(r.t))
            assert r.states() == [DriveState.ENABLING]
            assert r.drv.protection_state(0) is ProtectionState.PENDING
            r.run(0.004, None)  # one round trip; the next poll arms
            seen = frames_of(spy)
            assert r.drv.protection_state(0) is ProtectionState.CONFIRMED
            r.run(0.1, None)
            assert r.states() == [DriveState.ENABLED]
            prot = r.drv.protection(0)
            assert (prot.guard, prot.timeout_s) == (Guard.STATED, 1.0)
            assert "read back from the VESC (timeout_msec 1000 ms)" in prot.describe()
    finally:
        spy.shutdown()
    buffer = [f for f in seen if f.arbitration_id >> 8 in set(BufferPacket)]
    # The request, then the 6.00 reply: 37 FILL_RX_BUFFER, 40 _LONG, one PROCESS_RX_BUFFER.
    assert buffer[0] == make_get_appconf(23)
    reply = buffer[1:]
    assert [f.arbitration_id for f in reply] == [0x5FE] * 37 + [0x6FE] * 40 + [0x7FE]
    assert reply[-1].data[:4] == bytes.fromhex("170101EE")  # VESC 23, a reply, 494 bytes
    assert next(f for f in seen if f.arbitration_id >> 8 == CanPacketId.SET_RPM) == (
        make_set_rpm(23, 0))  # armed after the reply
    assert seen.index(make_set_rpm(23, 0)) > seen.index(reply[-1])


def test_two_vescs_are_asked_one_at_a_time(channel: str) -> None:
    motors, sims = wheels(1.0, 1.0)
    spy = can.Bus(interface="virtual", channel=channel)
    try:
        with rig(channel, motors, sims) as r:
            enable_and_run(r, 0.1)
            seen = frames_of(spy)
            assert [r.drv.protection_state(i) for i in (0, 1)] == [ProtectionState.CONFIRMED] * 2
            assert r.states() == [DriveState.ENABLED] * 2
    finally:
        spy.shutdown()
    ends = [i for i, f in enumerate(seen) if f.arbitration_id == 0x7FE]
    asks = [seen.index(make_get_appconf(n)) for n in (23, 24)]
    assert asks[0] < ends[0] < asks[1] < ends[1]


@pytest.mark.parametrize("policy", [WatchdogPolicy.REQUIRED, WatchdogPolicy.WARN])
def test_a_timeout_other_than_stated_fails_under_the_policy(
    channel: str, policy: WatchdogPolicy, caplog: pytest.LogCaptureFixture
) -> None:
    motors, sims = wheels(0.5)  # stated 0.5 s; the VESC has the factory 1 s
    spy = can.Bus(interface="virtual", channel=channel)
    try:
        with rig(channel, motors, sims) as r, caplog.at_level(logging.INFO):
            r.drv.watchdog_policy = policy
            enable_and_run(r, 0.5, [5.0])
            seen = frames_of(spy)
            assert r.drv.protection_state(0) is ProtectionState.FAILED
            why = ("the VESC's timeout (App Settings > General > Timeout, timeout_msec) reads "
                   "1000 ms, the configuration states controller_timeout_s 0.5 s (500 ms)")
            fix = ("fix: state the VESC's timeout, controller_timeout_s: 1, or set App Settings "
                   "> General > Timeout in VESC Tool to 500 ms")
            assert r.drv.protection_failure(0) == why
            rpm = [f for f in seen if f.arbitration_id >> 8 == CanPacketId.SET_RPM]
            if policy is WatchdogPolicy.REQUIRED:
                assert rpm == []  # not armed: nothing drives the motor
                assert r.states() == [DriveState.FAULT]
                assert r.drv.faults(0) & DriveFault.WATCHDOG
                assert r.drv.detail(0).startswith(
                    f"motor 'w0' (VESC node 23): controller watchdog not confirmed: {why}; {fix}")
                assert r.drv.enable_failed() == [0]
                assert REQUIRED_ARM in caplog.text
                assert sims[0].wheel_velocity_rad_s == 0.0
            else:
                assert rpm[0] == make_set_rpm(23, 0) and rpm[-1] != make_set_rpm(23, 0)
                assert r.states() == [DriveState.ENABLED]
                assert "arming it anyway (gateway.controller_watchdog: warn)" in caplog.text
                assert why in caplog.text
    finally:
        spy.shutdown()


def test_a_vesc_that_does_not_answer_is_armed_as_before_with_a_warning(
    channel: str, caplog: pytest.LogCaptureFixture
) -> None:
    motors, sims = wheels(1.0, appconf=AppconfResponder(answers=False))
    with rig(channel, motors, sims) as r, caplog.at_level(logging.WARNING):
        enable_and_run(r, 0.7)
        assert r.states() == [DriveState.ENABLING]  # three requests 0.25 s apart
        r.run(0.1, None)
        assert r.states() == [DriveState.ENABLED]
        assert r.drv.protection_state(0) is ProtectionState.NOT_APPLICABLE
        prot = r.drv.protection(0)
        assert (prot.guard, prot.timeout_s) == (Guard.STATED, 1.0)
        assert "could not be read back from the VESC: no reply to COMM_GET_APPCONF" in prot.how
    assert ("VESC 23 ('w0'): timeout not read back, arming it as stated: no reply to "
            "COMM_GET_APPCONF after 3 requests 0.25 s apart (firmware") in caplog.text


@pytest.mark.parametrize(("responder", "why"), [
    (AppconfResponder(crc_xor=0x0101), "the reply was malformed: PROCESS_RX_BUFFER: expected "
                                       "crc16 0x"),
    (AppconfResponder(controller_id=99), "cannot read the timeout: the reply's layout is not "
                                         "the one expected (byte 5, controller_id, is 99, "
                                         "expected the VESC's ID 23; signature 486554156)"),
])
def test_a_bad_reply_fails_the_read_with_its_reason(
    channel: str, responder: AppconfResponder, why: str, caplog: pytest.LogCaptureFixture
) -> None:
    motors, sims = wheels(0.5, appconf=responder)  # even a differing timeout is not judged
    with rig(channel, motors, sims) as r, caplog.at_level(logging.WARNING):
        enable_and_run(r, 1.0)
        result = r.drv.readback.results[0] if r.drv.readback else None
        assert result is not None and result.outcome is Outcome.NOT_READ
        assert result.why.startswith(why)
        assert r.states() == [DriveState.ENABLED]  # never blocks
        assert r.drv.rejected["malformed"] >= 1
    assert why in caplog.text


def test_an_unstated_timeout_is_shown_as_read(channel: str) -> None:
    motors, sims = wheels(0.0)
    with rig(channel, motors, sims) as r:
        assert r.drv.protection(0).guard is Guard.UNSTATED
        enable_and_run(r, 0.1)
        prot = r.drv.protection(0)
        assert (prot.guard, prot.timeout_s) == (Guard.UNSTATED, 1.0)
        assert prot.how == "not stated; read back from the VESC: timeout_msec 1000 ms"
        assert prot.fix == "state it: controller_timeout_s: 1"
        assert r.states() == [DriveState.ENABLED]
        sims[0].timeout_s = 0.0  # the timeout switched off in VESC Tool: nothing stops it
        enable_and_run(r, 0.1)
        assert r.drv.protection_state(0) is ProtectionState.FAILED
        assert "reads 0 ms: it never releases the motor" in r.drv.detail(0)


def test_check_says_it_is_read_back_while_enabling() -> None:
    """``wheelgate check`` is offline: the protection says when it will be read."""
    prot = VescDriver([motor(23, controller_timeout_s=1.0)]).protection(0)
    assert prot.how == ("set in VESC Tool; stated by controller_timeout_s; read back from the "
                        "VESC while enabling (COMM_GET_APPCONF over CAN)")
    drv = VescDriver([motor(23)])
    assert drv.preview_command([1.0]) == [make_set_rpm(23, 67)]  # armed as if confirmed


def test_a_vesc_with_the_gateways_id_is_not_read_and_armed_at_once() -> None:
    drv = VescDriver([motor(254), motor(23, wheel="right")])
    assert drv.readback is None
    assert drv.enable(0.0) == [make_set_rpm(254, 0), make_set_rpm(23, 0)]
    assert drv.protection_state(0) is ProtectionState.NOT_APPLICABLE
    assert not any(c.can_id >> 8 == BufferPacket.FILL_RX_BUFFER for c in drv.claims())


def test_silent_vescs_give_up_within_the_budget() -> None:
    rb = TimeoutReadback([Wanted(n, 1.0, 0.02) for n in range(4)])
    sent = rb.start(0.0)
    t = 0.0
    while t < 3.0:
        t += 0.01
        sent += rb.poll(t)
        if all(r.outcome is not Outcome.PENDING for r in rb.results):
            break
    assert t == pytest.approx(TimeoutReadback.BUDGET_S, abs=0.011)
    # 3 requests to each of the first two (0.75 s each), then the third's, then the budget.
    assert [f.arbitration_id & 0xFF for f in sent] == [0] * 3 + [1] * 3 + [2] * 2
    assert [r.outcome for r in rb.results] == [Outcome.NOT_READ] * 4
    assert "not read within 2 s of the enable" in rb.results[3].why


def test_a_late_reply_of_the_vesc_asked_before_is_not_taken_for_the_next() -> None:
    """A retry's reply that comes after the VESC was read (a slow bus) is not the next VESC's
    reply with another layout: it is dropped, and the next VESC's own reply is read."""
    drv = VescDriver([motor(23, controller_timeout_s=1.0),
                      motor(24, wheel="right", controller_timeout_s=1.0)])
    sims = [simulator_for(m) for m in drv.motors]
    first = drv.enable(0.0)
    late = sims[0].handle(first[0], 0.0)  # the same reply twice: to the request, to a retry
    for f in late:
        drv.on_frame(f)
    second = drv.poll(0.01)
    assert make_get_appconf(24) in second
    for f in late + sims[1].handle(make_get_appconf(24), 0.01):
        drv.on_frame(f)
    assert [drv.protection_state(i) for i in (0, 1)] == [ProtectionState.CONFIRMED] * 2
    assert not drv.rejected
