"""A simulated VESC: the controller side of :mod:`drivers.vesc.codec`.

Modelled on the firmware (https://github.com/vedderb/bldc, read at ``b9d287b3``:
``comm/comm_can.c``, ``motor/mc_interface.c``, ``motor/mcpwm_foc.c``, ``motor/foc_math.c``,
``timeout.c``), and built at its **factory settings** unless told otherwise
(``applications/appconf_default.h``, ``motor/mcconf_default.h``; a board's ``hwconf`` may
override them):

* **Status messages** only as enabled: the factory's ``can_status_msgs_r1`` is 0
  (``APPCONF_CAN_STATUS_MSGS_R1``), so a factory VESC sends no status at all.  ``status_msgs``
  is that bit mask; this simulator sends STATUS (bit 0) and STATUS_5 (bit 4), in that order,
  every ``1 / status_rate_hz`` (``can_status_rate_1``, 50 Hz from the factory) from the
  VESC's own phase (:attr:`~gateway.sim.device.DeviceSimulator.phase`), as
  ``cancom_status_thread`` does.  The other status packets are not simulated.
* **Timeout**: no command for ``timeout_s`` (``timeout_msec``, 1000 ms from the factory,
  ``APPCONF_TIMEOUT_MSEC``) releases the motor, which coasts (``timeout_brake_current`` 0 A:
  ``timeout_thread`` calls ``mc_interface_release_motor_override`` and a brake current below
  ``cc_min_current``).
* **Speed ramp** (``ramp_erpm_s``, ``s_pid_ramp_erpms_s``, 25000 ERPM/s from the factory,
  ``MCCONF_S_PID_RAMP_ERPMS_S``): SET_RPM does not set the speed loop's set point, it only
  stores the command (``mcpwm_foc_set_pid_speed`` in ``motor/mcpwm_foc.c``: the set point is
  first taken from the measured speed when the motor was not already speed-controlled).  Every
  period of the speed loop (``pid_thread``, ``sp_pid_loop_rate`` 1000 Hz from the factory) the
  set point steps toward the command by ``s_pid_ramp_erpms_s * dt``, up and down alike
  (``utils_step_towards`` in ``foc_run_pid_control_speed``, ``motor/foc_math.c``), and the
  motor follows the set point with the model's dynamics.  A ramp of 0 sets the set point to
  the command at once, as the firmware does then.  A release (timeout, fault, SET_CURRENT 0)
  or a current or brake command leaves speed control: no ramp, and the next SET_RPM starts
  its set point from the measured speed again.
* **Minimum ERPM** (``min_erpm``, ``s_pid_min_erpm``, 900 from the factory): SET_RPM below it
  does not start a stopped motor (``mcpwm_foc_set_pid_speed``).  A running motor whose
  *ramped* set point is below it is held at duty 0, phases shorted (``"Brake when set ERPM is
  below min ERPM"`` in ``mcpwm_foc.c``; :mod:`drivers.vesc.min_erpm`): a stop command first
  ramps the set point down to ``min_erpm`` under speed control, and only then brakes; a start
  from standstill is held at duty 0 until the set point has ramped up to ``min_erpm``.  The
  brake is modelled simply, with the speed loop's own dynamics (the model's time constant and
  acceleration limit); a real shorted-phase brake is weaker at low speed.
* The tachometer counts 60-degree steps of the electrical angle (6 per electrical revolution),
  is an int32 that wraps, and starts at ``initial_tacho`` so tests can begin near the wrap.
  :meth:`VescSimulator.power_cycle` zeroes it as every boot does (``mcpwm_foc_init``) and
  releases the motor; the status frames go on at once (the boot's silence: ``SILENT``).
* SET_CURRENT and SET_CURRENT_BRAKE below ``min_current_a`` (``cc_min_current``, 0.05 A)
  release the motor; above it SET_CURRENT drives toward the no-load speed (``max_rpm``) and
  SET_CURRENT_BRAKE brakes to a stop, both with an acceleration of ``accel_per_a_rad_s2`` per
  ampere (the model has no torque physics).
* Status fields are truncated toward zero, as the firmware's casts are (:func:`make_status`).
* PING is answered with a PONG carrying the ID the PING was addressed to (the firmware's
  choice, so a broadcast PING gets 255), HW_TYPE_VESC; COMM_GET_APPCONF in a
  PROCESS_SHORT_BUFFER as firmware 6.00 answers it (:mod:`drivers.vesc.sim_appconf`;
  ``appconf`` says whether and how).
* An injected :attr:`~gateway.sim.device.SimFault.FAULT` releases the motor; commands are
  ignored for ``fault_stop_s`` (``m_fault_stop_time_ms``, 500 ms by default) and then the
  fault clears itself.  The motor stays released until the next command.  Status frames and
  PONGs go on meanwhile and carry no fault code, as on the device.

:func:`simulator_for` builds one as a configuration says the device was set up (its
``controller_timeout_s``, ``status_rate_hz``, ``min_erpm``); :data:`drivers.BUILTIN_SIMULATORS`
names it for ``--sim`` and the tests (the driver never imports this module).
"""

from __future__ import annotations

import enum
import logging
import math
from typing import TYPE_CHECKING

from drivers.vesc.appconf import BufferPacket
from drivers.vesc.codec import (
    BROADCAST_ID,
    RPM_PER_RAD_S,
    TACHO_STEPS_PER_EREV,
    CanPacketId,
    VescCommand,
    VescPing,
    decode_command,
    make_pong,
    make_status,
    make_status5,
    wrap_int32,
)
from drivers.vesc.min_erpm import FACTORY_MIN_ERPM
from drivers.vesc.settings import (
    FACTORY_STATUS_MSGS,
    FACTORY_STATUS_RATE_HZ,
    FACTORY_TIMEOUT_S,
    STATUS_1,
    STATUS_5,
    VescOptions,
)
from drivers.vesc.sim_appconf import AppconfResponder
from gateway.core.errors import ConfigError, DecodeError
from gateway.sim.device import DeviceSimulator, SimFault

if TYPE_CHECKING:
    from gateway.core.types import Frame, MotorConfig
    from gateway.sim.device import MotorModel

log = logging.getLogger(__name__)

_MAX_CURRENT_A = 3276.7  # int16 / 10
_MAX_ERPM = 2**31 - 1
#: ``s_pid_ramp_erpms_s`` from the factory (``MCCONF_S_PID_RAMP_ERPMS_S``, eRPM/s).
FACTORY_RAMP_ERPM_S = 25000.0
#: The speed loop's period, in which the set point ramps (``sp_pid_loop_rate``: 1000 Hz).
PID_PERIOD_S = 0.001


class SimMode(enum.IntEnum):
    """What the simulated controller is doing."""

    RELEASED = 0
    SPEED = 1
    CURRENT = 2
    BRAKE = 3
    #: Speed control with its ramped set point below ``min_erpm``: duty 0, phases shorted,
    #: braking (a stop, or a start until the set point has ramped up to ``min_erpm``).
    BELOW_MIN_ERPM = 4


#: The modes in which the speed loop runs (``CONTROL_MODE_SPEED`` on a running motor).
_SPEED_MODES = (SimMode.SPEED, SimMode.BELOW_MIN_ERPM)


def simulator_for(motor: MotorConfig) -> VescSimulator:
    """A :class:`VescSimulator` for ``motor``, as the motor block says the device was set up
    in VESC Tool: its stated timeout (``controller_timeout_s``, else the factory 1 s), status
    messages (STATUS and STATUS_5 at ``status_rate_hz``, else none, as from the factory) and
    ``min_erpm``.  The speed ramp is the factory's: no key of the block states it.

    :raises ConfigError: for a motor block the driver would refuse.
    """
    o = VescOptions.from_block(motor.options, f"motor {motor.wheel!r}")
    rate = o.status_rate_hz
    return VescSimulator(motor, status_msgs=STATUS_1 | STATUS_5 if rate else FACTORY_STATUS_MSGS,
                         status_rate_hz=rate or FACTORY_STATUS_RATE_HZ, timeout_s=o.timeout_s,
                         min_erpm=o.min_erpm)


class VescSimulator(DeviceSimulator):
    """One simulated VESC, at factory settings unless the keywords say otherwise.

    :param motor: the motor block; ``options["pole_pairs"]`` is required (the other options
        are read by :func:`simulator_for`, not here).
    :param model: the motor physics.
    :param status_msgs: ``can_status_msgs_r1``: :data:`STATUS_1` and :data:`STATUS_5` bits
        (0, none, from the factory).
    :param status_rate_hz: ``can_status_rate_1`` (Hz; 0 sends nothing).
    :param initial_tacho: tachometer value at the start (int32).
    :param timeout_s: the device's command timeout, ``timeout_msec`` (s; 0: never).
    :param min_erpm: ``s_pid_min_erpm``: SET_RPM below it is not speed-controlled (eRPM).
    :param ramp_erpm_s: ``s_pid_ramp_erpms_s``: how fast the speed set point follows SET_RPM
        (eRPM/s; 0: at once).
    :param fault_stop_s: how long an injected FAULT lasts before it clears itself (s).
    :param v_in_v: input voltage reported in STATUS_5 (V).
    :param min_current_a: current commands below this release the motor (A).
    :param accel_per_a_rad_s2: motor acceleration per ampere in current and brake mode.
    :param appconf: how COMM_GET_APPCONF is answered (as firmware 6.00 from the factory).
    :raises ConfigError: if ``pole_pairs`` is missing or not a positive int, or a rate, a
        timeout, ``min_erpm`` or ``ramp_erpm_s`` is negative.
    """

    def __init__(
        self,
        motor: MotorConfig,
        model: MotorModel | None = None,
        *,
        status_msgs: int = FACTORY_STATUS_MSGS,
        status_rate_hz: float = FACTORY_STATUS_RATE_HZ,
        initial_tacho: int = 0,
        timeout_s: float = FACTORY_TIMEOUT_S,
        min_erpm: float = FACTORY_MIN_ERPM,
        ramp_erpm_s: float = FACTORY_RAMP_ERPM_S,
        fault_stop_s: float = 0.5,
        v_in_v: float = 24.0,
        min_current_a: float = 0.05,
        accel_per_a_rad_s2: float = 50.0,
        appconf: AppconfResponder | None = None,
    ) -> None:
        super().__init__(motor, model)
        pole_pairs = motor.options.get("pole_pairs")
        if not isinstance(pole_pairs, int) or isinstance(pole_pairs, bool) or pole_pairs < 1:
            raise ConfigError(f"motor {motor.wheel!r}.pole_pairs: expected int >= 1, got "
                              f"{pole_pairs!r}")
        for name, value in (("status_rate_hz", status_rate_hz), ("timeout_s", timeout_s),
                            ("min_erpm", min_erpm), ("ramp_erpm_s", ramp_erpm_s)):
            if not value >= 0.0:
                raise ConfigError(
                    f"simulated VESC {motor.node_id}: {name}: expected at least 0, got {value!r}"
                )
        self.pole_pairs = pole_pairs
        #: ``can_status_msgs_r1``: which status packets go out.
        self.status_msgs = status_msgs
        #: Seconds between status bursts (``inf``: none).
        self.status_period_s = 1.0 / status_rate_hz if status_rate_hz > 0.0 else math.inf
        self.timeout_s = timeout_s
        self.min_erpm = min_erpm
        self.ramp_erpm_s = ramp_erpm_s
        self.fault_stop_s = fault_stop_s
        self.v_in_v = v_in_v
        self.min_current_a = min_current_a
        self.accel_per_a_rad_s2 = accel_per_a_rad_s2
        self.appconf = appconf or AppconfResponder()
        #: What the controller is doing.
        self.mode = SimMode.RELEASED
        #: Frames addressed to this VESC that it could not parse.
        self.rejected = 0
        self._initial_tacho = wrap_int32(initial_tacho)
        self._steps0 = self._steps_now()
        self._speed_accel = self.model.max_accel_rad_s2
        self._current_a = 0.0
        #: The speed loop: the last SET_RPM (``m_speed_command_rpm``) and the ramped set point
        #: (``m_speed_pid_set_rpm``), in eRPM.
        self.command_erpm = 0.0
        self.set_point_erpm = 0.0
        self._last_cmd_s: float | None = None
        self._fault_since_s: float | None = None
        self._next_status_s: float | None = None
        self._now_s: float | None = None
        self._prev: tuple[float, float] | None = None

    @property
    def node_id(self) -> int:
        """This controller's ID."""
        return self.motor.node_id

    @property
    def erpm(self) -> float:
        """The motor's true speed in eRPM (what STATUS reports, before truncation)."""
        return self.model.velocity_rad_s * RPM_PER_RAD_S * self.pole_pairs

    @property
    def tachometer(self) -> int:
        """The tachometer as STATUS_5 would report it now."""
        return wrap_int32(self._initial_tacho + self._steps_now() - self._steps0)

    def _steps_now(self) -> int:
        electrical_rad = self.model.position_rad * self.pole_pairs
        return math.floor(electrical_rad * TACHO_STEPS_PER_EREV / (2.0 * math.pi))

    # ----------------------------------------------------------------- hooks

    def _on_frame(self, frame: Frame, now_s: float) -> list[Frame]:
        self._now_s = now_s
        eid = frame.arbitration_id
        if frame.is_extended_id and eid >> 8 == BufferPacket.PROCESS_SHORT_BUFFER:
            ours = eid & 0xFF in (self.node_id, BROADCAST_ID)  # (no status: rate 0.0)
            return self.appconf.answer(frame, self.node_id, self.timeout_s, 1.0 /
                                       self.status_period_s, self.status_msgs) if ours else []
        try:
            msg = decode_command(frame)
        except DecodeError as err:
            if frame.arbitration_id & 0xFF in (self.node_id, BROADCAST_ID):
                self.rejected += 1
                log.debug("simulated VESC %d ignores %s: %s", self.node_id, frame, err)
            return []
        if msg is None or msg.node_id not in (self.node_id, BROADCAST_ID):
            return []
        if isinstance(msg, VescPing):
            return [make_pong(msg.sender_id, msg.node_id)]
        # decode_msg() resets the timeout even while a fault makes the motor ignore commands.
        self._last_cmd_s = now_s
        if not self.faults & SimFault.FAULT:
            self._apply(msg)
        return []

    def _apply(self, cmd: VescCommand) -> None:
        model = self.model
        if cmd.packet == CanPacketId.SET_RPM:
            if self.mode == SimMode.RELEASED and abs(cmd.value) < self.min_erpm:
                return  # mcpwm_foc_set_pid_speed starts a stopped motor only at min ERPM
            if self.mode not in _SPEED_MODES:
                self.set_point_erpm = self.erpm  # the ramp starts from the measured speed
            self.command_erpm = cmd.value
            if self.ramp_erpm_s <= 0.0:
                self.set_point_erpm = cmd.value
            model.max_accel_rad_s2 = self._speed_accel
            model.armed = True
            self._follow_set_point()
            return
        if abs(cmd.value) < self.min_current_a:
            self._release()
            return
        model.max_accel_rad_s2 = min(self._speed_accel, abs(cmd.value) * self.accel_per_a_rad_s2)
        model.armed = True
        if cmd.packet == CanPacketId.SET_CURRENT:
            self.mode = SimMode.CURRENT
            self._current_a = cmd.value
            model.target_rad_s = math.copysign(self.motor.max_rpm / RPM_PER_RAD_S, cmd.value)
        else:
            self.mode = SimMode.BRAKE
            self._current_a = abs(cmd.value)
            model.target_rad_s = 0.0

    def _follow_set_point(self) -> None:
        """Speed control toward the set point, or duty 0 below ``min_erpm`` (the FOC ISR)."""
        if abs(self.set_point_erpm) < self.min_erpm:
            self.mode = SimMode.BELOW_MIN_ERPM
            self.model.target_rad_s = 0.0
        else:
            self.mode = SimMode.SPEED
            self.model.target_rad_s = self.set_point_erpm / self.pole_pairs / RPM_PER_RAD_S

    def _ramp(self, dt_s: float) -> None:
        """``utils_step_towards`` the command by ``s_pid_ramp_erpms_s * dt``."""
        sp, cmd = self.set_point_erpm, self.command_erpm
        if self.mode not in _SPEED_MODES or sp == cmd:
            return
        step = self.ramp_erpm_s * dt_s
        self.set_point_erpm = min(sp + step, cmd) if sp < cmd else max(sp - step, cmd)
        self._follow_set_point()

    def tick(self, now_s: float) -> list[Frame]:
        """Advance the motor to ``now_s``, the speed set point ramping every
        :data:`PID_PERIOD_S` on the way; return the periodic frames due."""
        last = self._last_tick_s
        if last is not None and now_s > last:
            t = last
            while (self.mode in _SPEED_MODES and self.set_point_erpm != self.command_erpm
                   and now_s - t > PID_PERIOD_S * (1.0 + 1e-9)):
                self._ramp(PID_PERIOD_S)  # the speed loop steps its set point, then runs
                if not self.faults & SimFault.STALL:  # (the base holds a stalled shaft)
                    self.model.step(PID_PERIOD_S)
                t += PID_PERIOD_S
            self._last_tick_s = t
            self._ramp(now_s - t)
        return super().tick(now_s)

    def power_cycle(self) -> None:
        """Lose power and boot again (see the module's doc): released, the tachometer at 0."""
        self._release()
        self.command_erpm = self.set_point_erpm = 0.0
        self._last_cmd_s, self._initial_tacho = None, 0
        self._steps0 = self._steps_now()

    def _release(self) -> None:
        self.mode = SimMode.RELEASED
        self._current_a = 0.0
        self.model.armed = False
        self.model.target_rad_s = 0.0
        self.model.max_accel_rad_s2 = self._speed_accel

    def _on_fault(self) -> None:
        self._release()
        self._fault_since_s = self._now_s

    def _on_tick(self, now_s: float) -> list[Frame]:
        self._now_s = now_s
        if not self.faults & SimFault.FAULT:
            self._fault_since_s = None
        elif self._fault_since_s is None:
            self._fault_since_s = now_s
        elif now_s - self._fault_since_s >= self.fault_stop_s:
            log.debug("simulated VESC %d: fault cleared itself", self.node_id)
            self.clear(SimFault.FAULT)
            self._fault_since_s = None
        last_cmd = self._last_cmd_s
        if (self.mode != SimMode.RELEASED and self.timeout_s > 0.0 and last_cmd is not None
                and now_s - last_cmd > self.timeout_s):
            log.debug("simulated VESC %d: command timeout, motor released", self.node_id)
            self._release()
        current_a = self._estimate_current(now_s)
        if not self.status_msgs & (STATUS_1 | STATUS_5) or math.isinf(self.status_period_s):
            return []  # the factory setting: no status messages
        due = self._next_status_s = self.due(self._next_status_s, now_s, self.status_period_s)
        if now_s < due - 1e-9:
            return []
        if now_s - due >= self.status_period_s:
            due = now_s  # fell behind: restart the schedule
        self._next_status_s = due + self.status_period_s
        return self._status_frames(current_a)

    # ----------------------------------------------------------------- internals

    def _estimate_current(self, now_s: float) -> float:
        v = self.model.velocity_rad_s
        prev, self._prev = self._prev, (now_s, v)
        if self.mode == SimMode.RELEASED:
            return 0.0
        if self.mode not in _SPEED_MODES:
            return self._current_a
        if prev is None or now_s <= prev[0]:
            return 0.0
        return (v - prev[1]) / (now_s - prev[0]) / self.accel_per_a_rad_s2  # accel / (a/A)

    def _status_frames(self, current_a: float) -> list[Frame]:
        erpm = min(max(self.erpm, -_MAX_ERPM), _MAX_ERPM)
        max_erpm = self.motor.max_rpm * self.pole_pairs
        # Duty 0 when released, and while braking below min ERPM (phases shorted).
        idle = self.mode in (SimMode.RELEASED, SimMode.BELOW_MIN_ERPM)
        duty = 0.0 if idle else min(max(erpm / max_erpm, -1.0), 1.0)
        current_a = min(max(current_a, -_MAX_CURRENT_A), _MAX_CURRENT_A)
        out = []
        if self.status_msgs & STATUS_1:
            out.append(make_status(self.node_id, erpm, current_a, duty))
        if self.status_msgs & STATUS_5:
            out.append(make_status5(self.node_id, self.tachometer, self.v_in_v))
        return out
