"""A second commander on the bus (``gateway.runtime.commanders``): the gateway's own frames
sent by another program are a fault while it drives, a warning while it does not; remote frames
and the twist input are not; the kernel filters let them in."""

from __future__ import annotations

import dataclasses
import logging
import struct
import threading
from typing import TYPE_CHECKING

import can
from click.testing import CliRunner

from gateway.cli import main
from gateway.config import load_config
from gateway.core.control import Source
from gateway.core.status import LastError
from gateway.core.types import ErrorCode, GatewayState, Twist
from gateway.drive.driveset import DriveSet
from gateway.drive.filters import CanFilter
from gateway.runtime.commanders import LISTEN_S, own_frames
from gateway.runtime.daemon import Daemon
from gateway.runtime.sdnotify import SystemdNotifier
from tests.conftest import CONFIG_DIR
from tests.e2e_helpers import Rig, reports, sent

if TYPE_CHECKING:
    import pytest

    from gateway.core.settings import GatewayConfig

#: Set_Input_Vel (cmd 0x0D) of ODrive node 1: the default robot's front-left command.
SET_INPUT_VEL_1 = 1 << 5 | 0x0D


def config(channel: str, name: str | None = None) -> GatewayConfig:
    cfg = load_config(None if name is None else CONFIG_DIR / name,
                      {"interface": "virtual", "channel": channel})
    return dataclasses.replace(cfg, loop=dataclasses.replace(cfg.loop, rate_hz=100.0))


def rig(channel: str, name: str | None = None) -> Rig:
    return Rig(config(channel, name))


def drive(r: Rig, seconds: float) -> None:
    for _ in range(max(1, round(seconds / 0.2))):
        r.gw.twist(Twist(0.3), r.t, Source.SOCKET)
        r.advance(0.2)


def other(r: Rig, ident: int, data: bytes = bytes(8), extended: bool = False,
          remote: bool = False) -> None:
    """A frame from another program on the robot's bus."""
    r.pilot.send(can.Message(arbitration_id=ident, data=b"" if remote else data,
                             is_extended_id=extended, is_remote_frame=remote,
                             dlc=8 if remote else len(data)))


def test_the_own_frames_are_the_cyclic_commands_and_the_gateways_reports() -> None:
    cfg = load_config(None)  # four ODrives, nodes 1..4; the CAN twist input on
    own = own_frames(cfg, DriveSet(cfg))
    ids = cfg.loop.can_ids
    assert {k for k, v in own.items() if v.startswith("a command: ")} == {
        (n << 5 | 0x0D, False) for n in (1, 2, 3, 4)}
    assert own[(SET_INPUT_VEL_1, False)] == "a command: ODrive node 1 Set_Input_Vel (front_left)"
    assert own[(ids.status, ids.extended)] == "WG_Status of another wheelgate"
    assert (ids.twist, ids.extended) not in own  # another node's twists are the input


def test_the_kernel_filters_let_another_senders_commands_in() -> None:
    with rig("wg-cmd-filters", "mecanum.yaml") as r:  # DJI: 0x200 is only ever sent by us
        assert CanFilter.exact(0x200, False) in r.gw.receive_filters
        ids = r.config.loop.can_ids
        assert CanFilter.exact(ids.odom_pose, ids.extended) in r.gw.receive_filters


def test_another_senders_command_is_a_fault_that_names_it_and_the_robot_stops() -> None:
    with rig("wg-cmd-fault") as r:
        r.enable()
        drive(r, 1.0)
        assert min(abs(s.wheel_velocity_rad_s) for s in r.drive_sims) > 1.0
        other(r, SET_INPUT_VEL_1, struct.pack("<ff", 3.0, 0.0))
        r.advance(0.05)
        assert r.gw.state is GatewayState.FAULT
        reason = r.gw.supervisor.reason
        assert reason.startswith(
            "another sender on virtual:wg-cmd-fault: heard 02D#0000404000000000 (a command: "
            "ODrive node 1 Set_Input_Vel (front_left)), which only this gateway sends: two "
            "programs command these motors"), reason
        assert r.gw.commanders.heard == 1
        errors = [e for e in r.gw.outbox
                  if isinstance(e, LastError) and e.code is ErrorCode.BUS_ERROR]
        assert errors and errors[-1].message == reason  # reported to subscribers and on CAN
        r.advance(1.0)  # zero commanded; the other sent once: every wheel comes to rest
        assert max(abs(s.wheel_velocity_rad_s) for s in r.drive_sims) < 0.05


def test_another_wheelgate_on_the_bus_is_a_warning_its_commands_a_fault(
        caplog: pytest.LogCaptureFixture) -> None:
    with rig("wg-cmd-twin") as r, caplog.at_level(logging.WARNING,
                                                  logger="gateway.runtime.commanders"):
        r.enable()
        ids = r.config.loop.can_ids
        other(r, ids.status, bytes(8), ids.extended)  # (another robot's gateway, maybe)
        r.advance(0.05)
        assert r.gw.state is GatewayState.RUNNING
        assert [rec.getMessage() for rec in caplog.records] == [
            f"another sender on virtual:wg-cmd-twin: heard {ids.status:X}#0000000000000000 "
            f"(WG_Status of another wheelgate): another wheelgate runs on this bus; if it "
            f"drives these motors, stop it; if it drives others, give each its own "
            f"gateway.can_ids (1 such frames since the last line)"]
        other(r, SET_INPUT_VEL_1)  # and it drives ours
        r.advance(0.05)
        after: GatewayState = r.gw.state
        assert after is GatewayState.FAULT


def test_remote_frames_and_a_quiet_bus_are_not_another_commander(
        caplog: pytest.LogCaptureFixture) -> None:
    with rig("wg-cmd-quiet") as r:
        r.enable()
        drive(r, 1.0)  # our own commands, hundreds of them: never heard back as another's
        other(r, SET_INPUT_VEL_1, remote=True)  # a request, not a command
        drive(r, 0.4)
        assert r.gw.state is GatewayState.RUNNING, r.gw.supervisor.reason
        assert r.gw.commanders.heard == 0
        r.gw.supervisor.disable()
        r.advance(0.2)
        with caplog.at_level(logging.WARNING, logger="gateway.runtime.commanders"):
            for _ in range(3):
                other(r, SET_INPUT_VEL_1)
                r.advance(0.05)
        state: GatewayState = r.gw.state
        assert state is GatewayState.DISABLED  # nothing of ours to overwrite: a warning
        assert r.gw.commanders.heard == 3
        lines = [rec.getMessage() for rec in caplog.records
                 if rec.name == "gateway.runtime.commanders"]
        assert len(lines) == 1 and lines[0].startswith("another sender on virtual:wg-cmd-quiet")
        assert lines[0].endswith("(1 such frames since the last line)")


def test_the_first_enable_waits_until_the_gateway_has_listened() -> None:
    with rig("wg-cmd-listen") as r:
        out = sent(r.gw)
        r.gw.supervisor.enable(r.t)
        r.advance(LISTEN_S - 0.05)
        assert r.gw.state is GatewayState.ENABLING and r.gw.supervisor.enable_pending
        assert set(out) <= reports(r.gw)  # nothing to the motors while it listens
        r.enable()  # then the enable is taken
        assert set(out) - reports(r.gw)


def test_systemd_and_the_log_say_the_gateway_listens_then_waits_for_the_motors(
        sock_path: str, caplog: pytest.LogCaptureFixture) -> None:
    with Rig(config("wg-cmd-says"), socket_path=sock_path) as r, \
            caplog.at_level(logging.INFO, "gateway.runtime.daemon"):
        r.gw.supervisor.enable(r.t)
        r.advance(0.6)
        assert r.gw.state is GatewayState.RUNNING
    states = [rec.getMessage() for rec in caplog.records if rec.getMessage().startswith("state")]
    assert states == [
        "state ENABLING: listening 0.25 s for another program commanding these motors before "
        "enabling them",
        "state ENABLING: waiting for the motors to enable",  # (listened: the enable is taken)
        "state RUNNING"], states


def test_a_second_gateway_beside_a_commanding_one_withholds_its_enable_and_sends_nothing(
        caplog: pytest.LogCaptureFixture) -> None:
    # The robot is driven by another program (a wheelgate already running: its command of
    # node 1 every cycle); this gateway starts with enable_on_start.
    with rig("wg-cmd-second") as r, caplog.at_level(logging.ERROR):
        out = sent(r.gw)
        r.gw.supervisor.enable(r.t)
        r.advance(1.5, lambda r: other(r, SET_INPUT_VEL_1, struct.pack("<ff", 2.0, 0.0)))
        assert r.gw.state is GatewayState.FAULT
        reason = r.gw.supervisor.reason
        assert reason.startswith(
            "enable withheld: another sender on virtual:wg-cmd-second: heard "
            "02D#0000004000000000 (a command: ODrive node 1 Set_Input_Vel (front_left)) 0.0"
        ), reason
        assert reason.endswith(" s ago: another program commands these motors (another "
                               "wheelgate run, jog --standalone, a script), and it keeps "
                               "them; stop it, then enable"), reason
        assert r.gw.supervisor.fault_code is ErrorCode.BUS_ERROR
        errors = [e for e in r.gw.outbox if isinstance(e, LastError)]
        assert errors and errors[-1].message == reason  # reported to subscribers and on CAN
        # The automatic recovery retried (and was withheld again) while the other sent.
        assert r.gw.supervisor.counts.faults >= 2
        assert set(out) <= reports(r.gw)  # not one frame to the motors: the other keeps them
        # The other stops: the automatic recovery enables this one.
        r.advance(3.0)
        after: GatewayState = r.gw.state
        assert after is GatewayState.RUNNING, r.gw.supervisor.reason
        assert set(out) - reports(r.gw)


def test_a_gateway_that_fought_lets_go_at_the_retry_while_the_other_commands() -> None:
    with rig("wg-cmd-letgo") as r:
        r.enable()
        drive(r, 0.4)
        out = sent(r.gw)
        r.advance(2.0, lambda r: other(r, SET_INPUT_VEL_1))
        assert r.gw.state is GatewayState.FAULT
        assert r.gw.supervisor.reason.startswith("enable withheld: "), r.gw.supervisor.reason
        assert not r.gw.armed
        tail = len(out)
        r.advance(0.5, lambda r: other(r, SET_INPUT_VEL_1))
        assert set(out[tail:]) <= reports(r.gw)  # let go: the disable went out once, then nothing


def test_a_canopen_gateway_makes_no_sync_while_another_produces_it() -> None:
    # CiA 301: one SYNC producer per network.  Our SYNC and heartbeat are housekeeping sent
    # even while disabled; beside another producer this gateway sends neither.
    with rig("wg-cmd-sync", "synchro.yaml") as r:
        out = sent(r.gw)
        r.gw.supervisor.enable(r.t)
        r.advance(1.0, lambda r: other(r, 0x80, b""))
        assert r.gw.state is GatewayState.FAULT
        assert "(a command: CiA 402 SYNC (" in r.gw.supervisor.reason, r.gw.supervisor.reason
        assert set(out) <= reports(r.gw)


def test_a_gateway_stopping_beside_another_commander_sends_its_motors_nothing(
        sock_path: str) -> None:
    cfg = config("wg-cmd-stop")
    with Rig(cfg, socket_path=sock_path) as r:
        assert r.daemon is not None
        r.gw.supervisor.enable(r.t)
        r.advance(0.6, lambda r: other(r, SET_INPUT_VEL_1))
        out = sent(r.gw)
        r.daemon.shutdown(r.t)
        assert out == []  # not even the zero and disarm: the motors are the other's
        assert r.daemon.left_to.startswith(
            "another program commands them (another sender on virtual:wg-cmd-stop: heard 02D#"
        ), r.daemon.left_to
    with Rig(cfg, socket_path=sock_path) as r:  # alone on the bus: the zero and disarm go out
        assert r.daemon is not None
        r.advance(0.6)
        out = sent(r.gw)
        r.daemon.shutdown(r.t)
        assert (SET_INPUT_VEL_1, False) in out and r.daemon.left_to == ""


def test_a_second_gateway_beside_a_running_one_stops_neither(sock_path: str) -> None:
    # The whole scene on the virtual bus (on vcan: test_socketcan_faults.py): a gateway
    # drives the robot; a second one for the same robot starts beside it, enabled at start.
    # The ODrives' heartbeats say closed loop (the first one's doing): the second must not take
    # that for its own enable.
    with rig("wg-cmd-two") as r:
        r.enable()
        drive(r, 0.6)
        faults = r.gw.supervisor.counts.faults
        second = Daemon(r.config, socket_path=sock_path, notifier=SystemdNotifier(None))
        try:
            second.gateway.edge.stamp_with_cycle_time = True  # (the rig's simulated time)
            out = sent(second.gateway)
            second.gateway.supervisor.enable(r.t)
            for _ in range(5):
                r.gw.twist(Twist(0.3), r.t, Source.SOCKET)
                r.advance(0.2, lambda r: second.step(r.t))
            assert second.gateway.state is GatewayState.FAULT
            assert second.gateway.supervisor.reason.startswith("enable withheld: ")
            assert r.gw.state is GatewayState.RUNNING, r.gw.supervisor.reason
            assert min(abs(s.wheel_velocity_rad_s) for s in r.drive_sims) > 1.0
            assert set(out) <= reports(r.gw)
            second.shutdown(r.t)
            assert set(out) <= reports(r.gw) and second.left_to
            drive(r, 0.4)
            assert r.gw.state is GatewayState.RUNNING, r.gw.supervisor.reason
            assert r.gw.supervisor.counts.faults == faults  # never disturbed
        finally:
            second.close()


def test_run_beside_another_commander_says_it_left_the_motors_to_it(
        sock_path: str, caplog: pytest.LogCaptureFixture) -> None:
    # `wheelgate run` (enabled at start) while a program commands node 1 every 10 ms on the
    # same bus: the fault, the line for the person, and a last line that sends no stop.
    channel = "wg-cmd-run"
    stop = threading.Event()

    def commander() -> None:
        with can.Bus(interface="virtual", channel=channel) as bus:
            while not stop.wait(0.01):
                bus.send(can.Message(arbitration_id=SET_INPUT_VEL_1, data=bytes(8),
                                     is_extended_id=False))

    thread = threading.Thread(target=commander, daemon=True)
    thread.start()
    try:
        result = CliRunner().invoke(main, ["--channel", channel, "run", "--sim", "--socket",
                                           sock_path, "--duration", "1.0"])
    finally:
        stop.set()
        thread.join(timeout=5.0)
    assert result.exit_code == 0, result.output
    assert "fault: enable withheld: another sender on virtual:wg-cmd-run: heard 02D#" in (
        caplog.text)
    assert ("wheelgate: not enabled: another program commands these motors, and nothing is "
            "sent to them while it does") in result.stderr
    assert ("wheelgate: stopped; nothing was sent to the motors: another program commands "
            "them (another sender on virtual:wg-cmd-run: heard 02D#") in result.stderr
