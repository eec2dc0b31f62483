"""Every safety behaviour of the daemon, on simulated time with the device simulators.

Command timeout, infeasible-twist policies, feedback timeout, motor faults, bus trouble and
e-stop; SIGTERM and sd_notify are in ``test_daemon_process.py``.
"""

from __future__ import annotations

import errno
import itertools
import logging
import time
from typing import TYPE_CHECKING

import can
import pytest
from can.interfaces.virtual import VirtualBus

from drivers.odrive.enums import CmdId
from gateway.bus.can_bus import drain
from gateway.bus.edge import UNSENT_FAULT_CYCLES
from gateway.core.control import AUTO_RETRIES
from gateway.core.settings import FeedbackRecovery
from gateway.core.types import ConstraintCode, ErrorCode, GatewayState, Twist
from gateway.sim.device import SimFault
from gateway.wire.can import TwistFlags
from tests.conftest import CONFIG_DIR
from tests.e2e_helpers import Rig, SocketPilot, errors_on_can, virtual_config

if TYPE_CHECKING:
    from collections.abc import Iterator

TB3 = CONFIG_DIR / "turtlebot3_burger.yaml"
MECANUM = CONFIG_DIR / "mecanum.yaml"


@pytest.fixture
def rig(channel: str, sock_path: str, request: pytest.FixtureRequest) -> Iterator[Rig]:
    loop = getattr(request, "param", {})
    cfg = virtual_config(TB3, channel, rate_hz=100.0, **loop)
    with Rig(cfg, sock_path) as r:
        r.enable()
        yield r


@pytest.fixture
def pilot(rig: Rig, sock_path: str) -> Iterator[SocketPilot]:
    p = SocketPilot(sock_path)
    yield p
    p.close()


def state(rig: Rig) -> GatewayState:
    """The gateway state, read through a call so mypy does not narrow it across cycles."""
    return rig.gw.state


def speeds(rig: Rig) -> tuple[float, ...]:
    return rig.gw.prev.wheel_rad_s


def commanded(rig: Rig) -> tuple[float, ...]:
    """The wheel speeds the simulated controllers were last commanded: what reached them."""
    return tuple(s.motor.motor_to_wheel_rad_s(s.model.target_rad_s) for s in rig.drive_sims)


def test_command_timeout_ramps_to_zero_within_deceleration(rig: Rig, pilot: SocketPilot) -> None:
    pilot.send(op="twist", vx=0.2, wz=0.0)
    rig.advance(0.45)  # cmd_timeout_s is 0.5
    assert min(commanded(rig)) > 5.0
    assert min(abs(s.wheel_velocity_rad_s) for s in rig.drive_sims) > 5.0
    assert not rig.gw.supervisor.cmd_timeout_active
    history = [commanded(rig)]
    rig.advance(1.5, lambda r: history.append(commanded(r)))
    history.append(commanded(rig))
    assert rig.gw.supervisor.cmd_timeout_active
    # What the controllers were told: down to zero, never faster than the deceleration limit
    # (one cycle's step), and the wheels followed.
    assert history[-1] == (0.0, 0.0)
    step = rig.config.limits.max_wheel_accel_rad_s2 * rig.period
    for before, after in itertools.pairwise(history):  # float32 on the wire: 1e-6 relative
        assert all(abs(a - b) <= step * (1 + 1e-6) for a, b in zip(after, before, strict=True)), (
            before, after, step)
    assert sum(1 for before, after in itertools.pairwise(history) if after != before) >= 5
    assert max(abs(s.wheel_velocity_rad_s) for s in rig.drive_sims) < 0.1
    assert rig.gw.supervisor.counts.cmd_timeouts == 1


@pytest.mark.parametrize("rig", [{"cmd_timeout_s": 0.0}], indirect=True)
def test_zero_command_timeout_keeps_the_last_twist(rig: Rig, pilot: SocketPilot) -> None:
    pilot.send(op="twist", vx=0.2)
    rig.advance(3.0)
    assert min(speeds(rig)) > 5.0
    assert not rig.gw.supervisor.cmd_timeout_active


def test_infeasible_twist_rejected_on_socket_and_can(rig: Rig, pilot: SocketPilot) -> None:
    pilot.send(op="twist", vx=0.2, id=1)
    rig.advance(0.3)
    pilot.send(op="twist", vx=0.2, vy=0.1, id=2)
    rig.advance(0.01)
    reply = next(m for m in pilot.messages() if m.get("id") == 2)
    assert reply["ok"] is False
    error = reply["error"]
    assert isinstance(error, dict)
    assert error["code"] == "infeasible_twist"
    assert error["constraint"] == "sliding"
    assert error["wheel"] in ("left", "right")
    assert error["residual_m_s"] == pytest.approx(0.1)
    assert error["nearest"] == {"vx_m_s": pytest.approx(0.2),
                                "vy_m_s": pytest.approx(0.0, abs=1e-9),
                                "wz_rad_s": pytest.approx(0.0, abs=1e-9)}
    reports = errors_on_can(rig)
    assert reports and reports[-1].code is ErrorCode.INFEASIBLE_TWIST
    assert reports[-1].constraint is ConstraintCode.SLIDING
    # The robot ramps to zero.
    rig.advance(1.0)
    assert speeds(rig) == (0.0, 0.0)
    # The same from a CAN twist frame: the WG_Error carries the frame's counter.
    rig.send_can_twist(Twist(0.2, 0.1, 0.0))
    counter = (rig.counter - 1) & 0xFF
    rig.advance(0.02)
    reports = errors_on_can(rig)
    assert reports[-1].code is ErrorCode.INFEASIBLE_TWIST
    assert reports[-1].twist_counter == counter
    assert rig.gw.supervisor.counts.infeasible == 2


@pytest.mark.parametrize("rig", [{"infeasible_policy": "project"}], indirect=True)
def test_infeasible_twist_projected(rig: Rig, pilot: SocketPilot) -> None:
    pilot.send(op="twist", vx=0.15, vy=0.1, id=7)
    rig.advance(0.4)  # within the command timeout
    reply = next(m for m in pilot.messages() if m.get("id") == 7)
    assert reply["ok"] is True and reply["projected"] is True
    assert "sliding" in str(reply["warning"])
    assert rig.gw.prev.twist.vx_m_s == pytest.approx(0.15)
    assert rig.gw.supervisor.counts.projected == 1


@pytest.mark.parametrize("rig", [{}, {"feedback_recovery": "manual"}], indirect=True)
def test_feedback_timeout_faults_names_motor_and_recovers(rig: Rig, pilot: SocketPilot) -> None:
    pilot.send(op="subscribe", topics=["error"])
    pilot.send(op="twist", vx=0.2)
    rig.advance(0.3)
    right = next(s for s in rig.sims if s.motor.wheel == "right")
    right.inject(SimFault.SILENT)
    rig.advance(0.5)
    assert state(rig) is GatewayState.FAULT
    assert "motor 'right' (node 2) stopped answering" in rig.gw.supervisor.reason
    assert speeds(rig) == (0.0, 0.0)  # every wheel commanded to zero at once
    events = [m for m in pilot.messages() if m.get("event") == "error"]
    assert events and "motor 'right'" in str(events[-1]["message"])
    assert errors_on_can(rig)[-1].code is ErrorCode.FEEDBACK_TIMEOUT
    pilot.send(op="twist", vx=0.2, id=9)
    rig.advance(0.02)
    refused = next(m for m in pilot.messages() if m.get("id") == 9)
    assert refused["ok"] is False
    right.clear(SimFault.SILENT)
    rig.advance(1.0)
    if rig.config.loop.feedback_recovery is FeedbackRecovery.AUTO:
        assert state(rig) is GatewayState.RUNNING
    else:
        assert state(rig) is GatewayState.FAULT
        pilot.send(op="enable")
        rig.advance(1.0)
        assert state(rig) is GatewayState.RUNNING


def test_motor_fault_zeroes_retries_then_waits_for_enable(rig: Rig, pilot: SocketPilot) -> None:
    pilot.send(op="twist", vx=0.2)
    rig.advance(0.3)
    left = next(s for s in rig.sims if s.motor.wheel == "left")
    left.inject(SimFault.FAULT)
    rig.advance(0.3)
    assert state(rig) is GatewayState.FAULT
    assert "motor 'left' (node 1) reports a fault: axis error" in rig.gw.supervisor.reason
    assert speeds(rig) == (0.0, 0.0)
    assert errors_on_can(rig)[-1].code is ErrorCode.MOTOR_FAULT
    # The fault persists: the automatic re-enables (which clear the ODrive's error) fail,
    # and after AUTO_RETRIES the gateway waits for an explicit enable (each attempt may take
    # up to enable_timeout_s, 5 s).
    rig.advance(25.0)
    assert state(rig) is GatewayState.FAULT
    assert rig.gw.supervisor.counts.faults == 1 + AUTO_RETRIES
    left.clear(SimFault.FAULT)
    rig.advance(2.0)
    assert state(rig) is GatewayState.FAULT
    pilot.send(op="enable")
    rig.advance(1.5)
    assert state(rig) is GatewayState.RUNNING


def test_transient_motor_fault_recovers_automatically(rig: Rig) -> None:
    left = next(s for s in rig.sims if s.motor.wheel == "left")
    left.inject(SimFault.FAULT)
    rig.advance(0.1)
    assert state(rig) is GatewayState.FAULT
    left.clear(SimFault.FAULT)
    rig.advance(2.0)
    assert state(rig) is GatewayState.RUNNING


def test_estop_from_socket_and_can_zeroes_at_once_and_latches(rig: Rig, pilot: SocketPilot
                                                             ) -> None:
    for source in ("socket", "can"):
        pilot.send(op="twist", vx=0.2)
        rig.advance(0.5)
        assert min(speeds(rig)) > 5.0
        drain(rig.pilot)
        if source == "socket":
            pilot.send(op="estop")
        else:
            rig.send_can_twist(Twist(), TwistFlags.ESTOP)
        rig.advance(rig.period)
        assert state(rig) is GatewayState.ESTOP
        assert speeds(rig) == (0.0, 0.0)  # no ramp
        sent = drain(rig.pilot)
        # ODrive disarm: Set_Axis_State IDLE (0x07 with state 1) to both nodes.
        idle = {f.arbitration_id for f in sent if f.arbitration_id & 0x1F == 0x07
                and f.data[:4] == b"\x01\x00\x00\x00"}
        assert idle == {0x027, 0x047}
        pilot.send(op="twist", vx=0.2, id=source)
        rig.advance(0.3)
        refused = next(m for m in pilot.messages() if m.get("id") == source)
        assert refused["ok"] is False
        assert refused["error"]["code"] == "estop"  # type: ignore[index]
        assert state(rig) is GatewayState.ESTOP
        pilot.send(op="enable")
        rig.advance(1.0)
        assert state(rig) is GatewayState.RUNNING
    assert rig.gw.supervisor.counts.estops == 2


def test_repeated_can_frame_is_ignored_but_never_an_estop(rig: Rig) -> None:
    rig.send_can_twist(Twist(0.2))
    rig.advance(0.3)
    assert min(speeds(rig)) > 5.0
    rig.counter -= 1  # the same counter again: a repeated frame
    rig.send_can_twist(Twist(-0.2))
    rig.advance(0.1)
    assert rig.gw.counts.can_duplicates == 1
    assert min(speeds(rig)) > 5.0  # the repeat did not command anything
    rig.counter -= 1
    rig.send_can_twist(Twist(), TwistFlags.ESTOP)
    rig.advance(rig.period)
    assert state(rig) is GatewayState.ESTOP
    assert rig.gw.counts.can_duplicates == 2


def test_can_sender_restarting_after_the_command_timeout_is_followed(rig: Rig) -> None:
    rig.send_can_twist(Twist(0.2))  # counter 0
    rig.advance(0.3)
    assert min(speeds(rig)) > 5.0
    rig.advance(1.0)  # silent past cmd_timeout_s (0.5): ramped to zero
    assert speeds(rig) == (0.0, 0.0)
    rig.counter = 0  # restarted: its sequence begins where the old one stopped
    rig.send_can_twist(Twist(0.2))
    rig.advance(0.3)
    assert rig.gw.counts.can_duplicates == 0
    assert min(speeds(rig)) > 5.0


class BusPlan:
    """What the gateway's bus does, whichever bus object it holds after reopens: it takes
    ``room`` frames per cycle (``None``: any number) and refuses the rest with ``ENOBUFS``, or,
    while ``down``, refuses everything with ``ENETDOWN``.  Records what went out per cycle."""

    def __init__(self, rig: Rig, monkeypatch: pytest.MonkeyPatch) -> None:
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
                    raise can.CanOperationError("Failed to transmit: No buffer space available",
                                                errno.ENOBUFS)
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
            raise can.CanOperationError("Failed to transmit: No buffer space available",
                                        errno.ENOBUFS)
        real_send(bus, msg, timeout)

    monkeypatch.setattr(VirtualBus, "send", slow)
    unsent, waits = rig.gw.edge.counts.frames_unsent, rig.gw.edge.counts.send_waits

    def busy(r: Rig) -> None:
        free_at[0] = time.perf_counter() + 0.1 * r.period  # drains within a tenth of a period

    rig.advance(0.2, busy)
    assert rig.gw.edge.counts.send_waits > waits
    assert rig.gw.edge.counts.frames_unsent == unsent
    assert state(rig) is GatewayState.RUNNING


def test_commands_that_do_not_go_out_are_a_fault_naming_the_wheel(
    rig: Rig, pilot: SocketPilot, monkeypatch: pytest.MonkeyPatch
) -> None:
    pilot.send(op="twist", vx=0.1)
    rig.advance(0.2)
    plan = BusPlan(rig, monkeypatch)
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
