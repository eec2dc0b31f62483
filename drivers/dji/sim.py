"""Simulated DJI C620 / C610 ESC with a current-driven motor (for tests and ``--sim``).

Protocol reference: the RoboMaster C620/C610 user guides' CAN protocol sections and DJI's
`Development-Board-C-Examples <https://github.com/RoboMaster/Development-Board-C-Examples>`_.

What the simulated ESC does:

* takes its int16 slot of ``0x200`` / ``0x1FF`` as a torque-current set point, clamped to the
  ESC's full scale, and applies it at once (the real ESC's FOC current loop is much faster
  than the 1 kHz bus, so it is not modelled);
* drives that current only while the supply voltage leaves room: near the motor's no-load
  speed the current it can drive with the rotation falls to zero (:class:`DjiMotorModel`), so
  a held current spins a wheel up to that speed and no faster;
* emits feedback every ``feedback_period_s`` (1 ms by default): the rotor angle quantised to
  13 bits (``floor``), the rotor speed rounded to whole rpm, the current it applies and the
  temperature (0 on a C610, which does not report one);
* **no command timeout**: no public source says what a C620 / C610 does when the command
  frames stop, so wheelgate assumes the worst, that it holds its last current for ever
  (:mod:`drivers.dji.protection`), and the simulator does the same: it is never kinder than the
  assumption, so no test can pass because a simulated ESC stopped a wheel that a real one might
  not.  ``command_timeout_s`` defaults to ``None`` (hold) and no configuration sets it
  (:func:`simulator_for` never does); a test may give a number to model an ESC that zeroes
  its output after that long without a command frame;
* injected ``SimFault.FAULT`` reports ``fault_temperature_c`` and switches the output off (the
  ESC protecting itself); clearing it restores the normal temperature, and the next command
  frame switches the output on again (DJI has no clear command);
* ``SimFault.SILENT`` stops the feedback (the base class does this);
* ``0x700`` frames are counted in :attr:`DjiSimulator.id_set_requests` and otherwise ignored;
* a **steering actuator** is simulated like any other ESC: current in, rotor angle out.  The
  ESC has no position mode, so the model's position loop stays off (``target_position_rad`` is
  ``None``): the gateway's host-side cascade holds the angle.  The rotor starts at
  ``zero_rad`` (the wheels at their neutral angle) unless ``initial_position_rad`` says
  otherwise, and the feedback carries its angle within the turn, as the real encoder does.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

from drivers.dji.codec import (
    COUNTS_PER_REV,
    ESC_MODELS,
    M3508_GEAR_RATIO,
    RAD_S_PER_RPM,
    DjiFeedback,
    DjiFrameId,
    EscModel,
    decode_command,
    encode_feedback,
)
from gateway.core.cadence import next_due
from gateway.core.errors import ConfigError, DecodeError
from gateway.sim.device import DeviceSimulator, MotorModel, SimFault

if TYPE_CHECKING:
    from gateway.core.types import Frame, MotorConfig

log = logging.getLogger(__name__)

_INT16_MAX = 0x7FFF

#: The M3508's speeds at its output on 24 V (rpm) without load and at its rated torque (3 N m,
#: 10 A at 0.3 N m/A), as measured in "RoboMaster电机特性测试" (sourcelizi.github.io, 2022-02,
#: C620 with M3508), which also describes the ESC's current falling as the voltage runs out.
M3508_NO_LOAD_RPM = 482.0
M3508_RATED_RPM = 469.0
#: The M2006's at its output on 24 V (rpm): no measured figure is public; this is the top of
#: the speed axis of the M2006 performance diagram in DJI's C610 user guide (24 V), an upper
#: bound, so at worst slightly kinder than the motor.
M2006_NO_LOAD_RPM = 450.0
#: The share of the no-load speed over which the drivable current falls from full scale to
#: zero: the M3508's figures above put the rated 10 A 13 rpm below no load, so the C620's full
#: scale, 20 A, 26 rpm below it: about 5.4 %.  The M2006 is assumed to be alike.
KNEE_SHARE = (20.0 / 10.0) * (M3508_NO_LOAD_RPM - M3508_RATED_RPM) / M3508_NO_LOAD_RPM


@dataclass(slots=True)
class DjiMotorModel(MotorModel):
    """A current-driven motor, rotor side: torque from current, inertia and viscous friction.

    .. math::

        J \\dot\\omega = k_t i - b \\omega, \\qquad \\dot\\theta = \\omega

    integrated exactly for a constant current over each step, so it is stable for any step.

    The supply voltage bounds the speed (back-EMF): the current the ESC can drive *with* the
    rotation falls to zero at the motor's no-load speed, linearly over the last
    :data:`KNEE_SHARE` of it, whatever the set point; a current against the rotation (braking)
    is never limited.  The ESC reports the current it applies, which then falls below the set
    point.  Without the limit a held current (the
    gateway killed, a host loop run away) spun the simulated rotor up to where friction alone
    balanced it, twenty and more times the no-load speed: a runaway no real motor shows.

    The inherited ``target_rad_s`` / ``time_constant_s`` fields are not used.

    :param torque_constant_nm_a: rotor-side torque per A (N m / A, > 0).
    :param inertia_kg_m2: rotor-side inertia including the reflected wheel load (kg m^2, > 0).
    :param damping_nm_s_rad: viscous friction (N m s / rad, > 0).
    :param no_load_rad_s: rotor speed at which the supply voltage leaves no driving current
        (rad/s, > 0).
    :param full_scale_a: the ESC's largest current (A, > 0), what it can drive below the knee.
    """

    torque_constant_nm_a: float = 0.3 / M3508_GEAR_RATIO
    inertia_kg_m2: float = 6e-5
    damping_nm_s_rad: float = 1.6e-5
    no_load_rad_s: float = M3508_NO_LOAD_RPM * M3508_GEAR_RATIO * RAD_S_PER_RPM
    full_scale_a: float = 20.0
    #: Current set point the ESC was given (A); it applies it while armed, within the limit.
    current_a: float = 0.0
    #: Current the ESC applied over the last step (A): what it reports.
    applied_a: float = 0.0

    def __post_init__(self) -> None:
        for name in ("torque_constant_nm_a", "inertia_kg_m2", "damping_nm_s_rad",
                     "no_load_rad_s", "full_scale_a"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ConfigError(f"DjiMotorModel.{name}: expected a number > 0, got {value!r}")

    @classmethod
    def for_esc(cls, esc: EscModel) -> DjiMotorModel:
        """Default physics for the motor an ESC type drives.

        M3508 (C620): 0.3 N m/A at the output (DJI datasheet figure) over 3591/187, a loaded
        wheel of 6e-5 kg m^2 at the rotor, no load at :data:`M3508_NO_LOAD_RPM`.  M2006
        (C610): 0.18 N m/A over 36, 1.2e-5 kg m^2, no load at :data:`M2006_NO_LOAD_RPM`.
        The inertias and the friction are plausible round numbers, not measurements.
        """
        if esc.name == "c610":
            return cls(
                torque_constant_nm_a=0.18 / esc.gear_ratio,
                inertia_kg_m2=1.2e-5,
                damping_nm_s_rad=1e-6,
                no_load_rad_s=M2006_NO_LOAD_RPM * esc.gear_ratio * RAD_S_PER_RPM,
                full_scale_a=esc.full_scale_a,
            )
        return cls(torque_constant_nm_a=0.3 / esc.gear_ratio, full_scale_a=esc.full_scale_a)

    def drivable_a(self, speed_rad_s: float) -> float:
        """The largest current (A) the ESC can drive with the rotation at this rotor speed."""
        left = self.no_load_rad_s - abs(speed_rad_s)
        return 0.0 if left <= 0.0 else min(
            self.full_scale_a, self.full_scale_a * left / (KNEE_SHARE * self.no_load_rad_s))

    def step(self, dt_s: float) -> None:
        """Advance by ``dt_s`` seconds with the present set point (zero when disarmed).

        Exact for any step: the speed follows one exponential per regime (the set point
        applied; the voltage-limited current, linear in the speed; none beyond the no-load
        speed), each piece ending where the speed crosses into the next regime.
        """
        if dt_s <= 0.0:
            return
        current = self.current_a if self.armed else 0.0
        sign = -1.0 if current < 0.0 else 1.0
        amps = min(abs(current), self.full_scale_a)
        j, b, kt, top = (self.inertia_kg_m2, self.damping_nm_s_rad, self.torque_constant_nm_a,
                         self.no_load_rad_s)
        slope = kt * self.full_scale_a / (KNEE_SHARE * top)  # the limited torque's, N m s/rad
        # Speeds in the set point's direction: below ``knee`` the set point is applied.
        knee = top - amps * KNEE_SHARE * top / self.full_scale_a
        u = sign * self.velocity_rad_s
        free = kt * amps / b  # where the set point alone would take the speed
        x = 0.0
        left = dt_s
        while left > 0.0:
            edge: float | None = None
            if amps == 0.0 or u < knee or (u == knee and free <= knee):  # the set point
                target, tau = free, j / b
                edge = knee if free > knee else None
            elif u <= top:  # the voltage limit: J u' = slope (top - u) - b u
                target, tau = slope * top / (slope + b), j / (slope + b)
                edge = knee if target < knee else None
            else:  # beyond the no-load speed: no driving current
                target, tau, edge = 0.0, j / b, top
            span = left
            if edge is not None and (reach := tau * math.log((target - u) / (target - edge))) > 0.0:
                span = min(left, reach)  # (> 0: rounding at an edge cannot stall the loop)
            else:
                edge = None
            decay = math.exp(-span / tau)
            x += target * span + (u - target) * tau * (1.0 - decay)
            u = edge if edge is not None and span < left else target + (u - target) * decay
            left -= span
        self.position_rad += sign * x
        self.velocity_rad_s = sign * u
        applied = amps if u < knee else min(amps, self.drivable_a(u))
        self.applied_a = sign * applied


class DjiSimulator(DeviceSimulator):
    """The device side of one C620 / C610 ESC.

    :param motor: the motor block (``node_id`` is the ESC ID; ``options["esc"]`` the type).
    :param model: motor physics; :meth:`DjiMotorModel.for_esc` when omitted.
    :param feedback_period_s: feedback interval (s), 1 ms like the real ESC.
    :param command_timeout_s: zero the output after this long without a command frame;
        ``None`` (default) holds the last set point for ever, as the real ESC is assumed to.
    :param temperature_c: temperature reported while healthy (degC).
    :param fault_temperature_c: temperature reported while ``SimFault.FAULT`` is injected.
    :param initial_position_rad: rotor angle at start (rad), e.g. just below a 13-bit wrap;
        ``None`` (default): 0 for a drive motor, ``zero_rad`` for a steering actuator.
    """

    def __init__(
        self,
        motor: MotorConfig,
        model: DjiMotorModel | None = None,
        *,
        feedback_period_s: float = 0.001,
        command_timeout_s: float | None = None,
        temperature_c: int = 35,
        fault_temperature_c: int = 110,
        initial_position_rad: float | None = None,
    ) -> None:
        esc_name = motor.options.get("esc", "c620")
        if esc_name not in ESC_MODELS:
            raise ConfigError(
                f"motor {motor.wheel!r}: esc: expected one of {sorted(ESC_MODELS)}, "
                f"got {esc_name!r}"
            )
        self.esc: EscModel = ESC_MODELS[str(esc_name)]
        self.physics = model if model is not None else DjiMotorModel.for_esc(self.esc)
        super().__init__(motor, self.physics)
        # Current-driven whatever the motor does: no position mode on the ESC.
        self.physics.target_position_rad = None
        if initial_position_rad is not None:
            self.physics.position_rad = initial_position_rad
        elif not motor.steering:
            self.physics.position_rad = 0.0
        self.esc_id = motor.node_id
        self.feedback_period_s = feedback_period_s
        self.command_timeout_s = command_timeout_s
        self.temperature_c = temperature_c
        self.fault_temperature_c = fault_temperature_c
        #: Raw current set point last received.
        self.command_raw = 0
        #: When the last command frame for this ESC arrived (s), ``None`` before the first.
        self.last_command_s: float | None = None
        #: ``0x700`` frames seen (must stay 0).
        self.id_set_requests = 0
        #: Malformed command frames seen.
        self.malformed = 0
        self._next_feedback_s: float | None = None

    # ----------------------------------------------------------------- hooks

    def _on_frame(self, frame: Frame, now_s: float) -> list[Frame]:
        if frame.arbitration_id == DjiFrameId.QUICK_ID_SET and not frame.is_extended_id:
            self.id_set_requests += 1
            log.warning("ESC %d received 0x700 (quick ID-setting mode)", self.esc_id)
            return []
        try:
            commands = decode_command(frame)
        except DecodeError as err:
            self.malformed += 1
            log.debug("ESC %d ignores %s: %s", self.esc_id, frame.to_cansend(), err)
            return []
        if commands is None or self.esc_id not in commands:
            return []
        fs = self.esc.full_scale_raw
        self.command_raw = min(max(commands[self.esc_id], -fs), fs)
        self.last_command_s = now_s
        self.physics.current_a = self.esc.raw_to_amps(self.command_raw)
        if not self.faults & SimFault.FAULT:
            self.physics.armed = True
        return []

    def _on_tick(self, now_s: float) -> list[Frame]:
        if (
            self.command_timeout_s is not None
            and self.last_command_s is not None
            and now_s - self.last_command_s > self.command_timeout_s
        ):
            self.command_raw = 0
            self.physics.current_a = 0.0
        if self.faults & SimFault.FAULT:
            self.physics.armed = False
        due = self._next_feedback_s = self.due(self._next_feedback_s, now_s,
                                               self.feedback_period_s)
        if now_s < due - 1e-9:
            return []
        self._next_feedback_s = next_due(due, now_s, self.feedback_period_s)
        return [encode_feedback(self.measure())]

    # ----------------------------------------------------------------- measurement

    def measure(self) -> DjiFeedback:
        """What the ESC reports now: quantised like the real encoder and fields."""
        turns = self.physics.position_rad / (2.0 * math.pi)
        angle = math.floor(turns * COUNTS_PER_REV) % COUNTS_PER_REV
        rpm = round(self.physics.velocity_rad_s / RAD_S_PER_RPM)
        current = self.esc.amps_to_raw(self.physics.applied_a) if self.physics.armed else 0
        if not self.esc.reports_temperature:
            temp = 0
        elif self.faults & SimFault.FAULT:
            temp = self.fault_temperature_c
        else:
            temp = self.temperature_c
        return DjiFeedback(
            esc_id=self.esc_id,
            angle_count=angle,
            speed_rpm=min(max(rpm, -_INT16_MAX), _INT16_MAX),
            current_raw=min(max(current, -_INT16_MAX), _INT16_MAX),
            temperature_c=min(max(temp, 0), 0xFF),
        )


def simulator_for(motor: MotorConfig) -> DjiSimulator:
    """A simulated ESC with a current-driven motor for ``motor`` (registered in
    :data:`drivers.BUILTIN_SIMULATORS`): it holds its last current for ever, as the real one is
    assumed to (:mod:`drivers.dji.protection`)."""
    return DjiSimulator(motor)
