"""Safety behaviours of the daemon on bus trouble, on simulated time with the device simulators:
a full transmit queue, commands that do not go out, a bus that stays down, and one wheel's
first feedback arriving late."""

from __future__ import annotations

import errno
import logging
import time
from typing import TYPE_CHECKING

import can
import pytest
from can.interfaces.pcan.pcan import PcanCanOperationError
from can.interfaces.virtual import VirtualBus

from drivers.odrive.enums import CmdId
from gateway.bus.can_bus import drain
from gateway.bus.edge import UNSENT_FAULT_CYCLES
from gateway.core.types import ErrorCode, GatewayState
from gateway.sim.device import SimFault
from tests.e2e_helpers import Rig, SocketPilot, virtual_config
from tests.runtime import safety_helpers
from tests.runtime.safety_helpers import TB3, state

if TYPE_CHECKING:
    from collections.abc import Callable

# The shared fixtures (safety_helpers.py), bound here so that pytest finds them.
rig = safety_helpers.rig
pilot = safety_helpers.pilot


def no_buffer_space() -> can.CanError:
    """SocketCAN's full transmit queue (``ENOBUFS``)."""
    return can.CanOperationError("Failed to transmit: No buffer space available", errno.ENOBUFS)


#: How interfaces say that their transmit queue is full, as python-can raises it: SocketCAN's
#: errno, and text alone where the vendor library gives no errno (PCAN-Basic's
#: PCAN_ERROR_QXMTFULL and PCAN_ERROR_XMTFULL, worded as in its PCANBasic.h; python-can's
#: ``can/interfaces/pcan/pcan.py`` raises "Failed to send: " and the library's text).
FULL_QUEUE: dict[str, Callable[[], can.CanError]] = {
    "socketcan": no_buffer_space,
    "pcan queue": lambda: PcanCanOperationError("Failed to send: Transmit queue is full"),
    "pcan controller": lambda: PcanCanOperationError(
        "Failed to send: Transmit buffer in CAN controller is full"),
}


class BusPlan:
    """What the gateway's bus does, whichever bus object it holds after reopens: it takes
    ``room`` frames per cycle (``None``: any number) and refuses the rest with ``full()`` (by
    default SocketCAN's ``ENOBUFS``), or, while ``down``, refuses everything with
    ``ENETDOWN``.  Records what went out per cycle."""

    def __init__(self, rig: Rig, monkeypatch: pytest.MonkeyPatch,
                 full: Callable[[], can.CanError] = no_buffer_space) -> None:
        self.rig = rig
        self.room: int | None = None
        self.down = False
        self.left = 0
        #: The arbitration IDs that went out, per cycle.
        self.sent: list[list[int]] = [[]]
        real_send, real_recv = VirtualBus.send, VirtualBus._recv_internal

        def send(bus: VirtualBus, msg: can.Message, timeout: float | None = None) -> None:
            if bus is not rig.gw.edge.bus:
                real_send(bus, msg, timeout)
                return
            if self.down:
                raise can.CanOperationError("Failed to transmit: Network is down",
                                            errno.ENETDOWN)
            if self.room is not None:
                if self.left <= 0:
                    raise full()
                self.left -= 1
            real_send(bus, msg, timeout)
            self.sent[-1].append(msg.arbitration_id)

        def recv(bus: VirtualBus, timeout: float | None) -> tuple[can.Message | None, bool]:
            if bus is rig.gw.edge.bus and self.down:
                raise can.CanOperationError("Failed to receive: Network is down", errno.ENETDOWN)
            return real_recv(bus, timeout)

        monkeypatch.setattr(VirtualBus, "send", send)
        monkeypatch.setattr(VirtualBus, "_recv_internal", recv)

    def cycle(self, _: Rig) -> None:
        """Before each gateway cycle: the queue has drained ``room`` frames since the last."""
        self.left = self.room or 0
        self.sent.append([])


def test_a_full_transmit_queue_cuts_bursts_without_starving_a_wheel(
    rig: Rig, pilot: SocketPilot, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    pilot.send(op="twist", vx=0.1)
    rig.advance(0.2)
    plan = BusPlan(rig, monkeypatch)
    commands = {(m.node_id << 5) | CmdId.SET_INPUT_VEL for m in rig.config.motors if m}
    plan.room = 1  # one frame per cycle: the burst of two wheel commands never fits

    def each(r: Rig) -> None:
        plan.cycle(r)
        if len(plan.sent) % 20 == 0:
            pilot.send(op="twist", vx=0.1)  # within the command timeout

    with caplog.at_level(logging.WARNING, logger="gateway.runtime.loop"):
        rig.advance(2.0, each)
    # What reached the bus: every wheel's command goes out every other cycle (the frame left
    # out goes first next time); without that, one wheel would never be commanded again.
    went = [ids for ids in plan.sent if ids]
    assert len(went) >= 150
    for can_id in commands:
        assert sum(can_id in ids for ids in went) >= 0.45 * len(went)
    assert max(rig.gw.edge.bursts.missed.values(), default=0) < UNSENT_FAULT_CYCLES
    assert rig.gw.edge.counts.partial_bursts >= 150
    assert rig.gw.edge.counts.frames_unsent >= 150
    assert state(rig) is GatewayState.RUNNING
    assert min(abs(s.wheel_velocity_rad_s) for s in rig.sims) > 1.0
    # Two seconds of cut bursts at 100 Hz: one log line per five seconds, not one per burst.
    assert len([r for r in caplog.records if "send failed" in r.getMessage()]) == 1
    # Room that comes back within the cycle's budget is waited for: nothing left out.
    plan.room = None
    real_send = VirtualBus.send
    free_at = [0.0]

    def slow(bus: VirtualBus, msg: can.Message, timeout: float | None = None) -> None:
        if bus is rig.gw.edge.bus and time.perf_counter() < free_at[0]:
            raise no_buffer_space()
        real_send(bus, msg, timeout)

    monkeypatch.setattr(VirtualBus, "send", slow)
    unsent, waits = rig.gw.edge.counts.frames_unsent, rig.gw.edge.counts.send_waits

    def busy(r: Rig) -> None:
        free_at[0] = time.perf_counter() + 0.1 * r.period  # drains within a tenth of a period

    rig.advance(0.2, busy)
    assert rig.gw.edge.counts.send_waits > waits
    assert rig.gw.edge.counts.frames_unsent == unsent
    assert state(rig) is GatewayState.RUNNING


@pytest.mark.parametrize("interface", FULL_QUEUE)
def test_commands_that_do_not_go_out_are_a_fault_naming_the_wheel(
    rig: Rig, pilot: SocketPilot, monkeypatch: pytest.MonkeyPatch, interface: str
) -> None:
    pilot.send(op="twist", vx=0.1)
    rig.advance(0.2)
    plan = BusPlan(rig, monkeypatch, FULL_QUEUE[interface])
    plan.room = 0  # the queue stays full: nothing goes out
    rig.advance((UNSENT_FAULT_CYCLES - 1) * rig.period, plan.cycle)
    assert state(rig) is GatewayState.RUNNING  # a few late commands are not a fault yet
    rig.advance(2 * rig.period, plan.cycle)
    assert state(rig) is GatewayState.FAULT
    sup = rig.gw.supervisor
    assert sup.fault_code is ErrorCode.BUS_ERROR
    first = next(m for m in rig.config.motors if m is not None)
    assert sup.faulted == (first.wheel,)
    assert f"Set_Input_Vel ({first.wheel})" in sup.reason
    assert f"has not gone out for {UNSENT_FAULT_CYCLES} cycles" in sup.reason
    assert "the CAN transmit queue stays full" in sup.reason
    plan.room = None  # room again: the fault and the zero reach the bus
    rig.advance(0.2, plan.cycle)
    states = [r.state for r in map(rig.gw.wg.decode_status, drain(rig.pilot)) if r is not None]
    assert GatewayState.FAULT in states
    commanded = [s.model.target_rad_s for s in rig.drive_sims]
    assert commanded == [0.0] * len(commanded)


def test_a_bus_that_stays_down_is_reopened_with_backoff_and_recovers(
    rig: Rig, pilot: SocketPilot, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    pilot.send(op="twist", vx=0.1)
    rig.advance(0.2)
    plan = BusPlan(rig, monkeypatch)
    plan.down = True
    first = rig.gw.edge.bus
    with caplog.at_level(logging.WARNING, logger="gateway.runtime.loop"):
        rig.advance(3.0, plan.cycle)
    assert not any(plan.sent)  # nothing went out, whichever bus object the gateway held
    assert rig.gw.edge.bus is not first  # reopened ...
    # ... with backoff: at 0, 0.1, 0.3, 0.7, 1.5 and 3.1 s, not once per failed burst.
    assert 4 <= rig.gw.edge.counts.bus_reopens <= 6
    assert rig.gw.edge.counts.send_failures >= 250
    assert rig.gw.edge.counts.receive_failures >= 250
    assert not rig.gw.edge.bus_healthy
    assert state(rig) is GatewayState.FAULT
    # Said as it is: the interface is down, not a transmit queue that stays full.
    channel = rig.config.bus.channel
    assert rig.gw.supervisor.reason.endswith(
        f"sending fails (Failed to transmit: Network is down [Error Code 100]): check that "
        f"the virtual interface {channel} is connected")  # (socketcan: ip link show)
    # One line per kind of trouble per five seconds (send, receive, reopen, the fault).
    assert len(caplog.records) <= 6, [r.getMessage() for r in caplog.records]
    plan.down = False
    rig.advance(3.0, plan.cycle)  # the next reopen or send finds the bus back
    assert rig.gw.edge.bus_healthy
    assert state(rig) is GatewayState.RUNNING
    pilot.send(op="twist", vx=0.1)
    rig.advance(0.5, plan.cycle)
    assert min(abs(s.wheel_velocity_rad_s) for s in rig.drive_sims) > 1.0


def test_first_feedback_of_one_wheel_arriving_late_does_not_break_the_loop(
    channel: str,
) -> None:
    cfg = virtual_config(TB3, channel, rate_hz=100.0)
    with Rig(cfg) as rig:
        right = next(s for s in rig.sims if s.motor.wheel == "right")
        right.inject(SimFault.SILENT)
        rig.gw.supervisor.enable(rig.t)
        rig.advance(0.3)  # left reports, right does not: odometry waits, nothing raises
        assert rig.gw.counts.odometry_errors == 0
        right.clear(SimFault.SILENT)
        rig.advance(1.0)
        rig.gw.supervisor.enable(rig.t)
        rig.advance(1.0)
        assert state(rig) is GatewayState.RUNNING
