"""The controlword half of a CiA 402 node's enable/stop sequence (:class:`ControlwordWalk`, a
part of :class:`~drivers.cia402.sequence.NodeSequencer`): the walk through the CiA 402 state
machine to OPERATION ENABLED, one controlword at a time in the command RPDO, each step
confirmed by the statusword of the feedback TPDOs; and the controlled stop (target 0 until speed
0, then SHUTDOWN; a steering actuator's is SHUTDOWN at once).

Reference: CiA 402 / IEC 61800-7-201 (device control: the state machine and its controlwords).
"""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING

from drivers.cia402.enums import (
    NEXT_TOWARD_ENABLED,
    TRANSITIONS,
    Controlword,
    State,
    StatuswordBit,
)
from drivers.cia402.phase import STOP_TARGET, STOPPED, Phase
from gateway.core.types import DriveFault

if TYPE_CHECKING:
    from drivers.cia402.codec import Cia402Codec
    from gateway.core.types import Frame

log = logging.getLogger(__name__)


class ControlwordWalk:
    """The walk to OPERATION ENABLED and the stop of one node.

    The sequencer that inherits it provides the attributes below and :meth:`fail`.
    """

    #: Controlwords are resent at this period until the statusword follows (s).
    CW_RESEND_S = 0.02
    #: Longest wait for speed 0 before SHUTDOWN when stopping (s).
    STOP_TIMEOUT_S = 1.0
    #: More state changes than this on the way to OPERATION ENABLED is a failure.
    MAX_WALK_STEPS = 8

    node_id: int
    label: str
    codec: Cia402Codec
    position: bool
    timeout_s: float
    hold: int | None
    phase: Phase
    statusword: int | None
    state: State | None
    _step_s: float
    _edge: tuple[State, State] | None
    _edges: int
    _cw_sent_s: float
    _last_cw: int | None

    def fail(self, message: str, flags: DriveFault) -> list[Frame]:
        raise NotImplementedError  # the sequencer's

    def stop(self, now_s: float) -> list[Frame]:
        """Begin a controlled stop: target 0, then SHUTDOWN once the speed is 0."""
        if self.phase in (Phase.ARMED, Phase.AWAIT_STATUS, Phase.WALKING):
            self.phase = Phase.STOPPING
            self._step_s = now_s
            self._cw_sent_s = float("-inf")
            return self._poll_stop(now_s)
        if self.phase is Phase.CONFIGURING:
            self.phase = Phase.IDLE  # pre-operational: no PDO reaches the drive
        return []

    def _rpdo(self, word: int) -> Frame:
        self._last_cw = word
        return self.codec.rpdo(self.node_id, word, 0 if self.hold is None else self.hold)

    def _poll_walk(self, now_s: float) -> list[Frame]:
        state = self.state
        if state is State.OPERATION_ENABLED:
            self.phase = Phase.ARMED
            log.info("%s: OPERATION ENABLED", self.label)
            return []
        if state is not None:
            edge = (state, NEXT_TOWARD_ENABLED[state])
            if edge != self._edge:
                self._edge, self._step_s, self._cw_sent_s = edge, now_s, float("-inf")
                self._edges += 1
                if self._edges > self.MAX_WALK_STEPS:
                    return self.fail(f"no OPERATION ENABLED after {self.MAX_WALK_STEPS} "
                                     "state changes", DriveFault.CONTROLLER)
        if self._edge is None:  # only invalid statuswords so far
            return []
        current, target = self._edge
        word = TRANSITIONS.get(self._edge)
        if now_s - self._step_s > self.timeout_s:
            if self.hold is None:
                return self.fail(
                    f"no position actual value (0x6064) in a TPDO within "
                    f"{self.timeout_s:g} s; a cyclic synchronous position drive is only "
                    f"enabled with its target set to where it stands", DriveFault.COMMUNICATION)
            how = "on its own" if word is None else f"after controlword 0x{word:04X}"
            return self.fail(
                f"no transition {current.label} -> {target.label} within "
                f"{self.timeout_s:g} s {how} (statusword 0x{self.statusword or 0:04X})",
                DriveFault.CONTROLLER)
        if word is None or now_s - self._cw_sent_s < self.CW_RESEND_S or self.hold is None:
            return []  # (no hold position yet: a CSP drive would run to target 0)
        self._cw_sent_s = now_s
        if word is Controlword.FAULT_RESET and (self._last_cw is None or self._last_cw & 0x80):
            return [self._rpdo(Controlword.DISABLE_VOLTAGE)]  # bit 7 low first: a rising edge
        return [self._rpdo(word)]

    def _poll_stop(self, now_s: float) -> list[Frame]:
        state = self.state
        if state in STOPPED:
            self.phase = Phase.IDLE
            return []
        if now_s - self._step_s > self.STOP_TIMEOUT_S + self.timeout_s:
            log.warning("%s: stop not confirmed by the statusword (0x%04X)",
                        self.label, self.statusword or 0)
            self.phase = Phase.IDLE
            return []
        moving = (not self.position and self.statusword is not None
                  and not self.statusword & StatuswordBit.SPEED_ZERO)
        if (state is State.OPERATION_ENABLED and moving
                and now_s - self._step_s < self.STOP_TIMEOUT_S):
            word: int = Controlword.ENABLE_OPERATION
        elif state is not None and state in STOP_TARGET:
            word = TRANSITIONS[(state, STOP_TARGET[state])]
        else:
            word = Controlword.SHUTDOWN
        if word == self._last_cw and now_s - self._cw_sent_s < self.CW_RESEND_S:
            return []
        self._cw_sent_s = now_s
        return [self._rpdo(word)]
