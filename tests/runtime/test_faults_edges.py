"""Fault injection during a run, at the edges: a controller that sends garbage or drops frames, a
bus that refuses sends, socket clients that leave mid-line or connect by the thousand.

The matrix of faults, safe states, errors and recoveries is in :mod:`tests.runtime.fault_helpers`.
"""

from __future__ import annotations

import contextlib
import json
import os
import socket
from typing import TYPE_CHECKING

import can
import pytest
from can.interfaces.virtual import VirtualBus

from gateway.bus.edge import UNSENT_FAULT_CYCLES
from gateway.core.control import AUTO_RETRIES
from gateway.core.types import ErrorCode, GatewayState
from gateway.sim.device import SimFault
from tests.e2e_helpers import Rig, SocketPilot
from tests.runtime import fault_helpers
from tests.runtime.fault_helpers import (
    DRIVERS,
    RATE_HZ,
    Run,
    Sample,
    assert_safe_from,
    reaction_bound,
    victim_text,
)

if TYPE_CHECKING:
    from collections.abc import Iterator


pytestmark = pytest.mark.timeout(60)


# The shared fixtures (fault_helpers.py), bound here so that pytest finds them.
run = fault_helpers.run


#: Longest time from garbage to FAULT (s), as in ``test_soak.py``.
GARBAGE_BOUND_S = 0.5


# -- a controller sends garbage ---------------------------------------------------------------


@pytest.mark.parametrize("run", [pytest.param((d, {"feedback_recovery": "manual"}), id=d)
                                 for d in DRIVERS], indirect=True)
def test_garbage_faults_counts_rejects_and_recovers_on_enable(run: Run) -> None:
    before = run.rejected()
    t0 = run.inject(SimFault.GARBAGE)
    samples = run.drive(1.5)
    assert run.victim.garbage_sent > 100
    fault = next(s for s in samples if s.state is GatewayState.FAULT)
    # Not the liveness bound: a garbage frame of the right length can pass for fresh feedback.
    assert fault.t - t0 <= GARBAGE_BOUND_S
    assert_safe_from(samples, fault)
    assert run.rig.gw.supervisor.reason.startswith(victim_text(run))
    middle = run.rejected()
    assert middle > before
    run.pilot.send(op="status", id="st")
    run.drive(0.5)
    assert run.rejected() > middle  # every garbage frame of a wrong length is counted
    status = next(m for m in run.messages() if m.get("id") == "st")
    counters = status["counters"]
    assert isinstance(counters, dict)
    assert sum(counters["rejected_frames"][type(run.driver).__name__].values()) >= middle
    run.victim.clear(SimFault.GARBAGE)
    run.drive(0.3)  # a valid heartbeat first: the ODrive enable reads the axis state
    assert run.state is GatewayState.FAULT
    run.pilot.send(op="enable")
    run.until(GatewayState.RUNNING, within_s=1.5)
    run.drive(1.0)
    assert run.following()


@pytest.mark.parametrize("run", DRIVERS, indirect=True)
def test_garbage_with_automatic_recovery_never_raises_nor_moves_when_not_running(
    run: Run,
) -> None:
    run.inject(SimFault.GARBAGE)
    samples = run.drive(4.0)
    faults = run.rig.gw.supervisor.counts.faults
    assert faults >= 1
    assert any(s.state is GatewayState.FAULT for s in samples)
    for s in samples:
        if s.state is not GatewayState.RUNNING:
            assert all(v == 0.0 for v in s.speeds), s
    run.victim.clear(SimFault.GARBAGE)
    run.drive(0.3)
    if run.state is not GatewayState.RUNNING:
        run.pilot.send(op="enable")
    run.until(GatewayState.RUNNING, within_s=AUTO_RETRIES * 1.5)


@pytest.mark.parametrize("run", [
    pytest.param((d, {"feedback_recovery": "manual"}), id=d) for d in DRIVERS
], indirect=True)
def test_rejected_frame_counters_stay_bounded_under_garbage(run: Run) -> None:
    run.inject(SimFault.GARBAGE)
    run.drive(2.0)
    assert run.rejected() > 100
    assert len(run.driver.rejected) <= 32, sorted(run.driver.rejected)[:5]


# -- a controller drops frames ----------------------------------------------------------------


#: What a fault for dropped frames says: the stream that lost every frame is named, the one
#: that still comes too (the VESC's STATUS_5 goes out right after its STATUS; an ODrive's
#: heartbeat comes every 100 ms beside estimates every 10 ms).
DROPPED_STREAM = {"vesc": "sends its STATUS but no STATUS_5 (none for ",
                  "odrive": "sends its encoder estimates but no heartbeat (none for "}


@pytest.mark.parametrize("run", DRIVERS, indirect=True)
def test_dropped_frames(run: Run) -> None:
    t0 = run.inject(SimFault.DROP)
    samples = run.drive(2.0)
    for s in samples:
        if s.state is not GatewayState.RUNNING:
            assert all(v == 0.0 for v in s.speeds), s
        if s.state is GatewayState.FAULT:
            assert f"{victim_text(run)} {DROPPED_STREAM[run.key]}" in s.reason
    faults = [s for s in samples if s.state is GatewayState.FAULT]
    if run.key == "vesc":
        # Two status frames per period: every STATUS_5 is lost, so the tachometer is silent.
        assert faults and faults[0].t - t0 <= reaction_bound(run)
    elif run.key in ("dji", "cia402"):  # a frame every 1 or 10 ms: half of them is plenty
        assert not faults
        assert run.following()
    # ODrive: heartbeats come every 100 ms; two lost in a row (250 ms liveness) fault it.
    run.victim.clear(SimFault.DROP)
    run.until(GatewayState.RUNNING, within_s=1.5)
    run.drive(1.0)
    assert run.following()


# -- the bus refuses sends --------------------------------------------------------------------


@contextlib.contextmanager
def refusing_bus(rig: Rig, monkeypatch: pytest.MonkeyPatch) -> Iterator[dict[str, int]]:
    """Make the gateway's bus -- whichever object it is after reopens -- refuse every frame."""
    real = VirtualBus.send
    calls = {"refused": 0}

    def send(self: VirtualBus, msg: can.Message, timeout: float | None = None) -> None:
        if self is rig.gw.edge.bus:
            calls["refused"] += 1
            raise can.CanOperationError("Transmit buffer full")
        real(self, msg, timeout)

    with monkeypatch.context() as patch:
        patch.setattr(VirtualBus, "send", send)
        yield calls


@pytest.mark.parametrize("run", DRIVERS, indirect=True)
def test_bus_refusing_sends_loop_goes_on_drives_fall_back(
    run: Run, monkeypatch: pytest.MonkeyPatch
) -> None:
    gw = run.rig.gw
    cycles = gw.counts.cycles
    with refusing_bus(run.rig, monkeypatch) as calls:
        samples = run.drive(1.5)
    assert gw.counts.cycles == cycles + len(samples)  # the loop never stopped
    assert calls["refused"] >= len(samples)
    assert gw.edge.counts.send_failures >= len(samples)
    assert gw.edge.counts.bus_reopens >= 1
    truth = [abs(s.wheel_velocity_rad_s) for s in run.rig.drive_sims]
    # The commands stopped going out: a bus fault that names the first frame left out.
    fault = next(s for s in samples if s.state is GatewayState.FAULT)
    assert f"has not gone out for {UNSENT_FAULT_CYCLES} cycles" in fault.reason
    assert gw.supervisor.fault_code is ErrorCode.BUS_ERROR
    assert fault.t - samples[0].t <= (UNSENT_FAULT_CYCLES + 2) * run.rig.period
    assert all(v == 0.0 for s in samples if s.t >= fault.t for v in s.speeds)
    if run.key in ("odrive", "vesc", "cia402"):
        # Nothing reaches the controllers: their own timeouts stop the wheels (the ODrive axis
        # watchdog the gateway set, 0.25 s; the VESC's timeout_msec; the CiA 402 drives'
        # heartbeat consumer, which misses the gateway's heartbeat).
        assert max(truth) < 0.1
    else:
        # DJI has no command timeout: the gateway's zero cannot reach it, and it keeps
        # turning on the last command.
        assert min(truth) > 1.0
    run.until(GatewayState.RUNNING, within_s=2.0)
    run.drive(1.0)
    assert run.following()
    assert gw.edge.bus_healthy


@pytest.mark.parametrize("run", ["odrive"], indirect=True)
def test_bus_that_keeps_refusing_reads_unhealthy(run: Run, monkeypatch: pytest.MonkeyPatch
                                                 ) -> None:
    healthy = []
    with refusing_bus(run.rig, monkeypatch):
        for _ in range(100):
            run.drive(1.0 / RATE_HZ)
            healthy.append(run.rig.gw.edge.bus_healthy)
    assert run.rig.gw.edge.counts.bus_reopens >= 2
    assert not any(healthy[-50:])


# -- socket clients ---------------------------------------------------------------------------


def open_fds() -> set[str]:
    return set(os.listdir("/proc/self/fd"))


@pytest.mark.parametrize("run", ["odrive"], indirect=True)
def test_client_disconnecting_mid_message_is_dropped_and_the_loop_goes_on(
    run: Run, sock_path: str
) -> None:
    server = run.rig.daemon.server if run.rig.daemon else None
    assert server is not None
    run.streaming = False
    run.pilot.send(op="stop")
    run.drive(1.0)
    assert all(v == 0.0 for v in run.rig.gw.prev.wheel_rad_s)
    cycles = run.rig.gw.counts.cycles
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as half:
        half.connect(sock_path)
        half.sendall(b'{"op": "twist", "vx": 0.2, "wz": 0.')
        run.drive(0.05)
    samples = run.drive(0.5)
    assert server.counters.dropped_partial == 1
    assert run.rig.gw.counts.cycles == cycles + 5 + len(samples)
    # The half twist was never acted on.
    assert all(s.state is GatewayState.RUNNING for s in samples)
    assert all(v == 0.0 for s in samples for v in s.speeds)
    fresh = SocketPilot(sock_path)
    try:
        fresh.send(op="status", id=1)
        run.drive(0.02)
        (reply,) = fresh.messages()
        assert reply["ok"] is True and reply["state"] == "running"
    finally:
        fresh.close()
    run.streaming = True
    run.drive(1.0)
    assert run.following()


@pytest.mark.parametrize("run", ["odrive"], indirect=True)
def test_a_thousand_clients_at_once_while_running(run: Run, sock_path: str) -> None:
    server = run.rig.daemon.server if run.rig.daemon else None
    assert server is not None
    server.max_clients = 500  # the daemon's pilot holds one of them
    before = open_fds()
    cycles = run.rig.gw.counts.cycles
    storm: list[socket.socket] = []
    samples: list[Sample] = []
    try:
        for _ in range(1000):
            sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
            storm.append(sock)
            sock.setblocking(False)
            while True:
                try:
                    sock.connect(sock_path)
                    break
                except BlockingIOError:  # the backlog is full: let the loop accept
                    samples += run.drive(1.0 / RATE_HZ)
        for index, sock in enumerate(storm):
            with contextlib.suppress(BrokenPipeError, ConnectionResetError):
                sock.sendall(b'{"op":"status","id":%d}\n' % index)
        samples += run.drive(0.5)
        served = refused = 0
        for index, sock in enumerate(storm):
            try:
                data = sock.recv(1 << 20)
            except ConnectionResetError:
                data = b""
            except BlockingIOError:
                pytest.fail(f"client {index} got neither a reply nor end-of-file")
            if data:
                reply = json.loads(data.split(b"\n")[0])
                assert reply["ok"] is True and reply["id"] == index
                served += 1
            else:
                refused += 1
    finally:
        for sock in storm:
            sock.close()
    assert (served, refused) == (499, 501)
    assert server.counters.refused == 501
    # The loop cycled all along and kept following the twist.
    assert run.rig.gw.counts.cycles == cycles + len(samples)
    assert all(s.state is GatewayState.RUNNING for s in samples)
    assert not run.rig.gw.supervisor.cmd_timeout_active
    assert run.following()
    run.drive(0.1)  # the server notices the closed clients
    assert server.counters.clients == 1
    assert open_fds() == before
    fresh = SocketPilot(sock_path)
    try:
        fresh.send(op="status", id="fresh")
        run.drive(0.02)
        (reply,) = fresh.messages()
        assert reply["ok"] is True and reply["id"] == "fresh"
    finally:
        fresh.close()
