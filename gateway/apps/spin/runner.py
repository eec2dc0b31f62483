"""The edge of ``wheelgate spin``: one motor's driver on the bus for the spin, behind a deadman.

:func:`run_spin` listens first (a command to the motor from another sender, or a wheelgate's
odometry or status, refuses the spin before anything is sent), enables the motor as the
gateway's loop does (enable frames, then a hold command and the driver's housekeeping every
cycle until the driver reports it armed), commands the plan cycle by cycle while recording the
feedback, and then -- in a ``finally``, so also after a fault, a deadman stop or an exception --
sends the driver's stop (zero and disarm) and records the wheel coasting down.

The motor gets a driver instance of its own (from the registry, as the drive set makes them),
so no other motor of the robot is armed.  The
:class:`~gateway.apps.spin.deadman.Deadman` ends the spin at any key on a terminal (Ctrl-Z
and Ctrl-C included) and at a signal; the stop goes out from the loop, never from a signal
handler.  Should this process die without sending it, the controller's own timeout is the
second stop.  An error once something was sent comes out as :class:`SpinFailedError`, which
says the stop went out; the gateway's refusal to arm the motor (its controller watchdog not
confirmed) as :class:`ArmRefusedError`, apart from a fault the controller reports.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from gateway.apps.spin.judge import Sample
from gateway.apps.spin.plan import command_ids, someone_else
from gateway.bus.can_bus import drain, send_frames
from gateway.core.errors import BusError, DriveFaultError, GatewayError, GatewayTimeoutError
from gateway.core.protection import ProtectionState
from gateway.core.types import DriveState
from gateway.drive.registry import get_driver_class

if TYPE_CHECKING:
    from collections.abc import Callable

    import can

    from gateway.apps.spin.deadman import Deadman
    from gateway.apps.spin.plan import SpinPlan
    from gateway.core.can_ids import CanIds
    from gateway.core.protection import WatchdogPolicy
    from gateway.core.types import Frame
    from gateway.drive.driver import MotorDriver

log = logging.getLogger(__name__)

#: How long the bus is listened to before arming (s): a wheelgate's status comes at 10 Hz.
LISTEN_S = 0.5
#: How long the wheel is watched coasting down after the stop (s).
COAST_S = 0.5


class BusInUseError(BusError):
    """Someone else drives the bus (a daemon, another commander): nothing was sent."""


class ArmRefusedError(GatewayError):
    """The gateway did not arm the motor: its controller-side stop (the controller watchdog
    the driver sets over CAN and reads back) could not be confirmed, and
    ``gateway.controller_watchdog: required`` arms no motor without it.  The gateway's refusal,
    not a fault the controller reports.

    :param why: what came back, or the silence (the driver's ``protection_failure``).
    :param fix: what to do, as the driver says (``""``: it says nothing).
    """

    def __init__(self, message: str, why: str, fix: str) -> None:
        super().__init__(message)
        self.why = why
        self.fix = fix


class SpinFailedError(GatewayError):
    """The spin failed once frames were sent (:attr:`cause`); its stop (:attr:`stop`, zero
    and disarm) was sent after the failure.  Its message is the cause's."""

    def __init__(self, cause: GatewayError, stop: tuple[Frame, ...]) -> None:
        super().__init__(str(cause))
        self.cause = cause
        self.stop = stop


@dataclass(frozen=True, slots=True)
class SpinRecord:
    """What one spin did.

    :param plan: the plan as commanded (a sweep's origin and side filled in).
    :param samples: the motor's feedback from the start of the command to the end of the
        coast (times from the start of the command).
    :param ended_s: when the command ended (s from its start; early when stopped).
    :param enable_s: how long the motor took to enable (s).
    :param stop: the frames of the stop (zero and disarm) that were sent.
    :param fault: the controller's fault, or silence, that ended the spin.
    :param stopped_by: the key or signal that stopped it.
    :param truth: an outside measurement of the wheel during the spin (``probe``), if any.
    """

    plan: SpinPlan
    samples: tuple[Sample, ...]
    ended_s: float
    enable_s: float
    stop: tuple[Frame, ...]
    fault: str = ""
    stopped_by: str = ""
    truth: tuple[Sample, ...] = ()


def run_spin(bus: can.BusABC, plan: SpinPlan, deadman: Deadman, *, rate_hz: float,
             enable_timeout_s: float, watchdog: WatchdogPolicy, can_ids: CanIds,
             listen_s: float = LISTEN_S, probe: Callable[[], float] | None = None,
             announce: Callable[[str], None] | None = None, header: str = "") -> SpinRecord:
    """Spin ``plan.motor`` on ``bus`` (see the module's doc).

    :param rate_hz: the command rate (the configuration's loop rate).
    :param enable_timeout_s: how long the motor may take to enable.
    :param watchdog: the configuration's ``controller_watchdog``.
    :param can_ids: the configuration's own CAN IDs (a running wheelgate sends them).
    :param probe: an outside measurement of the wheel's position (rad), read every cycle.
    :param announce: called with a line of progress.
    :param header: announced once the bus is found free, before anything is sent (what the
        spin will do).
    :return: the record (no samples and no stop frames when the deadman stopped it before
        anything was sent).
    :raises BusInUseError: when someone else drives the bus (nothing was sent).
    :raises SpinFailedError: once something was sent, for an error whose stop was sent: the
        controller faults while enabling (:class:`DriveFaultError`), the gateway refuses to
        arm it (:class:`ArmRefusedError`), it does not enable in time
        (:class:`GatewayTimeoutError`), a steering actuator's wheels stand where they leave no
        room to sweep (:class:`~gateway.apps.spin.plan.NoRoomError`), a frame cannot be sent
        (:class:`BusError`).
    :raises BusError: when the stop itself cannot be sent.
    """
    motor = plan.motor
    driver: MotorDriver[Any] = get_driver_class(motor.driver)([motor])
    driver.watchdog_policy = watchdog
    period = 1.0 / rate_hz
    say = announce or (lambda line: None)
    heard: list[Frame] = []
    end = time.monotonic() + listen_s
    while time.monotonic() < end:
        for frame in drain(bus):
            heard.append(frame)
            driver.on_frame(frame)
        reason = deadman.wait(min(period, end - time.monotonic()))
        if reason:
            return SpinRecord(plan, (), 0.0, 0.0, (), stopped_by=reason)
    who = someone_else(heard, command_ids(driver.preview_command([0.0])), can_ids, motor)
    if who is not None:
        raise BusInUseError(f"{who}: another gateway or tool drives {motor.wheel}; refusing to "
                            f"spin it (stop that one first, e.g. systemctl stop wheelgate)")
    if header:
        say(header)
    samples: list[Sample] = []
    truth: list[Sample] = []
    t0 = start = time.monotonic()
    fault = ""
    ended = enable_s = 0.0
    failed: GatewayError | None = None
    try:
        send_frames(bus, driver.enable(start))
        stopped_by = _enabled(bus, driver, deadman, period, enable_timeout_s)
        t0 = time.monotonic()
        enable_s = t0 - start
        if not stopped_by:
            say(f"enabled in {enable_s:.2f} s")
            fb = driver.feedback(0)
            plan = plan.from_origin(fb.position_rad if fb is not None else 0.0)
            fault, stopped_by = _command(bus, driver, plan, deadman, period, t0, samples,
                                         truth, probe)
            ended = min(time.monotonic() - t0, plan.duration_s)
    except GatewayError as err:
        failed = err
    finally:
        stop = driver.disable(time.monotonic())
        try:
            send_frames(bus, stop)
            log.info("spin: stop sent to %s (%d frames)", motor.wheel, len(stop))
        except BusError as err:
            log.error("spin: the stop to %s failed: %s; its controller's own timeout must "
                      "stop it", motor.wheel, err)
            raise
    if failed is not None:
        raise SpinFailedError(failed, tuple(stop)) from failed
    end = time.monotonic() + COAST_S
    while time.monotonic() < end:  # the wheel coasts down; its encoder still counts
        _receive(bus, driver, samples, t0)
        send_frames(bus, driver.poll(time.monotonic()))  # housekeeping (a CANopen heartbeat)
        time.sleep(period)
    if probe is not None:
        truth.append(Sample(time.monotonic() - t0, probe(), 0.0))
    return SpinRecord(plan, tuple(samples), ended, enable_s, tuple(stop), fault, stopped_by,
                      tuple(truth))


def _command(bus: can.BusABC, driver: MotorDriver[Any], plan: SpinPlan, deadman: Deadman,
             period: float, t0: float, samples: list[Sample], truth: list[Sample],
             probe: Callable[[], float] | None) -> tuple[str, str]:
    """Command the plan from ``t0`` on, cycle by cycle, recording the feedback (and the
    probe); returns the fault and the stop reason that ended it early (``""``: none)."""
    next_s = t0
    while True:
        now = time.monotonic()
        t = now - t0
        _receive(bus, driver, samples, t0)
        if probe is not None:
            truth.append(Sample(t, probe(), 0.0))
        fault = _trouble(driver, now)
        if fault or t >= plan.duration_s:
            return fault, ""
        send_frames(bus, driver.command([plan.setpoint(t)], now) + driver.poll(now))
        next_s += period
        reason = deadman.wait(next_s - time.monotonic())
        if reason:
            return "", reason


def _enabled(bus: can.BusABC, driver: MotorDriver[Any], deadman: Deadman, period: float,
             timeout_s: float) -> str:
    """Until the driver reports its motor armed, as the loop enables: a hold command and the
    housekeeping every cycle.  Returns what stopped it (``""``: armed).

    :raises ArmRefusedError: when the gateway refuses to arm it (its protection failed).
    :raises DriveFaultError: when the controller reports a fault.
    :raises GatewayTimeoutError: at ``deadline``, saying where the enable stands.
    """
    motor = driver.motors[0]
    deadline = time.monotonic() + timeout_s
    while True:
        now = time.monotonic()
        for frame in drain(bus):
            driver.on_frame(frame)
        state = driver.states(now)[0]
        if state is DriveState.ENABLED:
            return ""
        node = f"{motor.wheel} ({motor.driver} node {motor.node_id})"
        refused = _refusal(driver, node)
        if refused is not None:
            raise refused
        if state is DriveState.FAULT:
            raise DriveFaultError(f"{node} did not enable: it reports a fault: "
                                  f"{driver.detail(0) or driver.faults(0)!r}", motor.node_id,
                                  driver.faults(0))
        if now >= deadline:
            why = {DriveState.OFFLINE: "no feedback from it (check wiring, node_id, bitrate "
                                       "and power; silent streams: "
                                       f"{', '.join(driver.live.silent(0, now))})",
                   DriveState.ENABLING: "its enable sequence did not finish",
                   DriveState.DISABLED: "it answers but stays disarmed"}.get(state, state.name)
            raise GatewayTimeoutError(f"{node} did not enable within {timeout_s:g} s "
                                      f"(gateway.enable_timeout_s): {why}")
        fb = driver.feedback(0)
        frames = [] if motor.steering and fb is None else driver.command(
            [fb.position_rad if motor.steering and fb is not None else 0.0], now)
        send_frames(bus, frames + driver.poll(now))
        reason = deadman.wait(period)
        if reason:
            return reason


def _refusal(driver: MotorDriver[Any], node: str) -> ArmRefusedError | None:
    """Why the gateway itself will not arm the motor: its protection is
    :attr:`ProtectionState.FAILED` and the policy arms nothing without it (the driver then
    also raises the fault flag WATCHDOG, with the same text, whatever the controller says);
    ``None``: no such refusal."""
    if driver.protection_state(0) is not ProtectionState.FAILED or driver.may_arm(0):
        return None
    why, fix = driver.protection_failure(0), driver.protection(0).fix
    return ArmRefusedError(
        f"{node} did not enable: the gateway did not arm it: its controller watchdog was not "
        f"confirmed: {why}{f'; fix: {fix}' if fix else ''} (gateway.controller_watchdog: "
        f"required arms no motor without it)", why, fix)


def _receive(bus: can.BusABC, driver: MotorDriver[Any], samples: list[Sample],
             t0: float) -> None:
    """Take every waiting frame; record the motor's feedback when it is new."""
    for frame in drain(bus):
        driver.on_frame(frame)
    fb = driver.feedback(0)
    if fb is not None and (not samples or fb.timestamp_s - t0 != samples[-1].t_s):
        samples.append(Sample(fb.timestamp_s - t0, fb.position_rad, fb.velocity_rad_s))


def _trouble(driver: MotorDriver[Any], now: float) -> str:
    """Why the motor cannot go on (a fault, silence, disarmed by itself); ``""``: none."""
    state = driver.states(now)[0]
    if state is DriveState.ENABLED:
        return ""
    if state is DriveState.FAULT:
        return f"fault: {driver.detail(0) or driver.faults(0)!r}"
    if state is DriveState.OFFLINE:
        return f"no feedback ({', '.join(driver.live.silent(0, now))} silent)"
    return f"it is {state.name.lower()} (it disarmed by itself)"


