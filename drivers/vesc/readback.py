"""Reading every VESC's command timeout back while enabling, one VESC at a time.

The request and the reply are :mod:`drivers.vesc.appconf`'s.  The replies of all VESCs come to
the same identifiers (the gateway's :data:`~drivers.vesc.appconf.HOST_ID`) and their FILL
frames do not say who sent them, so the VESCs are asked in turn: each up to :attr:`ATTEMPTS`
times, :attr:`RETRY_S` apart, and all within :attr:`BUDGET_S` of the enable (the gateway's
``enable_timeout_s`` is 5 s from the factory).  The policy, per motor (:class:`Outcome`):

* the timeout read is the one stated (``controller_timeout_s``): CONFIRMED, armed;
* it differs, or nothing is stated and the VESC's timeout is off (0) or too short for the
  keep-alive (``command_period_s`` must be less than half of it): DIFFERS, a protection that
  FAILED under ``gateway.controller_watchdog`` (``required``: not armed; ``warn``: armed with a
  warning);
* nothing is stated and the timeout read is usable: READ, armed, and the protection shows it;
* no reply, a malformed one, or a reply of another layout: NOT_READ, armed as before this read
  existed (the timeout stays what the configuration states), with a warning saying why (the
  first thing that went wrong in the VESC's replies).

A disable cancels the read under way (its VESCs not read yet are as never read); the reads that
ended stand until the next enable, as the driver contract wants a protection's state to
(:class:`~gateway.core.protection.ProtectionState`; the ODrive's watchdog setup does the same).
"""

from __future__ import annotations

import dataclasses
import enum
from dataclasses import dataclass
from typing import TYPE_CHECKING

from drivers.vesc.appconf import (
    HOST_ID,
    BufferPacket,
    LayoutError,
    Reassembly,
    make_get_appconf,
    parse_appconf,
)
from drivers.vesc.settings import TIMEOUT_ACTION, TIMEOUT_FIX
from gateway.core.errors import DecodeError
from gateway.core.protection import Guard, Protection, ProtectionState

if TYPE_CHECKING:
    from collections.abc import Sequence

    from gateway.core.types import Frame

#: The identifiers of the buffer protocol's frames to the gateway, by packet.
REPLY_IDS = {(p << 8) | HOST_ID: p for p in BufferPacket}
#: Why a VESC may not answer.
SILENCE_CAUSES = (
    "firmware that does not answer COMM_GET_APPCONF over CAN, a VESC reached only through "
    "another's CAN forwarding, or a controller ID other than the configured one"
)


class Outcome(enum.Enum):
    """Where one motor's read stands (see the module for the policy)."""

    IDLE = "not read (never enabled, or a disable cancelled the read)"
    PENDING = "reading"
    CONFIRMED = "read back as stated"
    READ = "read back (not stated)"
    DIFFERS = "read back other than it must be"
    NOT_READ = "could not be read"


#: The outcomes as the driver contract reports them: not read yet (IDLE too: "not yet
#: written: the enable has not started") is PENDING.
_STATES = {Outcome.IDLE: ProtectionState.PENDING, Outcome.PENDING: ProtectionState.PENDING,
           Outcome.CONFIRMED: ProtectionState.CONFIRMED, Outcome.DIFFERS: ProtectionState.FAILED,
           Outcome.READ: ProtectionState.NOT_APPLICABLE,
           Outcome.NOT_READ: ProtectionState.NOT_APPLICABLE}


@dataclass(frozen=True, slots=True)
class Wanted:
    """What one motor's VESC must read: its ID, ``controller_timeout_s`` (0: not stated) and
    ``command_period_s`` (s)."""

    node_id: int
    stated_s: float
    period_s: float


@dataclass(frozen=True, slots=True)
class Result:
    """One motor's read: where it stands, ``timeout_msec`` (``None``: not read) and why it
    differs or could not be read (empty otherwise)."""

    outcome: Outcome = Outcome.IDLE
    read_ms: int | None = None
    why: str = ""

    @property
    def state(self) -> ProtectionState:
        """The outcome as the driver contract reports it."""
        return _STATES[self.outcome]


def judge(want: Wanted, read_ms: int) -> Result:
    """The policy: the timeout read against what must be (see the module)."""
    stated_ms = round(want.stated_s * 1000.0)
    if want.stated_s > 0.0:
        if read_ms == stated_ms:
            return Result(Outcome.CONFIRMED, read_ms)
        return Result(Outcome.DIFFERS, read_ms, (
            f"the VESC's timeout (App Settings > General > Timeout, timeout_msec) reads "
            f"{read_ms} ms, the configuration states controller_timeout_s {want.stated_s:g} s "
            f"({stated_ms} ms)"))
    if read_ms == 0:
        return Result(Outcome.DIFFERS, read_ms, (
            "the VESC's timeout (timeout_msec) reads 0 ms: it never releases the motor when "
            "wheelgate falls silent"))
    if not want.period_s < read_ms / 2000.0:
        return Result(Outcome.DIFFERS, read_ms, (
            f"the VESC's timeout (timeout_msec) reads {read_ms} ms: expected more than twice "
            f"command_period_s {want.period_s:g} s, or one lost frame releases the motor"))
    return Result(Outcome.READ, read_ms)


class TimeoutReadback:
    """The reads of one driver's VESCs (pure: frames in, frames out; the caller's clock).

    :param wanted: per motor, in the driver's order.
    """

    RETRY_S = 0.25
    ATTEMPTS = 3
    BUDGET_S = 2.0

    def __init__(self, wanted: Sequence[Wanted]) -> None:
        self.wanted = tuple(wanted)
        self.results = [Result()] * len(self.wanted)
        self._rx = Reassembly()
        self._current: int | None = None
        self._attempts = 0
        self._sent_s = self._started_s = 0.0
        self._error = ""

    def start(self, now_s: float) -> list[Frame]:
        """Forget the last reads and ask the first VESC."""
        self.results = [Result(Outcome.PENDING)] * len(self.wanted)
        self._started_s = now_s
        self._current = None
        return self._next(now_s)

    def stop(self) -> None:
        """A disable: cancel the read under way (the VESCs not read yet are IDLE again, as
        never read); the reads that ended stand until :meth:`start`."""
        self.results = [Result() if r.outcome is Outcome.PENDING else r for r in self.results]
        self._current = None
        self._rx.reset()

    def poll(self, now_s: float) -> list[Frame]:
        """A retry or the next VESC's request when due; the reads past the budget give up."""
        i = self._current
        if i is None:
            return self._next(now_s)
        if now_s - self._started_s >= self.BUDGET_S:
            self._give_up_all()
            return []
        if now_s - self._sent_s < self.RETRY_S:
            return []
        if self._attempts >= self.ATTEMPTS:
            self._settle(i, Result(Outcome.NOT_READ, None, (
                self._error or f"no reply to COMM_GET_APPCONF after {self._attempts} requests "
                f"{self.RETRY_S:g} s apart ({SILENCE_CAUSES})")))
            return self._next(now_s)
        return self._ask(i, now_s)

    def on_frame(self, frame: Frame) -> bool:
        """Take a frame of the buffer protocol to the gateway's ID.

        :return: whether the frame is one (it is taken even when no read is under way).
        :raises DecodeError: for a malformed one (a read under way notes it and retries).
        """
        if not frame.is_extended_id or frame.arbitration_id not in REPLY_IDS:
            return False
        i = self._current
        if i is None:
            self._rx.reset()
            return True
        reply = None
        try:
            reply = self._rx.feed(frame)
            if reply is None:
                return True
            read = parse_appconf(reply.payload, self.wanted[i].node_id)
        except LayoutError as err:
            if reply is not None and reply.sender_id in self._others(i):
                return True  # a late reply of a VESC asked before (to a retry): not this one's
            self._settle(i, Result(Outcome.NOT_READ, None, str(err)))
            raise
        except DecodeError as err:
            # The first error of the read is its reason (a lost frame, not what follows).
            self._error = self._error or f"the reply was malformed: {err}"
            raise
        self._settle(i, judge(self.wanted[i], read.timeout_msec))
        return True

    def _others(self, i: int) -> set[int]:
        return {w.node_id for k, w in enumerate(self.wanted) if k != i}

    def _next(self, now_s: float) -> list[Frame]:
        for i, r in enumerate(self.results):
            if r.outcome is Outcome.PENDING:
                if now_s - self._started_s >= self.BUDGET_S:
                    self._give_up_all()
                    return []
                self._current, self._attempts, self._error = i, 0, ""
                self._rx.reset()
                return self._ask(i, now_s)
        return []

    def _ask(self, i: int, now_s: float) -> list[Frame]:
        self._attempts += 1
        self._sent_s = now_s
        return [make_get_appconf(self.wanted[i].node_id, HOST_ID)]

    def _settle(self, i: int, result: Result) -> None:
        self.results[i] = result
        self._current = None

    def _give_up_all(self) -> None:
        for i, r in enumerate(self.results):
            if r.outcome is Outcome.PENDING:
                self.results[i] = Result(Outcome.NOT_READ, None, (
                    f"not read within {self.BUDGET_S:g} s of the enable (the VESCs are asked "
                    f"one at a time; the enable does not wait longer)"))
        self._current = None


def read_protection(base: Protection, result: Result, want: Wanted) -> Protection:
    """Motor's protection as its read stands: ``base`` (STATED or UNSTATED from the
    configuration, offline) with what was read back and, when it differs, the fix
    (:func:`differs_fix`)."""
    stated = "set in VESC Tool; stated by controller_timeout_s"
    said = stated if base.guard is Guard.STATED else base.how
    how = {
        Outcome.CONFIRMED: f"{stated} and read back from the VESC (timeout_msec "
                           f"{result.read_ms} ms)",
        Outcome.READ: f"not stated; read back from the VESC: timeout_msec {result.read_ms} ms",
        Outcome.DIFFERS: f"read back from the VESC other than it must be: {result.why}",
        Outcome.NOT_READ: f"{said}; could not be read back from the VESC: {result.why}",
    }.get(result.outcome)
    if how is None:  # not read yet (offline: ``check``)
        if base.guard is not Guard.STATED:
            return base
        return dataclasses.replace(base, how=(
            f"{stated}; read back from the VESC while enabling (COMM_GET_APPCONF over CAN)"))
    fix = base.fix
    if result.outcome is Outcome.DIFFERS and result.read_ms is not None:
        fix = differs_fix(want, result.read_ms)
    elif result.outcome is Outcome.READ and result.read_ms is not None:
        fix = f"state it: controller_timeout_s: {result.read_ms / 1000.0:g}"
    # What the VESC will do (the read, not the statement); 0 reads as "never".
    timeout = base.timeout_s if result.read_ms is None else (result.read_ms / 1000.0 or None)
    action = TIMEOUT_ACTION if result.read_ms else base.action
    return dataclasses.replace(base, timeout_s=timeout, action=action, how=how, fix=fix)


def differs_fix(want: Wanted, read_ms: int) -> str:
    """The fix for a timeout read other than it must be: set the stated one in VESC Tool, or
    state the one read -- only when the configuration would take it (``command_period_s``
    less than half of it), else saying why not."""
    stated_s = want.stated_s
    if stated_s <= 0.0 or read_ms <= 0:
        return TIMEOUT_FIX
    tool = f"set App Settings > General > Timeout in VESC Tool to {round(stated_s * 1000.0)} ms"
    read_s = read_ms / 1000.0
    if want.period_s < read_s / 2.0:  # as VescOptions.check takes it
        return f"state the VESC's timeout, controller_timeout_s: {read_s:g}, or {tool}"
    return (f"{tool} (the VESC's {read_ms} ms cannot be stated: the keep-alive, command_period_s "
            f"{want.period_s:g} s, must be less than half the VESC's timeout ({read_s / 2.0:g} s))")
