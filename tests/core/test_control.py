"""The supervisor's state machine, on simulated time."""

from __future__ import annotations

import ast
import dataclasses
from pathlib import Path
from typing import TYPE_CHECKING

import pytest

import gateway
from gateway.core import control
from gateway.core.control import (
    AUTO_RETRIES,
    AUTO_RETRY_DELAY_S,
    AUTO_RETRY_RESET_S,
    Accepted,
    Fault,
    Rejection,
    StatusBoard,
    Supervisor,
)
from gateway.core.errors import IllegalTransitionError
from gateway.core.kinematics import PRESETS, RobotModel
from gateway.core.settings import LoopConfig
from gateway.core.supervision import motor_fault_text
from gateway.core.transitions import IGNORED, TRANSITIONS, Event, next_state
from gateway.core.types import (
    DriveFault,
    DriveState,
    ErrorCode,
    GatewayState,
    MotorStatus,
    Twist,
    WheelFeedback,
)

if TYPE_CHECKING:
    from collections.abc import Callable

MODEL = RobotModel(PRESETS["differential"].wheels(wheel_radius=0.05, track=0.3))


def motors(*states: DriveState, age: float | None = 0.01) -> StatusBoard:
    return StatusBoard([
        MotorStatus(name, i + 1, st, DriveFault.MOTOR if st is DriveState.FAULT else
                    DriveFault.NONE, "phase loss" if st is DriveState.FAULT else "", age, None)
        for i, (name, st) in enumerate(zip(("left", "right"), states, strict=False))
    ])


def state_of(sup: Supervisor) -> GatewayState:
    """The state, read through a call so mypy does not narrow it across transitions."""
    return sup.state


def running(**cfg: object) -> Supervisor:
    sup = Supervisor(MODEL, dataclasses.replace(LoopConfig(), **cfg))  # type: ignore[arg-type]
    sup.enable(0.0)
    assert sup.take_enable_request()
    assert not sup.take_enable_request()
    sup.motors(motors(DriveState.ENABLED, DriveState.ENABLED), 0.1)
    assert state_of(sup) is GatewayState.RUNNING
    return sup


def test_twist_is_followed_until_the_command_timeout() -> None:
    sup = running(cmd_timeout_s=0.5)
    assert isinstance(sup.twist(Twist(0.3, 0.0, 0.1), 1.0), Accepted)
    d = sup.decide(1.4)
    assert (d.twist, d.ramp, d.armed, d.cmd_timeout) == (Twist(0.3, 0.0, 0.1), True, True, False)
    d = sup.decide(1.51)
    assert d.twist == Twist() and d.ramp and d.cmd_timeout
    assert sup.counts.cmd_timeouts == 1
    assert isinstance(sup.twist(Twist(0.1, 0.0, 0.0), 2.0), Accepted)
    assert sup.decide(2.1).twist == Twist(0.1, 0.0, 0.0)


def test_zero_timeout_disables_it() -> None:
    sup = running(cmd_timeout_s=0.0)
    sup.twist(Twist(0.3, 0.0, 0.0), 1.0)
    assert sup.decide(1000.0).twist == Twist(0.3, 0.0, 0.0)


def test_infeasible_reject_ramps_to_zero() -> None:
    sup = running()
    sup.twist(Twist(0.3, 0.0, 0.0), 1.0)
    result = sup.twist(Twist(0.3, 0.2, 0.0), 1.1)
    assert isinstance(result, Rejection)
    assert result.code is ErrorCode.INFEASIBLE_TWIST
    assert result.error is not None and result.error.constraint == "sliding"
    assert sup.decide(1.1).twist == Twist() and sup.decide(1.1).ramp
    assert sup.counts.infeasible == 1


def test_infeasible_project_follows_nearest() -> None:
    sup = running(infeasible_policy="project")
    result = sup.twist(Twist(0.3, 0.2, 0.0), 1.0)
    assert isinstance(result, Accepted) and result.projected
    assert result.twist.vx_m_s == pytest.approx(0.3)
    assert abs(result.twist.vy_m_s) < 1e-12
    assert sup.counts.projected == 1


def test_motor_fault_zeroes_names_motor_and_recovers_automatically() -> None:
    sup = running()
    sup.twist(Twist(0.3, 0.0, 0.0), 1.0)
    msg = sup.motors(motors(DriveState.ENABLED, DriveState.OFFLINE, age=0.4), 1.1)
    assert msg == Fault(ErrorCode.FEEDBACK_TIMEOUT,
                        "motor 'right' (node 2) stopped answering (no feedback for 0.400 s)")
    assert state_of(sup) is GatewayState.FAULT
    d = sup.decide(1.1)
    assert d.twist == Twist() and not d.ramp and d.armed
    assert isinstance(sup.twist(Twist(0.1, 0.0, 0.0), 1.2), Rejection)
    sup.motors(motors(DriveState.ENABLED, DriveState.DISABLED), 1.3)  # feedback is back
    assert state_of(sup) is GatewayState.FAULT  # waits AUTO_RETRY_DELAY_S first
    sup.motors(motors(DriveState.ENABLED, DriveState.DISABLED), 1.1 + AUTO_RETRY_DELAY_S)
    assert state_of(sup) is GatewayState.ENABLING
    assert sup.take_enable_request()
    sup.motors(motors(DriveState.ENABLED, DriveState.ENABLED), 1.8)
    assert state_of(sup) is GatewayState.RUNNING


def test_manual_recovery_waits_for_enable_and_disarm_action() -> None:
    sup = running(feedback_recovery="manual", fault_action="disarm")
    msg = sup.motors(motors(DriveState.FAULT, DriveState.ENABLED), 1.0)
    assert msg == Fault(ErrorCode.MOTOR_FAULT, "motor 'left' (node 1) reports a fault: phase loss")
    assert not sup.decide(1.0).armed
    sup.motors(motors(DriveState.DISABLED, DriveState.DISABLED), 1.1)
    assert state_of(sup) is GatewayState.FAULT
    sup.enable(1.2)
    assert state_of(sup) is GatewayState.ENABLING


def test_estop_latches_until_enable() -> None:
    sup = running()
    sup.twist(Twist(0.3, 0.0, 0.0), 1.0)
    sup.estop()
    d = sup.decide(1.0)
    assert (d.twist, d.ramp, d.armed) == (Twist(), False, False)
    refused = sup.twist(Twist(0.1, 0.0, 0.0), 1.1)
    assert isinstance(refused, Rejection) and refused.code is ErrorCode.ESTOP
    sup.motors(motors(DriveState.DISABLED, DriveState.DISABLED), 1.2)
    assert state_of(sup) is GatewayState.ESTOP  # no automatic way out
    sup.enable(1.3)
    assert state_of(sup) is GatewayState.ENABLING


def test_enable_timeout_faults_with_the_late_motor() -> None:
    sup = Supervisor(MODEL, dataclasses.replace(LoopConfig(), enable_timeout_s=1.0))
    sup.enable(0.0)
    assert sup.motors(motors(DriveState.ENABLED, DriveState.ENABLING), 0.5) is None
    msg = sup.motors(motors(DriveState.ENABLED, DriveState.ENABLING), 1.5)
    assert msg == Fault(ErrorCode.MOTOR_FAULT, "motor 'right' (node 2) did not enable within 1 s")
    assert state_of(sup) is GatewayState.FAULT


@pytest.mark.parametrize(("late", "says"), [
    (DriveState.FAULT, ", and it reports a fault: phase loss"),
    (DriveState.OFFLINE, ", and it has not answered (no feedback yet)"),
])
def test_enable_timeout_says_what_the_late_motor_reports(late: DriveState, says: str) -> None:
    """An enable sequence that failed on the way (a CiA 402 SDO that got no answer, say) leaves
    the motor in FAULT with the cause in its detail until the enable times out: the timeout's
    message carries that cause, not only the time."""
    sup = Supervisor(MODEL, dataclasses.replace(LoopConfig(), enable_timeout_s=1.0))
    sup.enable(0.0)
    msg = sup.motors(motors(DriveState.ENABLED, late, age=None), 1.5)
    assert msg == Fault(ErrorCode.MOTOR_FAULT,
                        f"motor 'right' (node 2) did not enable within 1 s{says}")


@dataclasses.dataclass(frozen=True)
class _FailedBoard(StatusBoard):
    """A board whose motors ``failed`` ended their enable sequence without arming."""

    failed: tuple[int, ...] = ()

    def enable_failed(self) -> list[int]:
        return list(self.failed)


def test_a_failed_enable_sequence_faults_at_once_with_its_cause() -> None:
    """A motor whose enable sequence has ended without arming it (a CiA 402 step that got no
    answer) is a fault at once, with the cause it reports, not after ``enable_timeout_s``; but
    not in the cycle that takes the enable request, before the drives have restarted their
    sequences (the last enable's failure would be seen)."""
    sup = Supervisor(MODEL, dataclasses.replace(LoopConfig(), enable_timeout_s=5.0))
    failed = _FailedBoard(motors(DriveState.ENABLED, DriveState.FAULT).statuses, (1,))
    sup.enable(0.0)
    assert sup.motors(failed, 0.01) is None  # the enable request not taken yet
    assert sup.take_enable_request()
    assert sup.motors(_FailedBoard(failed.statuses), 0.02) is None
    msg = sup.motors(failed, 0.5)
    assert msg == Fault(ErrorCode.MOTOR_FAULT, "motor 'right' (node 2) failed its enable "
                                               "sequence, and it reports a fault: phase loss")
    assert state_of(sup) is GatewayState.FAULT


def test_disabled_and_stop() -> None:
    sup = Supervisor(MODEL, LoopConfig())
    refused = sup.twist(Twist(0.1, 0.0, 0.0), 0.0)
    assert isinstance(refused, Rejection) and refused.code is ErrorCode.NOT_ENABLED
    sup = running()
    sup.twist(Twist(0.3, 0.0, 0.0), 1.0)
    sup.stop(1.1)
    assert sup.decide(1.1).twist == Twist() and sup.decide(1.1).armed
    sup.disable()
    assert not sup.decide(1.2).armed and state_of(sup) is GatewayState.DISABLED


@pytest.mark.parametrize(("host_loop", "state", "released"), [
    (True, DriveState.OFFLINE, True),  # a host-side loop on missing feedback: release
    (True, DriveState.FAULT, False),  # a fault code: the feedback is fine, hold zero
    (False, DriveState.OFFLINE, False),  # the drive's own loop holds zero
])
def test_fault_releases_host_side_speed_loops_when_feedback_is_in_doubt(
        host_loop: bool, state: DriveState, released: bool) -> None:
    sup = Supervisor(MODEL, LoopConfig(), host_speed_loop=host_loop)
    sup.enable(0.0)
    assert sup.take_enable_request()
    sup.motors(motors(DriveState.ENABLED, DriveState.ENABLED), 0.1)
    assert sup.motors(motors(DriveState.ENABLED, state, age=0.4), 1.0) is not None
    d = sup.decide(1.0)
    assert d.twist == Twist() and not d.ramp
    assert d.armed is not released


def recover(sup: Supervisor, now_s: float) -> float:
    """Feed healthy motors until the automatic re-enable reaches RUNNING; the time then."""
    t = now_s
    while state_of(sup) is GatewayState.FAULT and t < now_s + 10.0:
        t += 0.05
        sup.motors(motors(DriveState.DISABLED, DriveState.DISABLED), t)
    if state_of(sup) is GatewayState.ENABLING:
        assert sup.take_enable_request()  # (the loop sends the drives' enable frames)
        sup.motors(motors(DriveState.ENABLED, DriveState.ENABLED), t)
    return t


@pytest.mark.parametrize(("running_s", "recoveries"), [
    (1.0, AUTO_RETRIES),  # the fault comes back soon after each recovery: 3 tries, then wait
    (AUTO_RETRY_RESET_S, 6),  # RUNNING long enough in between: every fault is retried
])
def test_automatic_recovery_is_bounded_unless_running_holds_in_between(
        running_s: float, recoveries: int) -> None:
    sup = running()
    t = 1.0
    for _ in range(recoveries):
        assert sup.motors(motors(DriveState.FAULT, DriveState.ENABLED), t) is not None
        t = recover(sup, t)
        assert state_of(sup) is GatewayState.RUNNING
        t += running_s
        sup.motors(motors(DriveState.ENABLED, DriveState.ENABLED), t)
    assert sup.motors(motors(DriveState.FAULT, DriveState.ENABLED), t) is not None
    t = recover(sup, t)
    if recoveries == AUTO_RETRIES:
        assert state_of(sup) is GatewayState.FAULT  # waits for an explicit enable
        sup.enable(t)
        assert state_of(sup) is GatewayState.ENABLING
    else:
        assert state_of(sup) is GatewayState.RUNNING


@pytest.mark.parametrize("host_loop", [True, False])
def test_tracking_fault_of_a_host_side_speed_loop_waits_for_enable(host_loop: bool) -> None:
    sup = Supervisor(MODEL, LoopConfig(), host_speed_loop=host_loop)
    sup.enable(0.0)
    assert sup.take_enable_request()
    sup.motors(motors(DriveState.ENABLED, DriveState.ENABLED), 0.1)
    t, fault = 0.1, None
    while fault is None and t < 2.0:  # the right wheel turns at 10 rad/s on a command of 0
        t += 0.01
        status = StatusBoard([
            dataclasses.replace(m, feedback=WheelFeedback(0.0, 10.0 * k, t))
            for k, m in enumerate(motors(DriveState.ENABLED, DriveState.ENABLED).statuses)])
        fault = sup.motors(status, t, (0.0, 0.0))
    assert fault is not None and fault.code is ErrorCode.TRACKING_ERROR
    assert "'right'" in fault.message
    t = recover(sup, t)
    # The drive's own loop is re-enabled as usual; a loop closed on the host ran away on its
    # own feedback and is not restarted without an explicit enable.
    assert state_of(sup) is (GatewayState.FAULT if host_loop else GatewayState.RUNNING)


# -- the state table ---------------------------------------------------------------------------


def in_state(state: GatewayState) -> Supervisor:
    """A supervisor brought to ``state`` the way the gateway gets there."""
    sup = Supervisor(MODEL, LoopConfig())
    if state is GatewayState.ENABLING:
        sup.enable(0.0)
    elif state is GatewayState.RUNNING:
        sup = running()
    elif state is GatewayState.FAULT:
        sup = running()
        sup.motors(motors(DriveState.FAULT, DriveState.ENABLED), 0.2)
    elif state is GatewayState.ESTOP:
        sup.estop()
    elif state is GatewayState.STOPPING:
        sup.shutdown()
    assert state_of(sup) is state
    return sup


_D, _EN, _R = GatewayState.DISABLED, GatewayState.ENABLING, GatewayState.RUNNING
_F, _E, _S = GatewayState.FAULT, GatewayState.ESTOP, GatewayState.STOPPING
#: What each command does in each state (DISABLED, ENABLING, RUNNING, FAULT, ESTOP, STOPPING),
#: as the supervisor did before its state changes were a table.
COMMANDS: dict[str, tuple[tuple[GatewayState, ...], Callable[[Supervisor], object]]] = {
    "enable": ((_EN, _EN, _R, _EN, _EN, _S), lambda s: s.enable(1.0)),
    "disable": ((_D, _D, _D, _D, _E, _S), lambda s: s.disable()),
    "estop": ((_E,) * 6, lambda s: s.estop("test")),
    "shutdown": ((_S,) * 6, lambda s: s.shutdown()),
    "enable_failed": ((_F,) * 6, lambda s: s.enable_failed("refused")),
    "bus_fault": ((_D, _F, _F, _F, _E, _S), lambda s: s.bus_fault("bus-off")),
}


@pytest.mark.parametrize("command", sorted(COMMANDS))
@pytest.mark.parametrize("state", list(GatewayState), ids=lambda s: s.name)
def test_every_command_in_every_state_goes_where_it_did(command: str,
                                                        state: GatewayState) -> None:
    expected, act = COMMANDS[command]
    sup = in_state(state)
    act(sup)
    assert state_of(sup) is expected[list(GatewayState).index(state)]


def test_the_table_answers_every_pair_or_refuses_it() -> None:
    assert not TRANSITIONS.keys() & IGNORED
    for state in GatewayState:
        for event in Event:
            if (state, event) in TRANSITIONS:
                assert next_state(state, event) is TRANSITIONS[state, event]
            elif (state, event) in IGNORED:
                assert next_state(state, event) is None
            else:
                with pytest.raises(IllegalTransitionError, match=(
                        f"expected the event {event.value!r} in .*, but the gateway is "
                        f"{state.name}")):
                    next_state(state, event)
    # The events only the supervisor's own checks raise are refused where they cannot happen.
    with pytest.raises(IllegalTransitionError, match="expected the event 'enabled' in ENABLING"):
        next_state(GatewayState.RUNNING, Event.ENABLED)
    sup = running()
    with pytest.raises(IllegalTransitionError, match="'retry' in FAULT, but the gateway is "
                                                     "RUNNING"):
        sup._go(Event.RETRY)
    assert state_of(sup) is GatewayState.RUNNING


def test_the_state_changes_in_one_place() -> None:
    """``Supervisor.state`` is assigned only by ``_go`` (and its first value in ``__init__``);
    nothing else in the package assigns a supervisor's state."""
    tree = ast.parse(Path(control.__file__).read_text())
    where = [
        func.name
        for func in ast.walk(tree) if isinstance(func, ast.FunctionDef)
        for node in ast.walk(func) if isinstance(node, (ast.Assign, ast.AugAssign, ast.AnnAssign))
        for target in (node.targets if isinstance(node, ast.Assign) else [node.target])
        if isinstance(target, ast.Attribute) and target.attr == "state"
    ]
    assert sorted(where) == ["__init__", "_go"]
    for path in Path(gateway.__file__).parent.rglob("*.py"):
        text = path.read_text()
        assert "supervisor.state =" not in text and "sup.state =" not in text, path


@pytest.mark.parametrize(("detail", "age", "says"), [
    ("motor 'right' (ODrive node 2): controller watchdog not confirmed", None,
     "reports a fault: controller watchdog not confirmed, and it has not answered "
     "(no feedback yet)"),
    ("phase loss", 0.25, "reports a fault: phase loss, and it stopped answering (no feedback "
                         "for 0.250 s)"),
    ("motor 'left' (ODrive node 1): someone else's", 0.25,
     "reports a fault: motor 'left' (ODrive node 1): someone else's, and it stopped answering"),
])
def test_a_fault_message_names_each_motor_once_and_tells_silent_from_stopped(
    detail: str, age: float | None, says: str
) -> None:
    """The motor's name comes first, once (a driver's detail that names it again is cut), and
    a motor never heard from 'has not answered' rather than 'stopped answering'."""
    status = MotorStatus("right", 2, DriveState.OFFLINE, DriveFault.MOTOR, detail, age, None)
    text = motor_fault_text(status, "failed its enable sequence")
    assert text.startswith("motor 'right' (node 2) failed its enable sequence, and it " + says)
