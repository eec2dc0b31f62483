"""The enable and stop sequences of one CiA 402 node as a non-blocking state machine.

:class:`NodeSequencer` runs the configuration steps of :mod:`drivers.cia402.steps` one SDO at
a time, then walks the CiA 402 state machine to OPERATION ENABLED with controlwords sent in the
command RPDO, checking the statusword from the feedback TPDOs after each step (that half, and the
stop, are :mod:`drivers.cia402.walk`).  Every wait has
a deadline; a missed deadline or an SDO abort ends in :attr:`Phase.FAILED` with a message
naming the node, the step and the cause.  Except one: a node that has not answered at all since
the start (a drive still booting, powered with the gateway's computer) is asked again, the
sequence starting over every deadline, until it answers (its boot-up restarts the sequence as
well) or the gateway's own enable timeout ends the wait.

The target field of the RPDOs the sequencer sends itself is 0 for a drive motor (target
velocity).  For a steering actuator (cyclic synchronous position) it is :attr:`NodeSequencer.hold`,
the latest position actual value: a CSP drive follows 0x607A from the moment it reaches
OPERATION ENABLED, so the walk sends no controlword until that position is known, and the
drive is enabled on the spot where it stands.  Its stop is SHUTDOWN at once (released where it
stands): statusword bit 12 means "follows the target" in CSP, not "speed 0".

The controller-side protection steps (:func:`~drivers.cia402.steps.protection_steps`: the
heartbeat consumer 0x1016:01, the abort connection option code 0x6007 and the error behaviour
0x1029:01, written, then read back; an optional object the drive does not have is skipped) come
before NMT start, so before any controlword; a read of what the quick stop does (0x605A) follows
them, kept in :attr:`NodeSequencer.readings`.  :attr:`NodeSequencer.protection` says
where they stand; when one fails (an abort, no answer within :attr:`NodeSequencer.timeout_s`,
a read-back other than written) :attr:`NodeSequencer.protection_error` says why, and the
driver's :meth:`~gateway.drive.driver.MotorDriver.may_arm` decides: if not
(``controller_watchdog: required``) the sequence ends there, the drive stays pre-operational and
no controlword reaches it; if so (``warn``) it skips the rest of the protection and goes on.

Nothing here blocks or reads the clock: the driver passes ``now_s`` and sends what comes back.
"""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING

from drivers.cia402.codec import make_nmt
from drivers.cia402.enums import (
    Controlword,
    ServerCommand,
    State,
    state_from_statusword,
)
from drivers.cia402.faults import sdo_abort_text
from drivers.cia402.phase import Phase
from drivers.cia402.sdo import make_sdo_download, make_sdo_upload, shown_value
from drivers.cia402.steps import (
    ABSENT,
    NmtStep,
    SdoExpectStep,
    SdoReadStep,
    SdoVerifyStep,
    SdoWriteStep,
)
from drivers.cia402.walk import ControlwordWalk
from gateway.core.errors import DecodeError
from gateway.core.protection import ProtectionState
from gateway.core.types import DriveFault

if TYPE_CHECKING:
    from collections.abc import Callable

    from drivers.cia402.codec import Cia402Codec
    from drivers.cia402.sdo import SdoResponse
    from drivers.cia402.steps import Step
    from gateway.core.types import Frame

log = logging.getLogger(__name__)


class NodeSequencer(ControlwordWalk):
    """The enable/stop state machine of one node (the controlword walk and the stop:
    :class:`~drivers.cia402.walk.ControlwordWalk`).

    :param node_id: the node.
    :param label: how messages name it, e.g. ``node 3 ("left")``.
    :param codec: builds the command RPDO for controlword steps.
    :param steps: from :func:`~drivers.cia402.steps.configuration_steps`.
    :param position: a steering actuator in cyclic synchronous position mode (see above).
    :param may_arm: asked when the protection failed: whether the drive may be armed all the
        same (default: never).
    :param timeout_s: the deadline of each wait (an SDO answer, an :class:`SdoExpectStep`'s
        expected value, the first statusword after NMT start, each state-machine transition):
        the motor block's ``response_timeout_s``.
    """

    #: Pause between reads of an :class:`SdoExpectStep` (s).
    EXPECT_RETRY_S = 0.01

    def __init__(self, node_id: int, label: str, codec: Cia402Codec,
                 steps: tuple[Step, ...], *, position: bool = False,
                 may_arm: Callable[[], bool] | None = None, timeout_s: float = 0.5) -> None:
        self.node_id = node_id
        self.timeout_s = timeout_s
        self.label = label
        self.codec = codec
        self.steps = steps
        self.position = position
        #: The target field of the sequencer's own RPDOs: 0 (velocity) for a drive motor; for
        #: a steering actuator the latest position actual value (counts, int32) that the driver
        #: passes in, ``None`` until one came.
        self.hold: int | None = None if position else 0
        self.phase = Phase.IDLE
        #: Why the sequence failed ("" unless FAILED).
        self.error = ""
        #: Fault class of the failure.
        self.error_flags = DriveFault.NONE
        #: Latest statusword and the state it reports (``None`` if none or not a state).
        self.statusword: int | None = None
        self.state: State | None = None
        self._i = 0
        self._awaiting = False
        self._sent_s = 0.0
        self._step_s = 0.0
        self._retry_s = 0.0
        self._last_read: int | None = None
        #: Whether the node has answered an SDO since the sequence started (see
        #: :meth:`_poll_configure`), and how often the sequence started over for its silence.
        self._answered = False
        self.silent_restarts = 0
        self._edge: tuple[State, State] | None = None
        self._edges = 0
        self._cw_sent_s = float("-inf")
        self._last_cw: int | None = None
        self._has_protection = any(getattr(st, "protection", False) for st in steps)
        #: Where the controller-side protection stands (NOT_APPLICABLE without its steps).
        self.protection = (ProtectionState.PENDING if self._has_protection
                           else ProtectionState.NOT_APPLICABLE)
        #: Whether a drive whose protection failed may be armed all the same (see above).
        self.may_arm: Callable[[], bool] = may_arm or (lambda: False)
        #: Whether the sequence ended because the protection failed (:attr:`error` then only
        #: repeats :attr:`protection_error`).
        self.halted_by_protection = False
        #: Why the protection failed since the last start ("" if it did not).
        self.protection_error = ""
        #: What each :class:`SdoReadStep` got since the last start: (index, subindex) ->
        #: (value, ``None``), or (``None``, the abort code).
        self.readings: dict[tuple[int, int], tuple[int | None, int | None]] = {}
        #: The optional objects the drive does not have (their read-back is skipped).
        self.absent: set[tuple[int, int]] = set()

    # ----------------------------------------------------------------- inputs

    def start(self, now_s: float) -> list[Frame]:
        """Begin (or restart) the enable sequence."""
        self.phase = Phase.CONFIGURING
        self.error, self.error_flags = "", DriveFault.NONE
        self.halted_by_protection, self.protection_error = False, ""
        if self._has_protection:
            self.protection = ProtectionState.PENDING
        self._i, self._awaiting, self._retry_s, self._step_s = 0, False, now_s, now_s
        self._edge, self._edges, self._answered = None, 0, False
        self.readings, self.absent = {}, set()
        if self.position:
            self.hold = None  # only a position read after this start counts
        return self._issue(now_s)

    def quick_stop(self) -> list[Frame]:
        """QUICK STOP for a node that may be in OPERATION ENABLED (armed, or on its way),
        else nothing: before a restart of the sequence, whose NMT PRE-OPERATIONAL turns the
        PDOs off, so that a drive only unheard (its transmissions lost, or the gateway's
        reception) does not keep its last target out of reach of any later stop.  A drive
        already PRE-OPERATIONAL ignores it."""
        if self.phase in (Phase.ARMED, Phase.STOPPING, Phase.AWAIT_STATUS, Phase.WALKING):
            return [self._rpdo(Controlword.QUICK_STOP)]
        return []

    def fail(self, message: str, flags: DriveFault) -> list[Frame]:
        """End the sequence with ``message``; a drive that may be powered gets SHUTDOWN."""
        was = self.phase
        self.phase = Phase.FAILED
        self.error, self.error_flags = f"{self.label}: {message}", flags
        log.error("%s", self.error)
        if was in (Phase.AWAIT_STATUS, Phase.WALKING):
            return [self._rpdo(Controlword.SHUTDOWN)]
        return []

    def on_status(self, statusword: int) -> None:
        """Take a statusword from a feedback TPDO."""
        self.statusword = statusword
        self.state = state_from_statusword(statusword)

    def on_sdo(self, resp: SdoResponse, now_s: float) -> bool:
        """Take an SDO response; ``False`` if none was expected (late or foreign)."""
        self._answered = True
        step = self.steps[self._i] if self._i < len(self.steps) else None
        if (self.phase is not Phase.CONFIGURING or not self._awaiting
                or isinstance(step, NmtStep) or step is None
                or (resp.index, resp.subindex) != (step.index, step.subindex)):
            return False
        self._awaiting = False
        where = f"0x{step.index:04X}:{step.subindex:02X} ({step.what})"
        if isinstance(step, SdoReadStep) or (
                isinstance(step, SdoWriteStep) and step.optional
                and resp.command is ServerCommand.ABORT and resp.abort_code in ABSENT):
            self._noted(step, resp, where, now_s)
        elif resp.command is ServerCommand.ABORT:
            verb = (f"write of {shown_value(step.value)} to" if isinstance(step, SdoWriteStep)
                    else "read of")
            self._step_failed(step, f"SDO {verb} {where} aborted: "
                              f"{sdo_abort_text(resp.abort_code)}", DriveFault.COMMUNICATION, now_s)
        elif isinstance(step, SdoWriteStep):
            if resp.command is not ServerCommand.INITIATE_DOWNLOAD:
                self._step_failed(step, f"expected a download confirmation for {where}, got "
                                  f"{resp.command.name}", DriveFault.COMMUNICATION, now_s)
            else:
                self._advance(now_s)
        else:
            try:
                value = resp.value(step.dtype)
            except DecodeError as err:
                self._step_failed(step, str(err), DriveFault.COMMUNICATION, now_s)
                return True
            self._last_read = value
            if value == step.expected:
                self._advance(now_s)
            elif isinstance(step, SdoVerifyStep):
                self._step_failed(step, f"{where} reads {shown_value(value)} after the write of "
                                  f"{shown_value(step.expected)}", DriveFault.CONTROLLER, now_s)
            else:
                self._retry_s = now_s + self.EXPECT_RETRY_S
        return True

    def _noted(self, step: SdoWriteStep | SdoReadStep, resp: SdoResponse, where: str,
               now_s: float) -> None:
        """An answer that only informs: an optional object's absence, or a reading."""
        key, abort = (step.index, step.subindex), None
        if resp.command is ServerCommand.ABORT:
            abort = resp.abort_code
        if isinstance(step, SdoWriteStep):
            self.absent.add(key)
            log.info("%s: %s: the drive has none (%s): CiA 301's default applies", self.label,
                     where, sdo_abort_text(resp.abort_code))
        else:
            try:
                value = None if abort is not None else resp.value(step.dtype)
            except DecodeError as err:
                self._step_failed(step, str(err), DriveFault.COMMUNICATION, now_s)
                return
            self.readings[key] = (value, abort)
            text, doubt = step.explain(value, abort)
            log.log(logging.WARNING if doubt else logging.INFO, "%s: %s", self.label, text)
        self._advance(now_s)

    def on_sdo_error(self, err: DecodeError, now_s: float) -> None:
        """A malformed SDO response arrived while one was expected."""
        self._answered = True
        if self.phase is Phase.CONFIGURING and self._awaiting:
            self._awaiting = False
            self._step_failed(self.steps[self._i], str(err), DriveFault.COMMUNICATION, now_s)

    # ----------------------------------------------------------------- periodic

    def poll(self, now_s: float) -> list[Frame]:
        """Frames due at ``now_s``; checks every deadline."""
        if self.phase is Phase.CONFIGURING:
            return self._poll_configure(now_s)
        if self.phase is Phase.AWAIT_STATUS:
            if self.state is not None:
                self.phase = Phase.WALKING
            elif now_s - self._step_s > self.timeout_s:
                got = "none" if self.statusword is None else f"0x{self.statusword:04X}"
                return self.fail(
                    f"no valid statusword in a TPDO within {self.timeout_s:g} s after "
                    f"NMT start (last: {got})", DriveFault.COMMUNICATION)
            else:
                return []
        if self.phase is Phase.WALKING:
            return self._poll_walk(now_s)
        if self.phase is Phase.STOPPING:
            return self._poll_stop(now_s)
        return []

    # ----------------------------------------------------------------- internals

    def _advance(self, now_s: float) -> None:
        self._i += 1
        self._retry_s, self._step_s, self._last_read = now_s, now_s, None
        if (self.protection is ProtectionState.PENDING
                and getattr(self.steps[self._i - 1], "protection", False)
                and not any(getattr(st, "protection", False) for st in self.steps[self._i:])):
            self.protection = ProtectionState.CONFIRMED
            log.info("%s: the controller-side protection reads back as written", self.label)

    def _step_failed(self, step: Step, message: str, flags: DriveFault, now_s: float) -> None:
        """A configuration step failed: the sequence ends, unless it is a protection step
        and the drive may be armed all the same (then its other steps are skipped)."""
        if not getattr(step, "protection", False):
            self.fail(message, flags)
            return
        self.protection, self.protection_error = ProtectionState.FAILED, message
        if not self.may_arm():  # (the driver reports it, with the fix)
            self.phase, self.halted_by_protection = Phase.FAILED, True
            self.error = f"{self.label}: controller watchdog not confirmed: {message}"
            self.error_flags = DriveFault.WATCHDOG
            return
        while self._i < len(self.steps) and getattr(self.steps[self._i], "protection", False):
            self._i += 1
        self._awaiting, self._last_read = False, None
        self._retry_s = self._step_s = now_s

    def _issue(self, now_s: float) -> list[Frame]:
        out: list[Frame] = []
        while self._i < len(self.steps):
            step = self.steps[self._i]
            if isinstance(step, NmtStep) or (isinstance(step, SdoVerifyStep)
                                             and (step.index, step.subindex) in self.absent):
                if isinstance(step, NmtStep):
                    out.append(make_nmt(step.command, self.node_id))
                self._advance(now_s)
                continue
            if isinstance(step, SdoWriteStep):
                out.append(make_sdo_download(self.node_id, step.index, step.subindex,
                                             step.value, step.dtype))
            else:
                out.append(make_sdo_upload(self.node_id, step.index, step.subindex))
            self._awaiting, self._sent_s = True, now_s
            return out
        self.phase, self._step_s = Phase.AWAIT_STATUS, now_s
        self.statusword = self.state = None
        return out

    def _poll_configure(self, now_s: float) -> list[Frame]:
        step = self.steps[self._i]
        if isinstance(step, NmtStep):  # not reached: NMT steps never wait
            return self._issue(now_s)
        if isinstance(step, SdoExpectStep) and now_s - self._step_s > self.timeout_s:
            return self.fail(
                f"0x{step.index:04X}:{step.subindex:02X} ({step.what}) reads "
                f"{self._last_read}, expected {step.expected} within "
                f"{self.timeout_s:g} s", DriveFault.CONTROLLER)
        if self._awaiting:
            if now_s - self._sent_s > self.timeout_s and not self._answered:
                # Nothing from the node since the start: not booted yet (powered with the
                # gateway's computer), or not there.  Start over until it answers; the
                # gateway's enable_timeout_s ends the wait, saying the node is silent.
                if not self.silent_restarts:
                    log.info("%s: no answer to the enable sequence's first request yet; "
                             "asking again every %g s", self.label, self.timeout_s)
                self.silent_restarts += 1
                return self.start(now_s)
            if now_s - self._sent_s > self.timeout_s:
                op = (f"write of {shown_value(step.value)} to" if isinstance(step, SdoWriteStep)
                      else "read of")
                self._awaiting = False
                self._step_failed(
                    step, f"no SDO response within {self.timeout_s:g} s to the {op} "
                    f"0x{step.index:04X}:{step.subindex:02X} ({step.what})",
                    DriveFault.COMMUNICATION, now_s)
                return self._issue(now_s) if self.phase is Phase.CONFIGURING else []
            return []
        if now_s >= self._retry_s:
            return self._issue(now_s)
        return []
