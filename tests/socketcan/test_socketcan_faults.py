"""Bus faults on a kernel SocketCAN bus (the ``socketcan`` tier): a full transmit queue, an
interface that goes down and up, error frames and bus-off, CAN FD frames.

The gateway and its simulated controllers run in this process on simulated time, as in
``test_safety_bus.py``, but their frames cross the kernel's vcan interface, so every fault is the
kernel's own (``ENOBUFS`` from a rate-limited qdisc, ``ENETDOWN``, error frames delivered by
``CAN_RAW_ERR_FILTER``).  The checks judge what reaches the bus, not how fast: the CI runs
this tier in an emulated VM about 14 times slower than the host.
"""

from __future__ import annotations

import dataclasses
import logging
import subprocess
from typing import TYPE_CHECKING

import can
import pytest

from drivers.odrive.enums import CmdId
from gateway.config import load_config
from gateway.core.control import Source
from gateway.core.status import BusErrorState
from gateway.core.types import ErrorCode, GatewayState, Twist
from gateway.runtime.daemon import Daemon
from gateway.runtime.sdnotify import SystemdNotifier
from tests.e2e_helpers import Rig, error_frame, reports, sent

if TYPE_CHECKING:
    from collections.abc import Iterator
    from pathlib import Path

pytestmark = [pytest.mark.socketcan, pytest.mark.timeout(300)]


@pytest.fixture
def rig(vcan: str) -> Iterator[Rig]:
    """The default robot (four ODrives) on the kernel interface at 100 Hz simulated time."""
    cfg = load_config(None, {"interface": "socketcan", "channel": vcan})
    cfg = dataclasses.replace(cfg, loop=dataclasses.replace(cfg.loop, rate_hz=100.0))
    with Rig(cfg) as r:
        r.enable()
        yield r


def ip(*args: str) -> None:
    subprocess.run(["ip", *args], check=True, capture_output=True, timeout=30)


def tc(*args: str) -> None:
    subprocess.run(["tc", *args], check=True, capture_output=True, timeout=30)


def drive(rig: Rig, seconds: float, vx: float = 0.2) -> None:
    """Drive forward for ``seconds`` of simulated time, the twist renewed every 0.2 s."""
    for _ in range(max(1, round(seconds / 0.2))):
        rig.gw.twist(Twist(vx), rig.t, Source.SOCKET)
        rig.advance(0.2)


def state(rig: Rig) -> GatewayState:
    return rig.gw.state


def command_ids(rig: Rig) -> set[int]:
    return {(m.node_id << 5) | CmdId.SET_INPUT_VEL for m in rig.config.motors if m is not None}


def _longest_gap(order: list[int], can_id: int) -> int:
    """The most frames of other IDs between two of ``can_id`` (or before its first)."""
    longest = run = 0
    for i in order:
        run = 0 if i == can_id else run + 1
        longest = max(longest, run)
    return longest if can_id in order else len(order)


def test_a_full_transmit_queue_cuts_bursts_but_starves_no_wheel(
    rig: Rig, vcan: str, caplog: pytest.LogCaptureFixture
) -> None:
    drive(rig, 0.4)
    ids = command_ids(rig)
    order: list[int] = []  # the wheels' commands in the order they reached the bus
    watcher = can.Bus(interface="socketcan", channel=vcan,
                      can_filters=[{"can_id": i, "can_mask": 0x7FF, "extended": False}
                                   for i in ids])
    # A controller slower than the host: the queue takes 4 frames and drains 40 kbit/s
    # (312 frames/s), less than the gateway and the four simulated drives send.
    tc("qdisc", "replace", "dev", vcan, "root", "netem", "rate", "40kbit", "limit", "4")
    try:
        with caplog.at_level(logging.WARNING, logger="gateway.runtime.loop"):
            for _ in range(10):
                drive(rig, 0.2)
                while (msg := watcher.recv(0.0)) is not None:
                    order.append(msg.arbitration_id)
    finally:
        tc("qdisc", "del", "dev", vcan, "root")
        watcher.shutdown()
    counts = rig.gw.edge.counts
    assert counts.send_waits + counts.frames_unsent > 0, counts  # ENOBUFS happened
    # What reached the bus: every wheel's command, none starved behind the others.  Judged by
    # order, not rate (the VM's speed sets how much the queue takes a cycle): the frames left
    # out go first, longest left out first, so between two commands of one wheel the bus
    # carries a few of each other wheel's, never a run of them (the burst's own order
    # starved the last wheels: 28 of theirs to 102 of the first's).
    assert min(order.count(i) for i in ids) >= 10, order
    assert max(_longest_gap(order, i) for i in ids) <= 3 * (len(ids) - 1), order
    lines = [r for r in caplog.records if "send failed" in r.getMessage()]
    assert len(lines) <= 3, [r.getMessage() for r in lines]
    if state(rig) is GatewayState.FAULT:  # a queue this slow may keep a command out too long
        assert rig.gw.supervisor.fault_code in (ErrorCode.BUS_ERROR, ErrorCode.FEEDBACK_TIMEOUT)
    # The queue is fast again: the gateway runs on, or recovers by itself.
    rig.advance(3.0)
    drive(rig, 0.6)
    assert state(rig) is GatewayState.RUNNING, rig.gw.supervisor.reason
    assert min(abs(s.wheel_velocity_rad_s) for s in rig.drive_sims) > 1.0


def test_interface_down_and_up_reopens_with_backoff_and_recovers(
    rig: Rig, vcan: str, caplog: pytest.LogCaptureFixture
) -> None:
    drive(rig, 0.4)
    ip("link", "set", vcan, "down")
    try:
        with caplog.at_level(logging.WARNING, logger="gateway.runtime.loop"):
            drive(rig, 3.0)
    finally:
        ip("link", "set", vcan, "up")
    counts = rig.gw.edge.counts
    assert counts.send_failures >= 250, counts  # every burst of 3 s at 100 Hz failed
    assert counts.receive_failures >= 1, counts  # counted apart from send failures
    assert 3 <= counts.bus_reopens <= 7, counts  # backoff: 0, 0.1, 0.3, 0.7, 1.5, ... s
    assert not rig.gw.edge.bus_healthy
    assert state(rig) is GatewayState.FAULT
    assert len(caplog.records) <= 8, [r.getMessage() for r in caplog.records]
    rig.advance(3.0)  # up again: the next reopen or burst goes through, the drives answer
    drive(rig, 1.0)
    assert rig.gw.edge.bus_healthy
    assert state(rig) is GatewayState.RUNNING, rig.gw.supervisor.reason
    assert min(abs(s.wheel_velocity_rad_s) for s in rig.drive_sims) > 1.0


def test_error_frames_are_counted_by_class_and_bus_off_is_a_fault(rig: Rig) -> None:
    drive(rig, 0.4)
    # The kernel delivers error frames to every raw socket that asked for them (python-can's
    # socketcan asks for all); vcan passes a local sender's on like any frame.
    rig.pilot.send(error_frame(0x020))  # no ACK
    rig.pilot.send(error_frame(0x004, bytes([0, 0x08, 0, 0, 0, 0, 0, 0])))  # tx warning
    drive(rig, 0.2)
    assert state(rig) is GatewayState.RUNNING
    assert rig.gw.edge.bus_errors.state is BusErrorState.WARNING
    rig.pilot.send(error_frame(0x040))
    rig.advance(0.05)
    sup = rig.gw.supervisor
    assert state(rig) is GatewayState.FAULT
    assert sup.fault_code is ErrorCode.BUS_ERROR
    assert "CAN bus-off on socketcan:" in sup.reason
    rig.advance(0.5)
    assert [s.model.target_rad_s for s in rig.drive_sims] == [0.0] * 4  # the zero went out
    rig.pilot.send(error_frame(0x100))  # restarted
    rig.advance(4.0)
    drive(rig, 0.6)
    assert state(rig) is GatewayState.RUNNING, sup.reason
    counts = rig.gw.edge.bus_errors.counts
    assert (counts["error_frames"], counts["no_ack"], counts["controller"], counts["bus_off"],
            counts["restarted"]) == (4, 1, 1, 1, 1)


def test_can_fd_frames_are_ignored_and_counted(rig: Rig, vcan: str) -> None:
    drive(rig, 0.2)
    for frame in ("02D##1" + "11" * 12, "100##0" + "00" * 64, "7A0##1" + "22" * 8):
        subprocess.run(["cansend", vcan, frame], check=True, timeout=30)
    drive(rig, 0.4)
    assert rig.gw.edge.counts.fd_frames_ignored >= 2  # 0x7A0 may be kept out by the filters
    assert rig.gw.counts.bad_can_twists == 0
    assert state(rig) is GatewayState.RUNNING


def test_kernel_filters_keep_foreign_traffic_out_of_the_process(rig: Rig, vcan: str) -> None:
    """The gateway's socket is opened with filters for exactly what it consumes: a flood of
    foreign frames never reaches it (the drain sees only its drives' feedback)."""
    assert rig.gw.receive_filters is not None
    before = rig.gw.edge.counts.frames_received
    flood = subprocess.Popen(["cangen", vcan, "-g", "0.2", "-I", "7A0", "-L", "8", "-n", "5000"])
    try:
        drive(rig, 1.0)
    finally:
        flood.wait(timeout=60)
    received = {(i, e) for (i, e, tx) in rig.gw.edge.id_counts if not tx}
    assert (0x7A0, False) not in received
    assert all(rig.gw.receive_filters and any(f.matches(i, e) for f in rig.gw.receive_filters)
               for i, e in received), received
    assert rig.gw.edge.counts.frames_received > before  # the drives' feedback still comes
    assert state(rig) is GatewayState.RUNNING


def test_another_program_commanding_our_motors_is_a_fault(rig: Rig, vcan: str) -> None:
    # The kernel's filters let another socket's Set_Input_Vel of node 1 in (our own frames are
    # never delivered back to our socket: the drive above ran without a fault).
    drive(rig, 0.6)
    assert state(rig) is GatewayState.RUNNING, rig.gw.supervisor.reason
    with can.Bus(interface="socketcan", channel=vcan) as other:
        other.send(can.Message(arbitration_id=1 << 5 | CmdId.SET_INPUT_VEL, data=bytes(8),
                               is_extended_id=False))
    rig.advance(0.1)
    assert state(rig) is GatewayState.FAULT
    assert rig.gw.supervisor.reason.startswith(f"another sender on socketcan:{vcan}: heard 02D#")


def test_a_second_gateway_started_beside_a_running_one_stops_neither(
        rig: Rig, vcan: str, sock_dir: Path) -> None:
    # A second daemon for the same robot on the same kernel bus (a `wheelgate run` by hand
    # beside the service), enabled at start: it listens, hears the running one's commands
    # through the kernel, withholds its enable and sends the motors nothing, not even a stop
    # when it shuts down.  The running one hears only its reports: it drives on.
    drive(rig, 0.6)
    faults = rig.gw.supervisor.counts.faults
    second = Daemon(rig.config, socket_path=str(sock_dir / "second.sock"),
                    notifier=SystemdNotifier(None))
    try:
        second.gateway.edge.stamp_with_cycle_time = True  # (the rig's simulated time)
        out = sent(second.gateway)
        second.gateway.supervisor.enable(rig.t)  # as gateway.enable_on_start
        for _ in range(5):
            rig.gw.twist(Twist(0.2), rig.t, Source.SOCKET)
            rig.advance(0.2, lambda r: second.step(r.t))
        reason = second.gateway.supervisor.reason
        assert second.gateway.state is GatewayState.FAULT
        assert reason.startswith(f"enable withheld: another sender on socketcan:{vcan}: heard "
                                 ), reason
        assert " Set_Input_Vel (" in reason, reason  # the running one's command, through the kernel
        assert state(rig) is GatewayState.RUNNING, rig.gw.supervisor.reason
        assert min(abs(s.wheel_velocity_rad_s) for s in rig.drive_sims) > 1.0
        assert rig.gw.commanders.heard > 0  # its WG_Status and odometry: a warning only
        second.shutdown(rig.t)
        assert second.left_to.startswith("another program commands them (another sender on ")
        assert set(out) <= reports(rig.gw)  # nothing to the motors, not even a stop
        drive(rig, 0.4)
        assert state(rig) is GatewayState.RUNNING, rig.gw.supervisor.reason
        assert rig.gw.supervisor.counts.faults == faults  # never disturbed
        assert min(abs(s.wheel_velocity_rad_s) for s in rig.drive_sims) > 1.0
    finally:
        second.close()
