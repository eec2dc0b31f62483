"""Safety behaviours of the daemon around its commands, on simulated time with the device
simulators: command timeout, infeasible-twist policies, feedback timeout, motor faults, e-stop
and the CAN twist input.  SIGTERM and sd_notify are in ``test_daemon_process.py``; bus trouble
in ``test_safety_bus.py``."""

from __future__ import annotations

import itertools

import pytest

from gateway.bus.can_bus import drain
from gateway.core.control import AUTO_RETRIES
from gateway.core.settings import FeedbackRecovery
from gateway.core.types import ConstraintCode, ErrorCode, Frame, GatewayState, Twist
from gateway.sim.device import SimFault
from gateway.wire.can import TwistFlags
from tests.conftest import CONFIG_DIR
from tests.e2e_helpers import Rig, SocketPilot, errors_on_can
from tests.runtime import safety_helpers
from tests.runtime.safety_helpers import commanded, speeds, state

# The shared fixtures (safety_helpers.py), bound here so that pytest finds them.
rig = safety_helpers.rig
pilot = safety_helpers.pilot


MECANUM = CONFIG_DIR / "mecanum.yaml"


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


def test_a_stalled_cycle_does_not_step_the_wheels_past_the_acceleration_limit(
    rig: Rig, pilot: SocketPilot
) -> None:
    # The loop stalls 0.15 s (a GC pause, a slow disk; shorter than the controllers' own
    # timeout) while the controllers go on holding the last command: the first cycle after
    # it may not step the wheels by the acceleration of the whole stall.
    step = rig.config.limits.max_wheel_accel_rad_s2 * rig.period
    pilot.send(op="twist", vx=0.2)
    rig.advance(3 * rig.period)  # the ramp has begun
    before = commanded(rig)
    assert 0.0 < min(before) < 5.0
    end = rig.t + 0.15
    while rig.t < end:  # the loop stalled; the controllers not
        rig.ctl.step(rig.t)
        rig.t += rig.period / 2
    rig.advance(rig.period)
    after = commanded(rig)
    assert state(rig) is GatewayState.RUNNING
    assert all(0.0 < a - b <= 2 * step * (1 + 1e-6) for a, b in zip(after, before, strict=True)), (
        before, after, step)


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


@pytest.mark.parametrize("rig", [{"infeasible_policy": "project"}], indirect=True)
def test_a_projected_twist_ends_a_command_timeout(rig: Rig, pilot: SocketPilot) -> None:
    """A projected twist is followed: the command timeout it ends is no longer reported
    active, and the next one is counted."""
    pilot.send(op="twist", vx=0.1)
    rig.advance(1.0)  # cmd_timeout_s is 0.5
    assert rig.gw.supervisor.cmd_timeout_active
    for _ in range(10):
        pilot.send(op="twist", vx=0.1, vy=0.05)  # projected onto vx 0.1
        rig.advance(0.1)
    assert min(commanded(rig)) > 2.0
    assert not rig.gw.supervisor.cmd_timeout_active
    rig.advance(1.0)
    assert rig.gw.supervisor.counts.cmd_timeouts == 2


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


def test_a_can_twist_is_timed_from_its_arrival_not_from_the_cycle_that_reads_it(
        rig: Rig) -> None:
    """A twist frame that waited in the receive queue longer than cmd_timeout_s (0.5 s), as
    after a stalled loop, is stale when the cycle reads it: its receive time starts the command
    timeout, and no wheel is driven by it.  (The rig stamps frames with the cycle's time: the
    twist frames get their arrival 0.6 s earlier here.)"""
    receive, twist_id = rig.gw.edge.receive, rig.gw.wg.ids.twist

    def waited(now_s: float) -> list[Frame]:
        return [f._replace(timestamp_s=now_s - 0.6) if f.arbitration_id == twist_id else f
                for f in receive(now_s)]

    rig.gw.edge.receive = waited  # type: ignore[method-assign]
    rig.send_can_twist(Twist(0.2))
    rig.advance(0.3)
    assert rig.gw.counts.can_twists == 1
    assert rig.gw.supervisor.counts.cmd_timeouts == 1
    assert commanded(rig) == (0.0, 0.0)
    assert max(abs(s.wheel_velocity_rad_s) for s in rig.drive_sims) < 1e-9
    # The same twist read as it arrives drives the wheels.
    rig.gw.edge.receive = receive  # type: ignore[method-assign]
    rig.send_can_twist(Twist(0.2))
    rig.advance(0.3)
    assert min(speeds(rig)) > 5.0


def test_an_enable_soon_after_a_disable_ramps_from_zero(rig: Rig, pilot: SocketPilot) -> None:
    """A disable disarms the drives, which coast down on their own: an enable before the
    gateway's ramp would have come down must not command the speed of before the disable
    (it stepped to 4 rad/s in one cycle, ten times the acceleration limit's step)."""
    pilot.send(op="twist", vx=0.2, wz=0.0)
    rig.advance(0.4)
    assert min(commanded(rig)) > 5.0
    pilot.send(op="disable")
    rig.advance(2 * rig.period)  # (the ramp down would take 0.15 s)
    assert state(rig) is GatewayState.DISABLED
    pilot.send(op="enable")
    history: list[tuple[float, ...]] = []
    rig.advance(1.0, lambda r: history.append(commanded(r)))
    assert state(rig) is GatewayState.RUNNING
    assert max(abs(c) for cmd in history for c in cmd) == 0.0
