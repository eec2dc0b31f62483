"""The supervisor's side of the watch for another commander (:mod:`gateway.runtime.commanders`):
an enable the loop holds arms nothing, and one it withholds releases the motors."""

from __future__ import annotations

import dataclasses

from gateway.core.control import Supervisor
from gateway.core.settings import LoopConfig
from gateway.core.types import DriveState, ErrorCode, GatewayState, Twist
from tests.core.test_control import MODEL, motors, state_of


def test_an_enable_not_yet_taken_arms_nothing_and_a_withheld_one_releases_the_motors() -> None:
    # The loop holds an enable while it listens for another commander (runtime.commanders):
    # nothing is armed meanwhile, and the hold restarts the enable's timeout.
    sup = Supervisor(MODEL, dataclasses.replace(LoopConfig(), enable_timeout_s=0.1))
    sup.enable(0.0)
    assert state_of(sup) is GatewayState.ENABLING and sup.enable_pending
    assert not sup.decide(0.0).armed
    sup.hold_enable(0.2)
    assert sup.motors(motors(DriveState.DISABLED, DriveState.DISABLED), 0.25) is None
    assert state_of(sup) is GatewayState.ENABLING  # 0.25 s after enable(), 0.05 s after the hold
    reason = sup.yield_motors("another program commands these motors")
    assert reason == "enable withheld: another program commands these motors" == sup.reason
    assert state_of(sup) is GatewayState.FAULT and sup.fault_code is ErrorCode.BUS_ERROR
    assert not sup.enable_pending and not sup.take_enable_request()
    d = sup.decide(0.3)  # released although fault_action is zero (the other keeps them)
    assert d.twist == Twist() and not d.armed
    sup.enable(1.0)  # an enable taken again arms them
    assert sup.take_enable_request() and sup.decide(1.0).armed
    assert sup.motors(motors(DriveState.ENABLED, DriveState.FAULT), 1.1) is not None
    assert sup.decide(1.1).armed  # a motor fault after it: zero, armed, as before


def test_drives_enabled_before_the_enable_is_taken_are_not_running() -> None:
    # An ODrive reports ENABLED from its heartbeat (closed loop): another program may have
    # enabled it.  Until the loop takes the enable, that is no reason to run.
    sup = Supervisor(MODEL, LoopConfig())
    sup.enable(0.0)
    assert sup.motors(motors(DriveState.ENABLED, DriveState.ENABLED), 0.1) is None
    assert state_of(sup) is GatewayState.ENABLING and not sup.decide(0.1).armed
    assert sup.take_enable_request()
    sup.motors(motors(DriveState.ENABLED, DriveState.ENABLED), 0.2)
    assert state_of(sup) is GatewayState.RUNNING
