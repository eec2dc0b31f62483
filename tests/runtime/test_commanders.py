"""A second commander on the bus (``gateway.runtime.commanders``): the gateway's own frames
sent by another program are a fault while it drives, a warning while it does not; remote frames
and the twist input are not; the kernel filters let them in."""

from __future__ import annotations

import dataclasses
import logging
import struct
from typing import TYPE_CHECKING

import can

from gateway.config import load_config
from gateway.core.control import Source
from gateway.core.status import LastError
from gateway.core.types import ErrorCode, GatewayState, Twist
from gateway.drive.driveset import DriveSet
from gateway.drive.filters import CanFilter
from gateway.runtime.commanders import own_frames
from tests.conftest import CONFIG_DIR
from tests.e2e_helpers import Rig

if TYPE_CHECKING:
    import pytest

#: Set_Input_Vel (cmd 0x0D) of ODrive node 1: the default robot's front-left command.
SET_INPUT_VEL_1 = 1 << 5 | 0x0D


def rig(channel: str, name: str | None = None) -> Rig:
    cfg = load_config(None if name is None else CONFIG_DIR / name,
                      {"interface": "virtual", "channel": channel})
    return Rig(dataclasses.replace(cfg, loop=dataclasses.replace(cfg.loop, rate_hz=100.0)))


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
