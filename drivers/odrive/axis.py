"""One ODrive axis as the driver keeps it: one record per axis, and its enable sequence.

The sequence, per axis (as the official ``can_simple.py`` example of the `ODrive CAN protocol
<https://docs.odriverobotics.com/v/latest/manual/can-protocol.html>`_ arms an axis):

* arm: Clear_Errors, Set_Controller_Mode (velocity control with the configured input mode;
  position control for a steering actuator) and Set_Axis_State CLOSED_LOOP_CONTROL; ENABLING
  until a heartbeat shows CLOSED_LOOP_CONTROL;
* on 0.6 with the watchdog's endpoint IDs, the watchdog setup
  (:class:`~drivers.odrive.watchdog.WatchdogSetup`) runs first, and the axis is armed once it
  ends, if the driver's ``may_arm`` allows (confirmed, or failed under
  ``gateway.controller_watchdog: warn``);
* an enable that does not take is repeated every :attr:`Axis.ENABLE_RETRY_S` while the axis is
  alive, idle and error-free, :attr:`Axis.ENABLE_ATTEMPTS` times at most, each time only once a
  heartbeat sent after the last request (past :attr:`Axis.ENABLE_GRACE_S`) still shows IDLE;
  after the last one the axis is refused (:meth:`Axis.refused`) until the next enable, a
  heartbeat in CLOSED_LOOP_CONTROL, or a reported error; a reported error is never cleared
  automatically (the axis refused: it stays in FAULT);
* disarm: Set_Input_Vel 0 then Set_Axis_State IDLE, from any state.

The record is plain data the driver reads and writes on every frame; the methods here only
change the enable state and return frames, so they are tested through the driver.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar

from drivers.odrive.enums import AxisState, ControlMode, InputMode, ProcedureResult
from gateway.core.errors import IllegalTransitionError
from gateway.core.types import DriveFault

if TYPE_CHECKING:
    from collections.abc import Sequence

    from drivers.odrive.codec import OdriveCodec
    from drivers.odrive.watchdog import WatchdogSetup
    from gateway.core.types import Frame, MotorConfig

log = logging.getLogger(__name__)


@dataclass(slots=True)
class Axis:
    """One axis: its configuration and what the driver last learnt of it.

    :param index: the motor's position in the driver's ``motors``.
    :param motor: the motor block.
    :param node_id: its node ID.
    :param steer: whether it is a steering actuator (position control).
    :param scale: wheel to motor side, ``gear_ratio * sign`` (the driver's ``motor_scale``).
    :param rtr: encoder estimates are requested (``encoder_request: rtr``), not cyclic.
    :param input_mode: the input mode selected when arming.
    :param watchdog: the 0.6 watchdog setup (``None``: 0.5, or no endpoint IDs given).
    """

    #: Seconds between enable attempts that have not reached CLOSED_LOOP_CONTROL.
    ENABLE_RETRY_S: ClassVar[float] = 0.5
    #: Enable attempts (while the axis answers) before giving up.
    ENABLE_ATTEMPTS: ClassVar[int] = 3
    #: Heartbeats this soon after an enable request may still show the axis as it was before
    #: it: the errors it just cleared, or IDLE.
    ENABLE_GRACE_S: ClassVar[float] = 0.3

    index: int
    motor: MotorConfig
    node_id: int
    steer: bool
    scale: float
    rtr: bool
    input_mode: InputMode
    watchdog: WatchdogSetup | None
    #: The axis state in the last heartbeat (``UNDEFINED`` before one), and its timestamp.
    axis_state: AxisState | int = AxisState.UNDEFINED
    heartbeat_s: float = -math.inf
    #: The first position estimate (turns): a drive wheel's angle is counted from it.
    pos0_turns: float | None = None
    #: The previous cycle's steering command, ``(time, angle)``, for the speed feed-forward.
    last_angle: tuple[float, float] | None = None
    #: Enabling: armed or about to be, until CLOSED_LOOP_CONTROL, a refusal or giving up.
    enabling: bool = False
    #: Arming waits for the watchdog setup.
    arm_waits: bool = False
    enable_sent_s: float = 0.0
    attempts: int = 0
    #: The fault text from the heartbeat, and from the error reply it asked for.
    axis_detail: str = ""
    error_detail: str = ""
    #: A Get_Error (0.6) / Get_Motor_Error (0.5) request is due at the next poll.
    error_request_due: bool = False
    #: The faults of the last heartbeat's own error flags (without :attr:`refusal`).
    reported: DriveFault = DriveFault.NONE
    #: The last heartbeat's procedure result (0.6; ``SUCCESS`` in 0.5).
    procedure: ProcedureResult | int = ProcedureResult.SUCCESS
    #: Why the last enable gave up with the axis idle and error-free (:meth:`refused`; ""
    #: otherwise): a fault of the motor until the next enable, a heartbeat in
    #: CLOSED_LOOP_CONTROL (:meth:`armed_by`) or one with an error (:meth:`took_error`).
    refusal: str = ""

    # ----------------------------------------------------------------- the sequence

    def arm(self, codec: OdriveCodec, alive: bool) -> tuple[Frame, ...]:
        """The frames that request CLOSED_LOOP_CONTROL from the state last heard (unknown
        when the axis is not ``alive``).

        :raises IllegalTransitionError: naming the wheel, while the axis runs a calibration or
            homing procedure (a new state request would abort it).
        """
        current = self.axis_state if alive else AxisState.UNDEFINED
        mode = ControlMode.POSITION_CONTROL if self.steer else ControlMode.VELOCITY_CONTROL
        self.last_angle = None
        try:
            return codec.make_transition(
                self.node_id, current, AxisState.CLOSED_LOOP_CONTROL, self.input_mode, mode
            )
        except IllegalTransitionError as err:
            raise IllegalTransitionError(
                f'Cannot enable wheel "{self.motor.wheel}": {err}'
            ) from err

    def start(self, arm: Sequence[Frame], now_s: float) -> Sequence[Frame]:
        """Begin enabling with the frames of :meth:`arm`: sent now, or once the watchdog
        setup (which starts here) ends."""
        self.enabling = True
        self.enable_sent_s = now_s
        self.attempts = 1
        self.error_detail = self.refusal = ""
        wd = self.watchdog
        self.arm_waits = wd is not None
        return arm if wd is None else wd.start(now_s)

    def settled(
        self, codec: OdriveCodec, now_s: float, alive: bool, may_arm: bool
    ) -> tuple[Frame, ...]:
        """The watchdog setup ended: arm now if ``may_arm``, else stop enabling."""
        self.arm_waits = False
        if not may_arm:
            self.enabling = False
            return ()
        self.enable_sent_s = now_s
        self.attempts = 1
        return self.arm(codec, alive)

    def retry_due(self, now_s: float) -> bool:
        """Whether an enable under way has waited :attr:`ENABLE_RETRY_S` for its answer."""
        return (
            self.enabling
            and not self.arm_waits
            and now_s - self.enable_sent_s >= self.ENABLE_RETRY_S
        )

    def retry(
        self, codec: OdriveCodec, now_s: float, alive: bool, faulted: bool
    ) -> tuple[Frame, ...]:
        """Arm again if the axis is alive, idle and error-free, at most
        :attr:`ENABLE_ATTEMPTS` times, then give up (:attr:`refusal`); a fault ends enabling
        once past the grace.  Both wait for a heartbeat sent :attr:`ENABLE_GRACE_S` after the
        last request: an older one (a slow heartbeat) does not say how the axis took it."""
        if faulted:
            if now_s - self.enable_sent_s > self.ENABLE_GRACE_S:
                self.enabling = False  # the axis refused: stay in FAULT, never auto-clear
            return ()
        if not alive or self.axis_state != AxisState.IDLE:
            return ()  # not answering yet, or busy: wait without using up an attempt
        if self.heartbeat_s - self.enable_sent_s <= self.ENABLE_GRACE_S:
            return ()  # no heartbeat since the request yet: wait for its answer
        m = self.motor
        if self.attempts >= self.ENABLE_ATTEMPTS:
            self.refusal = self.refused()
            log.warning('ODrive node %d ("%s"): %s; giving up', m.node_id, m.wheel, self.refusal)
            self.enabling = False
            return ()
        self.attempts += 1
        self.enable_sent_s = now_s
        log.info('ODrive node %d ("%s"): enable attempt %d', m.node_id, m.wheel, self.attempts)
        return self.arm(codec, alive)

    def refused(self) -> str:
        """Why the axis stayed idle, error-free, through every enable attempt: what its last
        heartbeat's procedure result says (0.6), and what to do about a calibration."""
        text = (f"stayed in IDLE after {self.attempts} CLOSED_LOOP_CONTROL requests without an "
                f"error")
        result = self.procedure
        if result == ProcedureResult.SUCCESS:
            return text
        name = result.name if isinstance(result, ProcedureResult) else str(int(result))
        text += f"; procedure result {name}"
        if result == ProcedureResult.NOT_CALIBRATED:
            text += (" (the motor or encoder is not calibrated: with odrivetool, request "
                     "FULL_CALIBRATION_SEQUENCE, then keep the result with pre_calibrated and "
                     "save_configuration(), as ODrive's Getting Started guide does)")
        return text

    def disarm(self, codec: OdriveCodec) -> tuple[Frame, ...]:
        """Set_Input_Vel 0 and Set_Axis_State IDLE (allowed from any state)."""
        self.enabling = False
        self.arm_waits = False
        return codec.make_transition(self.node_id, self.axis_state, AxisState.IDLE)

    def armed_by(self, axis_state: AxisState | int, t: float) -> bool:
        """Take the axis state of a heartbeat sent at ``t``: whether it is
        CLOSED_LOOP_CONTROL, which ends enabling and a :attr:`refusal` (the axis did arm)."""
        self.axis_state = axis_state
        self.heartbeat_s = t
        armed = axis_state == AxisState.CLOSED_LOOP_CONTROL
        if armed:
            self.enabling = False
            if self.refusal:
                m = self.motor
                log.info('ODrive node %d ("%s") is in CLOSED_LOOP_CONTROL: no longer refused',
                         m.node_id, m.wheel)
                self.refusal = ""
        return armed

    def took_error(self, faults: DriveFault, detail: str) -> bool:
        """Take the faults of a heartbeat's error flags and their text: whether they are new
        (the last heartbeat had none; logged then).  A reported error replaces a
        :attr:`refusal`, which said there was none."""
        new = bool(faults) and not self.reported
        self.reported = faults
        if faults:
            self.refusal = ""
        if new:
            log.warning('ODrive node %d ("%s") reports %s', self.node_id, self.motor.wheel, detail)
        return new
