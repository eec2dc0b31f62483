"""The driver contract's part of controller-side protection (:mod:`gateway.core.protection`):
the default for protocols whose timeout is stated, the text of a protection fault, and the
per-motor record of protections that failed."""

from __future__ import annotations

import logging
import math
from typing import TYPE_CHECKING

from gateway.core.protection import Guard, Protection, ProtectionState, WatchdogPolicy

if TYPE_CHECKING:
    from collections.abc import Callable

log = logging.getLogger("gateway.drive.driver")


def stated_protection(protocol: str, action: str, fix: str, stated_s: float) -> Protection:
    """The protection of a motor whose controller's timeout cannot be set over CAN:
    :attr:`Guard.STATED` by its ``controller_timeout_s`` (``stated_s`` > 0), else
    :attr:`Guard.UNSTATED` with ``fix``.

    :param protocol: the protocol's name, for the message.
    :param action: what the controller does when the timeout expires.
    :param fix: how to set and state the timeout.
    """
    if stated_s > 0:
        return Protection(
            Guard.STATED,
            float(stated_s),
            action,
            "set on the controller outside wheelgate; stated by controller_timeout_s "
            "(not verifiable over CAN)",
        )
    return Protection(
        Guard.UNSTATED,
        None,
        "unknown",
        f"not stated: nothing known stops this {protocol} motor if wheelgate dies",
        fix,
    )


def fault_text(wheel: str, protocol: str, node_id: int, why: str, fix: str) -> str:
    """The text of a protection that was not confirmed: the motor, what came back, the fix."""
    return (
        f"motor {wheel!r} ({protocol} node {node_id}): controller watchdog not confirmed: "
        f"{why}" + (f"; fix: {fix}" if fix else "")
    )


#: How often the drivers' protection states are looked at for a failure to report (s).
CHECK_EVERY_S = 0.02


class FailedProtections:
    """Per motor, why its controller-side protection failed under
    :attr:`~gateway.core.protection.WatchdogPolicy.REQUIRED` (``""``: it did not), and
    whether this enable's failure has been reported (once per enable): looked for every cycle
    while a protection is pending, then every :data:`CHECK_EVERY_S` (a setup that starts again
    by itself, a CiA 402 node's boot-up, is pending again at the next look).

    :param n: the number of motors.
    """

    __slots__ = ("next_check_s", "reported", "why")

    def __init__(self, n: int) -> None:
        self.why: list[str] = [""] * n
        self.reported: list[bool] = [False] * n
        self.next_check_s = -math.inf

    def restart(self) -> None:
        """A new enable: every failure is to be reported again, the first look at once."""
        self.reported = [False] * len(self.reported)
        self.next_check_s = -math.inf

    def newly_failed(
        self, now_s: float, state: Callable[[int], ProtectionState]
    ) -> list[int]:
        """The motors whose protection (``state`` of each) failed and was not reported yet in
        this enable, now marked reported; ``[]`` when no look is due at ``now_s``."""
        if now_s < self.next_check_s:
            return []
        out, pending, reported = [], False, self.reported
        for i, done in enumerate(reported):
            if done:
                continue
            s = state(i)
            if s is ProtectionState.FAILED:
                reported[i] = True
                out.append(i)
            elif s is ProtectionState.PENDING:
                pending = True
        self.next_check_s = -math.inf if pending else now_s + CHECK_EVERY_S
        return out

    def merged(self, index: int, detail: str) -> str:
        """Motor ``index``'s fault text with its protection failure first."""
        failed = self.why[index]
        return failed if not detail or detail == failed else f"{failed}; {detail}"

    def fail(self, index: int, text: str, policy: WatchdogPolicy) -> bool:
        """Record that motor ``index``'s protection was not confirmed (``text``: the fault
        text): kept under :attr:`WatchdogPolicy.REQUIRED` (the motor is not armed), a warning
        under :attr:`WatchdogPolicy.WARN`.

        :return: whether it is kept as a fault.
        """
        if policy is WatchdogPolicy.REQUIRED:
            log.error("%s; not arming it (gateway.controller_watchdog: required)", text)
            self.why[index] = text
            return True
        log.warning("%s; arming it anyway (gateway.controller_watchdog: warn)", text)
        return False


def may_arm(state: ProtectionState, policy: WatchdogPolicy) -> bool:
    """Whether a motor may be armed as far as its protection goes: confirmed, not configured
    by its driver, or failed under :attr:`WatchdogPolicy.WARN`."""
    if state is ProtectionState.PENDING:
        return False
    return state is not ProtectionState.FAILED or policy is WatchdogPolicy.WARN
