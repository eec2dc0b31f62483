"""Stateful driver for DJI RoboMaster C620 (M3508) and C610 (M2006) ESCs.

Protocol reference: DJI's `Development-Board-C-Examples
<https://github.com/RoboMaster/Development-Board-C-Examples>`_ (``14.CAN``) and
the RoboMaster C620/C610 user guides' CAN protocol sections.  The wire format lives in
:mod:`drivers.dji.codec`.

The ESCs take only a current set point, so this driver closes the wheel-speed loop on the host
(:class:`drivers.dji.pi.SpeedPi`, one per motor) every time :meth:`DjiDriver.command` is called,
from the rotor speed in the latest feedback frame.  Call it at a steady rate (DJI's own examples
run at 1 kHz; 100 Hz or more works with the default gains); each call returns one frame per
command group (``0x200`` for ESC 1-4, ``0x1FF`` for ESC 5-8) that holds a configured motor.

Things the protocol does not have, and what the driver does instead:

* **no enable / disable**: :meth:`~DjiDriver.enable` only arms the host-side loop (no frames);
  a disarmed driver sends zero current every cycle; :meth:`~DjiDriver.disable` returns
  zero-current frames, which the gateway must send on shutdown because the ESC holds its last
  set point;
* **no heartbeat**: a motor is OFFLINE when its feedback is older than ``liveness_s``; it then
  gets zero current and its integrator is reset;
* **no fault frame**: over-temperature is a **host-side** check of the temperature byte (C620
  only): above ``max_temp_c`` the motor goes to FAULT (``DriveFault.OVER_TEMPERATURE``) and is
  disarmed; the flag clears once the temperature is back at or below
  ``max_temp_c - TEMP_HYSTERESIS_C``, and :meth:`~DjiDriver.enable` re-arms it;
* ``0x700`` (quick ID setting) is never sent;
* **no known command timeout**: the ESC is assumed to hold its last current, so every motor
  block must say ``no_controller_stop: acknowledged`` (:mod:`drivers.dji.protection`).

**Steering actuators** (``STEERING``): the ESC has no position mode either, so a steering
actuator gets a host-side cascade every cycle: the position loop of
:class:`drivers.dji.position.PositionLoop` (P plus a D term on the error rate, with the
commanded angle's change since the previous cycle as speed feed-forward) gives a rotor-speed
set point, clipped to ``max_rpm``, which the same speed PI as a wheel's turns into the current.
"Arming it in position mode" is arming that cascade (no frames); on a fault, a disable or lost
feedback it gets zero current like every other motor.  The position it follows and reports is
**absolute within one rotor turn only**: the ESC reports the rotor angle 0..8191 within a turn,
so the driver takes the first sample's reading, moved by whole turns to lie within half a turn
of ``zero_rad``, plus the unwrapped change since
(:func:`drivers.dji.position.power_up_position_rad`).  ``zero_rad`` is the rotor's reading at
the wheels' neutral angle (0..2 pi, or any value that differs from it by whole turns).  A geared
actuator must therefore be **powered up with its wheels at the neutral angle, or within half a
rotor turn of it** (``pi / gear_ratio`` at the wheel's plane: 9.4 degrees through an M3508's
gearbox, 5 degrees through an M2006's); powered up further away, every angle is off by whole
rotor turns and nothing detects it.  Turns made while feedback is lost are lost too.

Motor-block keys (``OPTIONS``): ``esc`` (``"c620"`` default, or ``"c610"``), ``kp`` (A per rad/s
of **rotor** speed error, default 0.1), ``ki`` (A per rad of integrated rotor speed error,
default 1.0), ``max_current_a`` (0 = the ESC's full scale: 20 A C620, 10 A C610),
``liveness_s`` (0.1, the same for every motor of the bus), ``max_temp_c`` (80 degC) and the
required ``no_controller_stop: acknowledged``; for a
steering actuator only (an error in a drive motor's block) ``steer_kp`` (default 35 1/s) and
``steer_kd`` (default 0.7), see :data:`drivers.dji.position.STEERING_OPTIONS`.
The common ``gear_ratio`` must be set to the gearbox ratio: 3591/187 (~19.2032) for the M3508,
36 for the M2006; ``max_rpm`` is at the rotor (about 9000 for an M3508 at 24 V).
"""

from __future__ import annotations

import logging
import math
from types import MappingProxyType
from typing import TYPE_CHECKING, ClassVar

from drivers.dji.codec import (
    COUNTS_PER_REV,
    ESC_MODELS,
    RAD_S_PER_RPM,
    DjiCodec,
    DjiFeedback,
    decode_feedback,
    feedback_id,
    unwrap_delta,
)
from drivers.dji.pi import SpeedPi
from drivers.dji.position import STEERING_OPTIONS, PositionLoop, power_up_position_rad
from drivers.dji.protection import ACK_KEY, ACK_OPTION, ACTION, check_acknowledged
from drivers.dji.protection import protection as dji_protection
from drivers.dji.sim import DjiSimulator
from gateway.core.errors import ConfigError, DecodeError, EncodeError
from gateway.core.types import DriveFault, DriveState, WheelFeedback
from gateway.drive.driver import MotorDriver, OptionSpec
from gateway.drive.filters import CanFilter

if TYPE_CHECKING:
    from collections.abc import Mapping, Sequence

    from drivers.dji.codec import EscModel
    from gateway.core.protection import Protection
    from gateway.core.types import Frame, MotorConfig

log = logging.getLogger(__name__)

#: The over-temperature flag clears this far below ``max_temp_c`` (degC).
TEMP_HYSTERESIS_C = 5.0


def _number(opts: Mapping[str, object], key: str) -> float:
    value = opts[key]
    if not isinstance(value, (int, float)):  # validate_options guarantees it
        raise ConfigError(f"{key}: expected a number, got {value!r}")
    return float(value)


class DjiDriver(MotorDriver):
    """Host-side speed control of up to eight C620 / C610 ESCs on one bus.

    :param motors: the motors, ``node_id`` = ESC ID 1..8 (set with the ESC's button).
    :raises ConfigError: for a bad option, a motor block without ``no_controller_stop:
        acknowledged``, a repeated ESC ID, a current limit above the ESC's full scale, or
        different ``liveness_s`` values.
    """

    OPTIONS: ClassVar[Mapping[str, OptionSpec]] = MappingProxyType(
        {
            "esc": OptionSpec(
                str, "c620", choices=tuple(ESC_MODELS), help="ESC type: c620 (M3508), c610 (M2006)"
            ),
            "kp": OptionSpec(
                float, 0.1, minimum=0.0, help="proportional gain, A per rad/s of rotor speed error"
            ),
            "ki": OptionSpec(
                float, 1.0, minimum=0.0, help="integral gain, A per rad of integrated rotor error"
            ),
            "max_current_a": OptionSpec(
                float, 0.0, minimum=0.0, maximum=20.0, help="current limit in A, 0 = full scale"
            ),
            "liveness_s": OptionSpec(
                float, 0.1, minimum=0.001, help="feedback older than this is OFFLINE (s)"
            ),
            "max_temp_c": OptionSpec(
                float, 80.0, minimum=0.0, maximum=255.0, help="C620 over-temperature limit (degC)"
            ),
            ACK_KEY: ACK_OPTION,
            **STEERING_OPTIONS,
        }
    )
    NODE_ID_RANGE: ClassVar[tuple[int, int]] = (1, 8)
    DEFAULT_LIVENESS_S: ClassVar[float] = 0.1
    HOST_SPEED_LOOP: ClassVar[bool] = True
    STEERING: ClassVar[bool] = True
    PROTOCOL: ClassVar[str] = "DJI"
    TIMEOUT_ACTION: ClassVar[str] = ACTION

    def __init__(self, motors: Sequence[MotorConfig]) -> None:
        super().__init__(motors)
        self._esc: list[EscModel] = []
        self._pi: list[SpeedPi] = []
        self._max_temp_c: list[float] = []
        #: Per motor, the position loop of a steering actuator, ``None`` for a drive motor.
        self._position: list[PositionLoop | None] = []
        liveness: set[float] = set()
        for m in self.motors:
            where = f"motor {m.wheel!r}"
            opts = self.validate_options(m.options, where)
            self._position.append(self._position_loop(m, opts, where))
            esc = ESC_MODELS[str(opts["esc"])]
            limit = _number(opts, "max_current_a") or esc.full_scale_a
            if limit > esc.full_scale_a:
                raise ConfigError(
                    f"{where}.max_current_a: expected at most {esc.full_scale_a:g} A for a "
                    f"{esc.name.upper()}, got {limit:g}"
                )
            self._esc.append(esc)
            self._pi.append(SpeedPi(_number(opts, "kp"), _number(opts, "ki"), limit))
            self._max_temp_c.append(_number(opts, "max_temp_c"))
            liveness.add(_number(opts, "liveness_s"))
            if m.gear_ratio == 1.0:
                log.warning(
                    "%s: gear_ratio is 1.0; an %s needs %.6g", where, esc.motor, esc.gear_ratio
                )
        if len(liveness) > 1:
            raise ConfigError(
                f"DJI motors: expected one liveness_s for every motor, got {sorted(liveness)}"
            )
        self.liveness_s = liveness.pop() if liveness else self.DEFAULT_LIVENESS_S
        self.codec = DjiCodec({m.node_id: e for m, e in zip(self.motors, self._esc, strict=True)})
        self._feedback_index = {feedback_id(m.node_id): i for i, m in enumerate(self.motors)}
        n = len(self.motors)
        self._integral_a = [0.0] * n
        self._current_a = [0.0] * n
        self._rotor_rad_s = [0.0] * n
        self._last_count: list[int | None] = [None] * n
        self._count_sum = [0] * n
        #: Rotor position (rad) at the first sample: 0 for a drive motor (its position counts
        #: from there), the absolute power-up position for a steering actuator.
        self._origin_rad = [0.0] * n
        #: Rotor position (rad) of the latest sample, from ``_origin_rad``.
        self._rotor_rad = [0.0] * n
        #: A steering actuator's rotor target of the previous cycle, for the feed-forward.
        self._last_target_rad: list[float | None] = [None] * n
        self._raw: list[DjiFeedback | None] = [None] * n
        self._last_command_s: float | None = None
        #: (speed bound in rad/s, gear ratio, sign, steering) per motor, for the per-cycle
        #: paths.
        self._scale = tuple(
            (m.max_wheel_rad_s * (1.0 + 1e-9), m.gear_ratio, m.sign, m.steering)
            for m in self.motors
        )

    @classmethod
    def validate_options(cls, raw: Mapping[str, object], where: str) -> dict[str, object]:
        """Validate the protocol keys and fill in defaults, except the steering keys.

        ``steer_kp`` and ``steer_kd`` are checked but left out unless given: they mean nothing
        to a drive motor, whose block must not carry them; a steering actuator without them
        gets their defaults when the driver is built.

        :raises ConfigError: for an unknown key, a bad value, or a block without
            ``no_controller_stop: acknowledged``
            (:func:`drivers.dji.protection.check_acknowledged`).
        """
        out = super().validate_options(raw, where)
        check_acknowledged(out, where)
        for key in STEERING_OPTIONS:
            if key not in raw:
                del out[key]
        return out

    @staticmethod
    def _position_loop(
        m: MotorConfig, opts: Mapping[str, object], where: str
    ) -> PositionLoop | None:
        if not m.steering:
            given = sorted(k for k in STEERING_OPTIONS if k in opts)
            if given:
                raise ConfigError(
                    f"{where}.{given[0]}: expected only in a steering actuator's block "
                    f"(steering:), got it in a drive motor's block"
                )
            return None
        return PositionLoop.from_options(opts, m.max_rpm * RAD_S_PER_RPM)

    # ----------------------------------------------------------------- hooks

    def enable(self, now_s: float) -> list[Frame]:
        """Arm the host-side loops of every motor that is not in fault (no frames).

        A steering actuator's cascade (position loop, then speed loop) is the DJI stand-in for
        a position control mode; it holds the commanded angle from the next :meth:`command`.
        """
        self._reset_loops()
        for i, m in enumerate(self.motors):
            if self._faults[i]:
                log.warning("ESC %d (%s) stays disarmed: %s", m.node_id, m.wheel, self._detail[i])
                continue
            self.set_armed(i, True)
        return []

    def disable(self, now_s: float) -> list[Frame]:
        """Disarm every motor; zero-current frames for every group that holds a motor."""
        self._reset_loops()
        for i in range(len(self.motors)):
            self.set_armed(i, False)
        return self._frames([0.0] * len(self.motors))

    def command(self, wheel_rad_s: Sequence[float], now_s: float) -> list[Frame]:
        """Run every motor's loops once and pack the currents.

        A drive motor's speed loop follows its wheel speed; a steering actuator's position loop
        turns its angle into a rotor-speed target for its speed loop, with the change of the
        target since the previous call as feed-forward (none on the first call after
        :meth:`enable`).  A motor gets zero current (and an empty integrator) unless it is
        ENABLED, i.e. armed, with fresh feedback and no fault.

        :param wheel_rad_s: one setpoint per motor: a drive motor's wheel speed in rad/s within
            ``max_rpm``, a steering actuator's steering angle in rad.
        :raises EncodeError: for a wrong number of setpoints, a speed that is not finite or
            above the motor's ``max_rpm``, or a steering angle that is not finite.
        """
        targets = self._rotor_targets(wheel_rad_s)
        dt = 0.0 if self._last_command_s is None else now_s - self._last_command_s
        dt = min(max(dt, 0.0), self.liveness_s)
        self._last_command_s = now_s
        currents = []
        for i, target in enumerate(targets):
            speed = target
            loop = self._position[i]
            if loop is not None:  # a steering actuator: target is a rotor position
                last, self._last_target_rad[i] = self._last_target_rad[i], target
                ff = 0.0 if last is None or dt <= 0.0 else (target - last) / dt
                speed = loop.speed_target(target - self._rotor_rad[i], ff, self._rotor_rad_s[i])
            if self.state(i, now_s) is not DriveState.ENABLED:
                self._integral_a[i] = 0.0
                currents.append(0.0)
                continue
            current, self._integral_a[i] = self._pi[i].step(
                self._integral_a[i], speed - self._rotor_rad_s[i], dt
            )
            currents.append(current)
        return self._frames(currents)

    def preview_command(self, wheel_rad_s: Sequence[float]) -> list[Frame]:
        """The frames :meth:`command` would send for zero measured speed and empty integrators.

        A steering actuator is assumed at rest at its neutral angle (rotor at ``zero_rad``,
        as at power-up) with no feed-forward (a first cycle).  Pure: ignores armed state and
        feedback and changes nothing (for ``frames`` output).

        :raises EncodeError: as :meth:`command`.
        """
        targets = self._rotor_targets(wheel_rad_s)
        currents = []
        for m, loop, pi, target in zip(self.motors, self._position, self._pi, targets, strict=True):
            speed = target if loop is None else loop.speed_target(target - m.zero_rad, 0.0, 0.0)
            currents.append(pi.preview(speed))
        return list(self.codec.encode_command(self._raw_currents(currents)))

    def receive_filters(self) -> tuple[CanFilter, ...]:
        """The feedback identifiers of the configured ESCs (``0x200 + ESC ID``, 11-bit)."""
        return tuple(CanFilter.exact(i, False) for i in sorted(self._feedback_index))

    def on_frame(self, frame: Frame) -> bool:
        """Take a feedback frame of a configured ESC (others are not this driver's).

        :return: whether it was the feedback ID of a configured ESC; malformed ones are
            counted in :attr:`rejected`.
        """
        if frame.is_extended_id:
            return False  # DJI ESCs use 11-bit IDs; a 29-bit frame is another device's
        index = self._feedback_index.get(frame.arbitration_id)
        if index is None:
            return False
        try:
            fb = decode_feedback(frame)  # what self.codec.decode does, one call less per frame
        except DecodeError as err:
            self.reject("malformed feedback", err)
            return True
        if fb is None:  # cannot happen for a feedback ID; keeps mypy honest
            return False
        self._take_feedback(index, fb, frame.timestamp_s)
        return True

    @classmethod
    def make_simulator(cls, motor: MotorConfig) -> DjiSimulator:
        """A simulated ESC with a current-driven motor for ``motor``: it holds its last current
        for ever, as the real one is assumed to (:mod:`drivers.dji.protection`)."""
        return DjiSimulator(motor)

    def protection(self, index: int) -> Protection:
        """:attr:`~gateway.core.protection.Guard.NONE`: the ESC has no known command timeout and is
        assumed to hold its last current (:mod:`drivers.dji.protection`)."""
        return dji_protection(self.motors[index])

    # ----------------------------------------------------------------- read-outs

    @property
    def currents_a(self) -> tuple[float, ...]:
        """The currents of the last frames built, per motor (A)."""
        return tuple(self._current_a)

    def measurement(self, index: int) -> DjiFeedback | None:
        """The last decoded feedback of motor ``index`` (raw device units)."""
        return self._raw[index]

    # ----------------------------------------------------------------- internals

    def _reset_loops(self) -> None:
        self._integral_a = [0.0] * len(self.motors)
        self._last_target_rad = [None] * len(self.motors)
        self._last_command_s = None

    def _rotor_targets(self, wheel_rad_s: Sequence[float]) -> list[float]:
        """Rotor speed (drive motor) or rotor position (steering actuator) targets, rad(/s)."""
        if len(wheel_rad_s) != len(self.motors):
            what = "setpoints" if any(m.steering for m in self.motors) else "wheel speeds"
            raise EncodeError(
                f"Expected {len(self.motors)} {what} for the DJI motors, "
                f"but got {len(wheel_rad_s)}."
            )
        out: list[float] = []
        # Per-motor constants from __init__; the same arithmetic as m.max_wheel_rad_s and
        # m.wheel_to_motor_rad_s(w) (w * gear * sign).
        for (bound, gear, sign, steer), w in zip(self._scale, wheel_rad_s, strict=True):
            if steer:
                m = self.motors[len(out)]
                if not math.isfinite(w):
                    raise EncodeError(
                        f"Expected a finite steering angle in rad for node {m.node_id} "
                        f'("{m.wheel}"), but got {w}.'
                    )
                out.append(m.steer_to_motor_rad(w))
                continue
            if not (math.isfinite(w) and abs(w) <= bound):
                m = self.motors[len(out)]
                lim = m.max_wheel_rad_s
                raise EncodeError(
                    f'Expected velocity for node {m.node_id} ("{m.wheel}") between '
                    f"{-lim:.4g} and {lim:.4g} rad/s, but got {w}."
                )
            out.append(w * gear * sign)
        return out

    def _raw_currents(self, currents_a: Sequence[float]) -> dict[int, int]:
        rows = zip(self.motors, self._esc, currents_a, strict=True)
        return {m.node_id: esc.amps_to_raw(a) for m, esc, a in rows}

    def _frames(self, currents_a: list[float]) -> list[Frame]:
        self._current_a = list(currents_a)
        return list(self.codec.encode_command(self._raw_currents(currents_a)))

    def _take_feedback(self, i: int, fb: DjiFeedback, t: float) -> None:
        m = self.motors[i]
        last = self._last_count[i]
        if last is not None:
            prev = self._feedback[i]
            if prev is not None and t - prev.timestamp_s > self.liveness_s:
                log.warning(
                    "ESC %d (%s): feedback resumed after %.3f s; turns made meanwhile are lost",
                    m.node_id,
                    m.wheel,
                    t - prev.timestamp_s,
                )
            self._count_sum[i] += unwrap_delta(last, fb.angle_count)
        elif m.steering:
            self._origin_rad[i] = power_up_position_rad(fb.angle_count, m.zero_rad)
        self._last_count[i] = fb.angle_count
        self._raw[i] = fb
        rotor_rad_s = self._rotor_rad_s[i] = fb.speed_rpm * RAD_S_PER_RPM
        rotor_rad = self._rotor_rad[i] = (
            self._origin_rad[i] + self._count_sum[i] * 2.0 * math.pi / COUNTS_PER_REV
        )
        _, gear, sign, steer = self._scale[i]
        # Wheel side as m.motor_to_wheel_rad_s: x * sign / gear; a steering actuator's
        # position as m.motor_to_steer_rad: from zero_rad.
        position = (rotor_rad - m.zero_rad if steer else rotor_rad) * sign / gear
        self._feedback[i] = WheelFeedback(position, rotor_rad_s * sign / gear, t)
        if self._esc[i].reports_temperature:
            self._check_temperature(i, fb)

    def _check_temperature(self, i: int, fb: DjiFeedback) -> None:
        if not self._esc[i].reports_temperature:
            return
        limit = self._max_temp_c[i]
        if fb.temperature_c > limit:
            if not self._faults[i]:
                m = self.motors[i]
                log.error(
                    "ESC %d (%s): %d degC is above max_temp_c %g; disarmed",
                    m.node_id,
                    m.wheel,
                    fb.temperature_c,
                    limit,
                )
            self.set_fault(
                i,
                DriveFault.OVER_TEMPERATURE,
                f"temperature {fb.temperature_c} degC above max_temp_c {limit:g} (host-side)",
            )
            self.set_armed(i, False)
            self._integral_a[i] = 0.0
        elif self._faults[i] and fb.temperature_c <= limit - TEMP_HYSTERESIS_C:
            log.info("ESC %d: back to %d degC", self.motors[i].node_id, fb.temperature_c)
            self.set_fault(i, DriveFault.NONE)
