"""Controller-side protection: what makes a motor controller stop by itself when the gateway
falls silent (killed, out of memory, a frozen host), and how sure the gateway is of it.

The gateway's own safety (command timeout, faults, e-stop) needs the gateway alive.  When it
dies, only the controllers can stop the wheels, each by its own watchdog: an ODrive axis
watchdog, a CiA 402 drive's heartbeat consumer (CiA 301 object 0x1016) with its abort
connection option (CiA 402 object 0x6007), a VESC's app-configuration timeout.  Each driver
says per motor which :class:`Guard` it has (:meth:`gateway.drive.driver.MotorDriver.protection`):

* :attr:`Guard.CONFIGURED`: the gateway writes the protection while enabling and reads it
  back; the motor is armed only once it is confirmed
  (:meth:`gateway.drive.driver.MotorDriver.protection_state`), or, with the policy
  :attr:`WatchdogPolicy.WARN`, armed with a warning when it could not be confirmed;
* :attr:`Guard.STATED`: the protocol cannot set it over CAN; it was set with the vendor's tool
  and the configuration states it (``controller_timeout_s``);
* :attr:`Guard.UNSTATED`: as STATED, but the configuration does not say: a warning in
  ``check`` and at start-up;
* :attr:`Guard.NONE`: the controller has no such protection (DJI C620/C610, by the worst
  reading of what is public); the configuration must acknowledge it.

The stop time after the last frame is what :attr:`Protection.timeout_s` says, plus the
controller's own deceleration (an axis that goes idle coasts).
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

__all__ = ["Guard", "Protection", "ProtectionState", "WatchdogPolicy", "check_timeout", "stop_text"]


class WatchdogPolicy(str, enum.Enum):
    """``gateway.controller_watchdog``: what happens when a protection the protocol can
    configure is not confirmed."""

    #: The motor is not armed; it reports FAULT naming the motor, the protocol and the fix.
    REQUIRED = "required"
    #: The motor is armed anyway, with a warning in the log and in the motor's detail.
    WARN = "warn"


class Guard(str, enum.Enum):
    """How a motor's controller-side protection is known."""

    CONFIGURED = "configured"
    STATED = "stated"
    UNSTATED = "unstated"
    NONE = "none"


class ProtectionState(enum.Enum):
    """Where the configuring of a :attr:`Guard.CONFIGURED` protection stands."""

    #: Not configured by the gateway (STATED, UNSTATED, NONE).
    NOT_APPLICABLE = "not applicable"
    #: Written, not yet read back (or not yet written: the enable has not started).
    PENDING = "pending"
    #: Read back with the values written.
    CONFIRMED = "confirmed"
    #: No answer, or a read-back other than written, within the driver's time.
    FAILED = "failed"


@dataclass(frozen=True, slots=True)
class Protection:
    """One motor's controller-side protection.

    :param guard: how it is known.
    :param timeout_s: the controller acts this long after wheelgate falls silent (its last
        command or, for CiA 402, its last heartbeat; ``None``: unknown or never).
    :param action: what the controller then does, e.g. ``"goes IDLE (the motor coasts)"``.
    :param how: where it lives and how it is set, e.g. ``"axis watchdog, written over CAN
        (RxSdo endpoints 154, 153) and read back"``.
    :param fix: what the user does to get it (empty when there is nothing to do).
    :param configurable: whether the protocol could set it over CAN had the configuration
        said how (an ODrive 0.6 without its endpoint IDs): with
        :attr:`WatchdogPolicy.REQUIRED` such an :attr:`Guard.UNSTATED` motor is refused.
    """

    guard: Guard
    timeout_s: float | None
    action: str
    how: str
    fix: str = ""
    configurable: bool = False

    def describe(self) -> str:
        """One line for ``check`` and the start-up log."""
        if self.guard is Guard.NONE:
            return f"NONE: {self.how}"
        when = ("after a time not known" if self.timeout_s is None
                else f"{self.timeout_s:g} s after")
        head = f"{self.guard.value}: stops {when} wheelgate falls silent ({self.action}); "
        return head + self.how


def check_timeout(protection: Protection, period_s: float, where: str) -> str | None:
    """A problem with a protection's timeout against the loop period, or ``None``.

    A controller timeout shorter than three loop periods trips on an ordinary late cycle.

    :param where: the motor, for the message, e.g. ``"motor 'left' (odrive node 1)"``.
    """
    t = protection.timeout_s
    if t is None or protection.guard is Guard.NONE:
        return None
    if t < 3.0 * period_s:
        return (
            f"{where}: controller timeout {t:g} s: expected at least three loop periods "
            f"({3.0 * period_s:g} s), or a late cycle stops the motor"
        )
    return None


def stop_text(guard: Guard, timeout_s: float | None, state: ProtectionState) -> str:
    """A controller-side stop as ``status`` and the ROS diagnostics word it: ``configured
    0.25 s (confirmed)``, ``stated 1 s``, ``none``."""
    timeout = f" {timeout_s:g} s" if timeout_s else ""
    return guard.value + timeout + ("" if state is ProtectionState.NOT_APPLICABLE
                                    else f" ({state.value})")
