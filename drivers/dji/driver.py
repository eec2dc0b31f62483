"""Stateful driver for DJI RoboMaster C620 (M3508) and C610 (M2006) ESCs.

Protocol reference: DJI's `Development-Board-C-Examples
<https://github.com/RoboMaster/Development-Board-C-Examples>`_ (``14.CAN``) and
the RoboMaster C620/C610 user guides' CAN protocol sections.  The wire format lives in
:mod:`drivers.dji.codec`, the motor-block keys in :mod:`drivers.dji.options`.

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

The common ``gear_ratio`` must be set to the gearbox ratio: 3591/187 (~19.2032) for the M3508,
36 for the M2006; ``max_rpm`` is at the rotor (about 9000 for an M3508 at 24 V).

Per cycle (:meth:`DjiDriver._command`, :meth:`DjiDriver._on_frame`) the driver builds no
object but the frames, the feedback and the unpacked fields: the per-motor constants and state
are one :class:`~drivers.dji.axis.Axis` record per motor.
"""

from __future__ import annotations

import logging
import math
from typing import TYPE_CHECKING, ClassVar

from drivers.dji.axis import Axis
from drivers.dji.codec import (
    COMMAND_IDS,
    COUNTS_PER_REV,
    FEEDBACK_HZ,
    HALF_REV_COUNTS,
    RAD_S_PER_RPM,
    DjiFeedback,
    encode_command,
    feedback_fields,
    feedback_id,
    message_name,
)
from drivers.dji.options import DjiOptions
from drivers.dji.position import STEERING_OPTIONS, power_up_position_rad
from drivers.dji.protection import ACTION
from drivers.dji.protection import protection as dji_protection
from gateway.core.errors import ConfigError
from gateway.core.types import DriveFault, WheelFeedback
from gateway.drive.claims import FrameClaim
from gateway.drive.driver import MotorDriver

if TYPE_CHECKING:
    from collections.abc import Sequence

    from gateway.core.protection import Protection
    from gateway.core.types import Frame, MotorConfig
    from gateway.drive.traffic import Traffic

__all__ = ["TEMP_HYSTERESIS_C", "DjiDriver"]

log = logging.getLogger(__name__)

#: The over-temperature flag clears this far below ``max_temp_c`` (degC).
TEMP_HYSTERESIS_C = 5.0
#: Rotor rad per encoder count.
_RAD_PER_COUNT = 2.0 * math.pi / COUNTS_PER_REV


class DjiDriver(MotorDriver[DjiOptions]):
    """Host-side speed control of up to eight C620 / C610 ESCs on one bus.

    :param motors: the motors, ``node_id`` = ESC ID 1..8 (set with the ESC's button).
    :raises ConfigError: for a bad option, a motor block without ``no_controller_stop:
        acknowledged``, a repeated ESC ID, a current limit above the ESC's full scale, a
        steering key in a drive motor's block, or different ``liveness_s`` values.
    """

    Options = DjiOptions
    #: One feedback age for the bus: the speed loop steps every motor on the same clock.
    BUS_WIDE: ClassVar[tuple[str, ...]] = ("liveness_s",)
    NODE_ID_RANGE: ClassVar[tuple[int, int]] = (1, 8)
    HOST_SPEED_LOOP: ClassVar[bool] = True
    STEERING: ClassVar[bool] = True
    MALFORMED: ClassVar[str] = "malformed feedback"
    PROTOCOL: ClassVar[str] = "DJI"
    TIMEOUT_ACTION: ClassVar[str] = ACTION
    #: The ESCs' CAN runs at 1 Mbit/s, fixed (C620 and C610 user guides).
    BITRATES: ClassVar[tuple[int, ...]] = (1_000_000,)

    def __init__(self, motors: Sequence[MotorConfig]) -> None:
        super().__init__(motors)
        for m in self.motors:
            given = sorted(k for k in STEERING_OPTIONS if k in m.options)
            if given and not m.steering:
                raise ConfigError(
                    f"motor {m.wheel!r}.{given[0]}: expected only in a steering actuator's "
                    f"block (steering:), got it in a drive motor's block"
                )
        #: The bus's ``liveness_s`` (one value: :attr:`BUS_WIDE`), read every cycle.
        self._stale_s = self.live.liveness_s
        #: One record per motor, in :attr:`motors` order.
        self._axes: tuple[Axis, ...] = tuple(
            Axis.of(i, m, o, scale)
            for i, (m, o, scale) in enumerate(zip(self.motors, self.opts, self.motor_scale,
                                                  strict=True))
        )
        #: Feedback identifier -> its motor's record: the dispatch of :meth:`_on_frame`.
        self._by_feedback_id = {feedback_id(m.node_id): ax
                                for m, ax in zip(self.motors, self._axes, strict=True)}
        #: The command groups that hold a configured ESC (0: ``0x200``, 1: ``0x1FF``).
        self._groups: tuple[int, ...] = tuple(sorted({ax.group for ax in self._axes}))
        #: The raw current set points of ESC 1..8 (those of unconfigured ESCs stay 0).
        self._raw = [0] * 8
        self._last_command_s: float | None = None

    # ----------------------------------------------------------------- hooks

    def _enable(self, now_s: float) -> list[Frame]:
        """Arm the host-side loops of every motor that is not in fault (no frames).

        A steering actuator's cascade (position loop, then speed loop) is the DJI stand-in for
        a position control mode; it holds the commanded angle from the next :meth:`command`.
        """
        self._reset_loops()
        for i, m in enumerate(self.motors):
            if self.faults(i):
                log.warning("ESC %d (%s) stays disarmed: %s", m.node_id, m.wheel, self.detail(i))
                continue
            self.set_armed(i, True)
        return []

    def disable(self, now_s: float) -> list[Frame]:
        """Disarm every motor; zero-current frames for every group that holds a motor."""
        self._reset_loops()
        raw = self._raw
        for ax in self._axes:
            self.set_armed(ax.index, False)
            ax.current_a = 0.0
            raw[ax.slot] = 0
        return encode_command(raw, self._groups)

    def _command(self, setpoints: Sequence[float], now_s: float) -> list[Frame]:
        """Run every motor's loops once and pack the currents.

        A drive motor's speed loop follows its wheel speed; a steering actuator's position loop
        turns its angle into a rotor-speed target for its speed loop, with the change of the
        target since the previous call as feed-forward (none on the first call after
        :meth:`enable`).  A motor gets zero current (and an empty integrator) unless it is
        ENABLED, i.e. armed, with fresh feedback and no fault.
        """
        live = self.live
        stale_s = self._stale_s
        last = self._last_command_s
        dt = 0.0 if last is None else now_s - last
        if dt < 0.0:
            dt = 0.0
        elif dt > stale_s:
            dt = stale_s
        self._last_command_s = now_s
        # MotorDriver.state written out (no ENABLING here): ENABLED = armed, no fault, alive.
        heard, armed, faults = live.oldest, self._armed, self._faults
        raw = self._raw
        for ax, w in zip(self._axes, setpoints):  # noqa: B905 - the base checked the count
            loop = ax.loop
            if loop is None:
                speed = w * ax.scale
            else:  # a steering actuator: w is an angle, the target a rotor position
                target = ax.zero_rad + w * ax.scale
                previous, ax.last_target_rad = ax.last_target_rad, target
                ff = 0.0 if previous is None or dt <= 0.0 else (target - previous) / dt
                speed = loop.speed_target(target - ax.rotor_rad, ff, ax.rotor_rad_s)
            i = ax.index
            t = heard[i]
            if armed[i] and not faults[i] and t is not None and now_s - t <= stale_s:
                current, ax.integral_a = ax.pi.step(ax.integral_a, speed - ax.rotor_rad_s, dt)
            else:
                current = ax.integral_a = 0.0
            ax.current_a = current
            # EscModel.amps_to_raw written out
            raw[ax.slot] = round(current * ax.full_scale_raw / ax.full_scale_a)
        return encode_command(raw, self._groups)

    def preview_command(self, setpoints: Sequence[float]) -> list[Frame]:
        """The frames :meth:`command` would send for zero measured speed and empty integrators.

        A fresh driver for the same motors, armed, every motor taken as alive and at rest
        (a steering actuator at its neutral angle, rotor at ``zero_rad``, as at power-up), runs
        one first cycle (no feed-forward).  Changes nothing here (for ``frames`` output).

        :raises EncodeError: as :meth:`command`.
        """
        fresh = type(self)(self.motors)
        fresh.enable(0.0)
        for ax in fresh._axes:
            ax.rotor_rad = ax.zero_rad
            fresh.live.heard(ax.index, 0, 0.0)
        return fresh.command(setpoints, 0.0)

    def _on_frame(self, frame: Frame) -> bool:
        """Take a feedback frame of a configured ESC (others are not this driver's).

        :raises DecodeError: for a malformed feedback frame of a configured ESC.
        """
        ax = self._by_feedback_id.get(frame.arbitration_id)
        if ax is None or frame.is_extended_id:  # DJI ESCs use 11-bit IDs: 29-bit is another's
            return False
        fields = ax.fields = feedback_fields(frame)
        t = frame.timestamp_s
        angle = fields[0]
        last = ax.last_count
        if last < 0:  # the first sample
            if ax.loop is not None:
                ax.origin_rad = power_up_position_rad(angle, ax.zero_rad)
        else:
            d = angle - last  # codec.unwrap_delta written out: the shorter way round
            if d > HALF_REV_COUNTS:
                d -= COUNTS_PER_REV
            elif d < -HALF_REV_COUNTS:
                d += COUNTS_PER_REV
            ax.count_sum += d
            if t - ax.last_s > self._stale_s:
                self._resumed(ax, t)
        ax.last_count = angle
        ax.last_s = t
        rotor_rad_s = ax.rotor_rad_s = fields[1] * RAD_S_PER_RPM
        rotor_rad = ax.rotor_rad = ax.origin_rad + ax.count_sum * _RAD_PER_COUNT
        # Wheel side as MotorConfig.motor_to_wheel_rad_s (x * sign / gear); a steering
        # actuator's position as motor_to_steer_rad, from zero_rad (0 for a drive motor).
        self.store_feedback(ax.index, WheelFeedback(
            (rotor_rad - ax.zero_rad) * ax.sign / ax.gear, rotor_rad_s * ax.sign / ax.gear, t
        ))
        if fields[3] > ax.max_temp_c or ax.hot:
            self._temperature(ax, fields[3])
        return True

    def doubts(self) -> tuple[str, ...]:
        """A ``gear_ratio`` of 1.0: the ESCs' motors have gearboxes (3591/187, 36)."""
        return tuple(f"motor {m.wheel!r}: gear_ratio is 1.0; an {ax.esc.motor} needs "
                     f"{ax.esc.gear_ratio:.6g} (its gearbox)"
                     for ax, m in zip(self._axes, self.motors, strict=True)
                     if m.gear_ratio == 1.0)

    def claims(self) -> tuple[FrameClaim, ...]:
        """The feedback of every configured ESC (``0x200 + ESC ID``, 11-bit, its motor's),
        and the command frames this driver sends (``0x200`` / ``0x1FF``, every motor's)."""
        feedback = sorted((feedback_id(m.node_id), i) for i, m in enumerate(self.motors))
        return (
            *(FrameClaim.exact(ident, False, i) for ident, i in feedback),
            *(FrameClaim.exact(COMMAND_IDS[g], False, None, receive=False)
              for g in self._groups),
        )

    def traffic(self, rate_hz: float) -> Traffic:
        """Every ESC's feedback at 1 kHz: fixed in the ESC (the user guides; DJI's examples
        decode it in their CAN receive interrupt), whatever the loop's rate."""
        from gateway.drive.traffic import Sender, Stream, Traffic  # noqa: PLC0415 - check and run only
        return Traffic((Stream("FEEDBACK_ESC", Sender.CONTROLLERS, FEEDBACK_HZ * len(self.motors),
                               8, False, f"{FEEDBACK_HZ:g} Hz each, fixed in the ESC"),))

    def message_name(self, arbitration_id: int, is_extended_id: bool) -> str | None:
        """``COMMAND_ESC_1_4``, ``COMMAND_ESC_5_8`` or ``FEEDBACK_ESC_<n>``
        (:func:`drivers.dji.codec.message_name`); ``None`` for a 29-bit identifier."""
        return None if is_extended_id else message_name(arbitration_id)

    def protection(self, index: int) -> Protection:
        """:attr:`~gateway.core.protection.Guard.NONE`: the ESC has no known command timeout and is
        assumed to hold its last current (:mod:`drivers.dji.protection`)."""
        return dji_protection(self.motors[index])

    # ----------------------------------------------------------------- read-outs

    @property
    def currents_a(self) -> tuple[float, ...]:
        """The currents of the last frames built, per motor (A)."""
        return tuple(ax.current_a for ax in self._axes)

    @property
    def integrals_a(self) -> tuple[float, ...]:
        """The speed loops' integrator states, per motor (A)."""
        return tuple(ax.integral_a for ax in self._axes)

    def measurement(self, index: int) -> DjiFeedback | None:
        """The last decoded feedback of motor ``index`` (raw device units)."""
        ax = self._axes[index]
        if ax.fields is None:
            return None
        angle, speed, current, temp, _reserved = ax.fields
        return DjiFeedback(self.motors[index].node_id, angle, speed, current, temp)

    # ----------------------------------------------------------------- internals

    def _reset_loops(self) -> None:
        for ax in self._axes:
            ax.integral_a = 0.0
            ax.last_target_rad = None
        self._last_command_s = None

    def _resumed(self, ax: Axis, t: float) -> None:
        m = self.motors[ax.index]
        log.warning("ESC %d (%s): feedback resumed after %.3f s; turns made meanwhile are lost",
                    m.node_id, m.wheel, t - ax.last_s)

    def _temperature(self, ax: Axis, temp_c: int) -> None:
        """The host-side over-temperature check of a C620 (a C610's limit is infinite)."""
        i, limit = ax.index, ax.max_temp_c
        if temp_c > limit:
            if not ax.hot:
                m = self.motors[i]
                log.error("ESC %d (%s): %d degC is above max_temp_c %g; disarmed",
                          m.node_id, m.wheel, temp_c, limit)
            ax.hot = True
            self.set_fault(
                i,
                DriveFault.OVER_TEMPERATURE,
                f"temperature {temp_c} degC above max_temp_c {limit:g} (host-side)",
            )
            self.set_armed(i, False)
            ax.integral_a = 0.0
        elif temp_c <= limit - TEMP_HYSTERESIS_C:
            log.info("ESC %d: back to %d degC", self.motors[i].node_id, temp_c)
            ax.hot = False
            self.set_fault(i, DriveFault.NONE)
