"""The stateful VESC driver: wheel rad/s to eRPM, tachometer odometry, liveness.

Protocol reference: https://github.com/vedderb/bldc/blob/master/documentation/comm_can.md and
``comm/comm_can.c``; the frames are built and parsed by :mod:`drivers.vesc.codec`, the units
converted per motor by :mod:`drivers.vesc.axis`.

Behaviour that follows from the protocol:

* **No enable or arm state.**  A VESC drives the motor on any valid command.  :meth:`enable`
  reads every VESC's timeout back (below), and arms each motor -- starts its command stream,
  SET_RPM 0 -- once its read ended and :meth:`may_arm`; :meth:`disable` sends SET_CURRENT 0,
  which releases the motor (below ``cc_min_current`` the firmware stops switching), and stops
  the streams.  A motor reads ENABLING after :meth:`enable` until it is armed and both status
  frames have arrived again, then ENABLED.
* **Controller-side protection (stated, read back).**  The VESC releases the motor, which
  coasts, when no command arrives for its app configuration's ``timeout_msec`` (VESC Tool: App
  Settings > General > Timeout; 1000 ms from the factory, ``applications/appconf_default.h``;
  brake current ``timeout_brake_current``, 0 A; ``timeout.c``).  It is written only with the
  whole app configuration, so wheelgate does not set it: the configuration states it as
  ``controller_timeout_s`` (:meth:`protection`: STATED, or UNSTATED with a warning when 0, the
  default), and :meth:`enable` reads it back with COMM_GET_APPCONF (:mod:`drivers.vesc.appconf`)
  and checks it (:mod:`drivers.vesc.readback`, which says the policy).
* **Keep-alive.**  :meth:`command` sends SET_RPM on every call.  :meth:`poll` resends the last
  command once ``command_period_s`` has passed since the last send, so a caller that ticks
  :meth:`poll` at :attr:`VescDriver.keepalive_period_s` keeps the motor running even when
  commands come slower.  If neither is called within the VESC's timeout (the gateway stalled
  or died), the VESC stops the motor by itself.  ``command_period_s`` must be less than half
  that timeout (the stated one, else the factory 1 s) so that one lost frame cannot release
  the motor.
* **Minimum ERPM.**  Below ``s_pid_min_erpm`` (``min_erpm``, 900 from the factory) a VESC does
  not speed-control: a stopped motor stays stopped, a running one brakes to a stop
  (:mod:`drivers.vesc.min_erpm`).  Such commands go out as they are -- the device's own
  setting decides, and a statement the gateway cannot verify must not stop a wheel the device
  would drive -- and are counted (:attr:`command_counts` ``below_min_erpm``) and logged at
  most once per 5 s.  :meth:`uncontrolled_band` gives the wheel speeds concerned.
* **Feedback.**  Velocity comes from STATUS (eRPM), position from the STATUS_5 tachometer
  (6 steps per electrical revolution, int32, unwrapped modulo 2**32 so odometry is exact to one
  step).  Both streams are needed (:attr:`LIVENESS_STREAMS`); the VESC sends neither until they
  are ticked in VESC Tool (App Settings > General: Can Messages Rate 1, Status 1 and Status 5;
  ``can_status_msgs_r1`` bits 0 and 4; none from the factory, and the motor setup wizard ticks
  Status 1 to 4 only).  A motor missing a stream says so in its status detail, and the driver
  logs it once after enable.  ``status_rate_hz`` states the rate that was set (Can Status
  Rate 1).
* **Faults.**  The simple status frames carry no fault code (that takes COMM_GET_VALUES over
  the multi-frame buffer protocol, not implemented).  A VESC fault releases the motor, makes the
  firmware ignore commands for ``m_fault_stop_time_ms`` and then clears itself; the gateway sees
  only the motor not following.  What the driver does detect is silence: a motor whose STATUS
  or STATUS_5 stream is older than ``liveness_s`` is OFFLINE.  FAULT is never reported.
* **Controller reset.**  A power-cycled VESC restarts its tachometer at 0 unannounced; the
  odometry takes the step for a jump, not motion (:mod:`gateway.core.odom_feed`).
"""

from __future__ import annotations

import dataclasses
import logging
import math
from typing import TYPE_CHECKING, ClassVar

from drivers.vesc import settings
from drivers.vesc.appconf import HOST_ID
from drivers.vesc.axis import Axis
from drivers.vesc.codec import arbitration_id, make_set_current, make_set_rpm, unpack_status
from drivers.vesc.frames import (
    RECEIVED,
    STATUS,
    STATUS_5,
    UNUSED,
    claims,
    message_name,
    pong_is_ours,
    status_traffic,
)
from drivers.vesc.min_erpm import BELOW_MIN_ERPM, BandWatch, doubt, uncontrolled_band
from drivers.vesc.readback import Outcome, TimeoutReadback, Wanted, read_protection
from drivers.vesc.settings import VescOptions
from gateway.core.protection import Guard, Protection, ProtectionState
from gateway.core.types import DriveState, WheelFeedback
from gateway.drive.driver import MotorDriver

if TYPE_CHECKING:
    from collections.abc import Mapping, Sequence

    from drivers.vesc.codec import VescStatus, VescStatus5
    from gateway.core.types import Frame, MotorConfig
    from gateway.drive.claims import FrameClaim
    from gateway.drive.traffic import Traffic

log = logging.getLogger(__name__)


class VescDriver(MotorDriver[VescOptions]):
    """Every VESC on one bus, commanded in electrical RPM.

    :param motors: the motor blocks, each with ``driver: vesc`` and its protocol keys.
    :raises ConfigError: for a node ID outside 0..254, a node ID used twice, or bad options.
    """

    Options = VescOptions
    #: VESC controller IDs; 255 is broadcast.
    NODE_ID_RANGE: ClassVar[tuple[int, int]] = (0, 254)
    #: A motor is OFFLINE while either status stream is older than ``liveness_s``.
    LIVENESS_STREAMS: ClassVar[tuple[str, ...]] = ("STATUS", "STATUS_5")
    STREAM_HINTS: ClassVar[Mapping[str, str]] = settings.STREAM_HINTS
    SPEED_STREAM: ClassVar[int | None] = STATUS
    #: After :meth:`enable`, how long status frames may be missing before the hint is logged.
    STATUS_HINT_AFTER_S: ClassVar[float] = 1.0
    PROTOCOL: ClassVar[str] = "VESC"
    TIMEOUT_ACTION: ClassVar[str] = settings.TIMEOUT_ACTION
    TIMEOUT_FIX: ClassVar[str] = settings.TIMEOUT_FIX
    #: Seconds between two log lines about commands below ``min_erpm``.
    BAND_LOG_EVERY_S: ClassVar[float] = 5.0
    #: The timeout is read back while enabling, and a wrong one is a failed protection.
    CONFIGURES_PROTECTION: ClassVar[bool] = True

    def __init__(self, motors: Sequence[MotorConfig]) -> None:
        super().__init__(motors)
        self._axes = tuple(
            Axis.of(i, m, o, s)
            for i, (m, o, s) in enumerate(zip(self.motors, self.opts, self.motor_scale,
                                              strict=True))
        )
        #: Identifier of a status frame of ours -> (its motor, its stream or UNUSED).
        self._routes = {
            arbitration_id(packet, a.node_id): (a, use)
            for a in self._axes for packet, use in RECEIVED
        }
        self._enabled = self._settling = False
        self._enabled_at_s: float | None = None
        self._band_watch = BandWatch(self.BAND_LOG_EVERY_S)
        #: The timeout reads; none when a VESC has the gateway's own ID (its replies' ID).
        self.readback = None if HOST_ID in self._index else TimeoutReadback(
            [Wanted(a.node_id, o.controller_timeout_s, o.command_period_s)
             for a, o in zip(self._axes, self.opts, strict=True)])
        for a in self._axes:
            self.set_fault(a.index, self.faults(a.index), a.missing())

    @classmethod
    def validate_options(cls, raw: Mapping[str, object], where: str) -> dict[str, object]:
        """Validate the protocol keys (:class:`~drivers.vesc.settings.VescOptions`), then check
        ``command_period_s`` against the VESC's timeout and ``liveness_s`` against the stated
        status rate; raises :class:`ConfigError` for an unknown, missing or bad key
        (``timeout_s`` with its new name), a keep-alive period too long for the VESC's
        timeout, or a liveness time shorter than two status periods."""
        out = super().validate_options(raw, where)
        VescOptions.from_block(out, where)  # the keys against each other
        return out

    # ----------------------------------------------------------------- protection

    def protection(self, index: int) -> Protection:
        """STATED from ``controller_timeout_s``; else UNSTATED, saying what is known (the
        factory timeout) and how to state it; with what the last enable read back."""
        prot = super().protection(index)
        if prot.guard is Guard.UNSTATED:
            prot = dataclasses.replace(prot, how=settings.UNSTATED_HOW)
        rb = self.readback
        return prot if rb is None else read_protection(prot, rb.results[index], rb.wanted[index])

    def protection_state(self, index: int) -> ProtectionState:
        """PENDING until the timeout was read back (the read gave up: NOT_APPLICABLE); CONFIRMED
        as stated; FAILED when it differs; kept over a disable (:mod:`drivers.vesc.readback`)."""
        rb = self.readback
        return ProtectionState.NOT_APPLICABLE if rb is None else rb.results[index].state

    def protection_failure(self, index: int) -> str:
        """What the VESC's timeout read back as, against what it must be."""
        why = self.readback.results[index].why if self.readback is not None else ""
        return why or super().protection_failure(index)

    def doubts(self) -> tuple[str, ...]:
        """A motor whose VESC speed-controls none of the speeds it may be commanded
        (:func:`drivers.vesc.min_erpm.doubt`)."""
        return tuple(d for i, (m, o) in enumerate(zip(self.motors, self.opts, strict=True))
                     if (d := doubt(m, o.min_erpm, o.pole_pairs, self.uncontrolled_band(i))))

    def uncontrolled_band(self, index: int) -> tuple[float, float] | None:
        """The wheel speeds (rad/s) motor ``index``'s VESC does not speed-control: ``(0.0,
        high)`` for every speed with ``0 < |speed| < high`` (``high`` is ``min_erpm`` at the
        wheel); ``None`` when ``min_erpm`` is 0 (:mod:`drivers.vesc.min_erpm`)."""
        o = self.opts[index]
        return uncontrolled_band(o.min_erpm, o.pole_pairs, self.motors[index].gear_ratio)

    # ----------------------------------------------------------------- units

    @property
    def keepalive_period_s(self) -> float:
        """Call :meth:`poll` at least this often (s) to keep every VESC from timing out."""
        return min((o.command_period_s for o in self.opts), default=math.inf)

    def erpm_for(self, index: int, wheel_rad_s: float) -> int:
        """The SET_RPM value for a wheel speed of motor ``index`` (within its ``max_rpm``,
        which :meth:`command` checks)."""
        return round(wheel_rad_s * self._axes[index].erpm_per_rad_s)

    def wheel_rad_for(self, index: int, steps: int) -> float:
        """The wheel angle in rad for ``steps`` tachometer steps of motor ``index``."""
        return steps * self._axes[index].rad_per_step

    # ----------------------------------------------------------------- commands

    def _enable(self, now_s: float) -> list[Frame]:
        """Read the timeouts back (the first request), or, when the gateway's ID is a VESC's,
        start every command stream at once: SET_RPM 0 (VESC has no arm state)."""
        self._enabled = True
        self._enabled_at_s = now_s
        for a in self._axes:
            a.erpm = 0
            a.sent_s = None
            a.hinted = False
            self.set_armed(a.index, False)
        if self.readback is None:
            log.warning("VESC: a motor has ID %d, the gateway's own: the VESCs' timeouts are "
                        "not read back", HOST_ID)
            return [f for a in self._axes for f in self._arm(a, now_s)]
        self._settling = True
        return self.readback.start(now_s)

    def _arm(self, a: Axis, now_s: float) -> list[Frame]:
        """Arm motor ``a``: start its command stream with SET_RPM 0."""
        self.set_armed(a.index, True)
        a.sent_s = now_s
        return [make_set_rpm(a.node_id, 0)]

    def _settle(self, now_s: float) -> list[Frame]:
        """Arm each motor whose read ended, if :meth:`may_arm` (the base reports a failure)."""
        rb, out = self.readback, []
        assert rb is not None
        for a in self._axes:
            r = rb.results[a.index]
            if self.is_armed(a.index) or r.outcome is Outcome.PENDING or not self.may_arm(a.index):
                continue
            if r.outcome is Outcome.NOT_READ:
                log.warning("VESC %d (%r): timeout not read back, arming it as stated: %s",
                            a.node_id, a.wheel, r.why)
            else:
                log.info("VESC %d (%r): timeout_msec read back: %s ms (%s); arming",
                         a.node_id, a.wheel, r.read_ms, r.outcome.value)
            out += self._arm(a, now_s)
        self._settling = any(r.outcome is Outcome.PENDING for r in rb.results)
        return out

    def preview_command(self, setpoints: Sequence[float]) -> list[Frame]:
        """The frames of :meth:`command` from a fresh driver whose timeouts read back as
        stated (every motor armed)."""
        fresh = type(self)(self.motors)
        fresh.enable(0.0)
        _ = [fresh._arm(a, 0.0) for a in fresh._axes]
        return fresh.command(setpoints, 0.0)

    def disable(self, now_s: float) -> list[Frame]:
        """SET_CURRENT 0 to every motor, which releases it, and stop the command stream."""
        self._enabled = False
        self._enabled_at_s = None
        if self.readback is not None:  # (cancels a read under way; the reads done stand)
            self.readback.stop()
        for a in self._axes:
            a.erpm = 0
            a.sent_s = None
            self.set_armed(a.index, False)
        return [make_set_current(a.node_id, 0.0) for a in self._axes]

    def _command(self, setpoints: Sequence[float], now_s: float) -> list[Frame]:
        """SET_RPM for every armed motor; nothing while disabled."""
        if not self._enabled:
            return []
        out = []
        armed = self._armed
        for a, wheel_rad_s in zip(self._axes, setpoints):  # noqa: B905 - the base checked
            if not armed[a.index]:
                continue
            erpm = round(wheel_rad_s * a.erpm_per_rad_s)  # erpm_for, inlined (every cycle)
            if erpm and -a.min_erpm < erpm < a.min_erpm:  # min_erpm.in_band, inlined
                self._below_min_erpm(a, erpm, now_s)
            a.erpm = erpm
            a.sent_s = now_s
            out.append(make_set_rpm(a.node_id, erpm))
        return out

    def _below_min_erpm(self, a: Axis, erpm: int, now_s: float) -> None:
        """Count (and at most every :attr:`BAND_LOG_EVERY_S` log) a command in the band."""
        self.command_counts[BELOW_MIN_ERPM] += 1
        line = self._band_watch.note(a.node_id, a.wheel, erpm, a.min_erpm, now_s)
        if line is not None:
            log.warning("%s", line)

    def _poll(self, now_s: float) -> list[Frame]:
        """The timeout reads' requests, then arming; resend the last command to every armed
        motor not commanded for ``command_period_s``."""
        out: list[Frame] = []
        if not self._enabled:
            return out
        rb = self.readback
        if rb is not None and self._settling:  # (until every read ended: not every cycle)
            out += rb.poll(now_s)
            out += self._settle(now_s)
        for a in self._axes:
            if a.sent_s is None:
                continue  # not armed
            if now_s - a.sent_s >= a.command_period_s:
                a.sent_s = now_s
                out.append(make_set_rpm(a.node_id, a.erpm))
            if not a.hinted and (a.status_s is None or a.status5_s is None):
                self._hint(a, now_s)  # (once both streams were seen, it has nothing to say)
        return out

    def _hint(self, a: Axis, now_s: float) -> None:
        """Log, once per enable and :attr:`STATUS_HINT_AFTER_S` after it, what a motor has
        never sent."""
        since = self._enabled_at_s
        if since is None or now_s - since < self.STATUS_HINT_AFTER_S:
            return
        missing = a.missing()
        if missing:
            a.hinted = True
            log.warning("VESC %d (%r), %.1f s after enable: %s (and check that it is on the "
                        "bus in CAN_MODE_VESC with this ID)", a.node_id, a.wheel, now_s - since,
                        missing)

    # ----------------------------------------------------------------- frames

    def claims(self) -> tuple[FrameClaim, ...]:
        """The frames of our VESCs (:func:`drivers.vesc.frames.claims`)."""
        return claims([a.node_id for a in self._axes], self.readback is not None)

    def message_name(self, arbitration_id: int, is_extended_id: bool) -> str | None:
        """The ``CAN_PACKET_ID`` name of a VESC frame (:func:`drivers.vesc.frames.message_name`)."""
        return message_name(arbitration_id, is_extended_id)

    def traffic(self, rate_hz: float) -> Traffic:
        """The stated status frames (:func:`drivers.vesc.frames.status_traffic`)."""
        return status_traffic(self.opts)

    def _on_frame(self, frame: Frame) -> bool:
        """Take the frames our VESCs send: STATUS and STATUS_5 (used), STATUS_2/3/4/6 and a
        PONG naming one of them (taken, unused).

        :raises DecodeError: for a STATUS or STATUS_5 of ours, or a PONG to one of our IDs,
            that is a remote frame or has the wrong length.
        """
        route = self._routes.get(frame.arbitration_id)
        if route is None or not frame.is_extended_id:
            rb = self.readback
            return (rb is not None and rb.on_frame(frame)) or pong_is_ours(frame, self.index_of)
        a, stream = route
        if stream == UNUSED:
            return True  # ours, but nothing the gateway uses
        fields = unpack_status(frame)
        t = frame.timestamp_s
        i = a.index
        heard = self.live.heard
        if stream == STATUS:
            first = a.status_s is None
            a.status, a.status_s = fields, t
            a.velocity_rad_s = fields[0] * a.rad_s_per_erpm
            heard(i, STATUS, t)
            other = a.status5_s
        else:
            first = a.status5_s is None
            if not first:  # wrap_int32 of the difference, inlined (every frame)
                a.steps += (fields[0] - a.status5[0] + 0x80000000) % 0x100000000 - 0x80000000
                a.position_rad = a.steps * a.rad_per_step
            a.status5, a.status5_s = fields, t
            heard(i, STATUS_5, t)
            other = a.status_s
        if other is None:  # one stream only: no feedback yet
            if first:
                self.set_fault(i, self.faults(i), a.missing())
            return True
        # Stamped with the position's time (a STATUS refreshes the speed only); each stream
        # was heard above at its own time.
        pos_s = other if stream == STATUS else t
        self.store_feedback(i, WheelFeedback(a.position_rad, a.velocity_rad_s, pos_s), None)
        if first:
            self.set_fault(i, self.faults(i), a.missing())
        return True

    # ----------------------------------------------------------------- state

    def _ready_state(self, index: int) -> DriveState:
        """ENABLING after :meth:`enable` until both status streams were heard again; then
        ENABLED; DISABLED when not enabled.  Never FAULT (see the module)."""
        if not self._enabled:
            return DriveState.DISABLED
        if not self._armed[index]:
            return DriveState.ENABLING  # its timeout is being read back
        since, oldest = self._enabled_at_s, self.live.oldest[index]
        if since is not None and oldest is not None and oldest < since:
            return DriveState.ENABLING
        return DriveState.ENABLED

    def last_status(self, index: int) -> VescStatus | None:
        """The latest STATUS of motor ``index`` (current and duty), or ``None``."""
        return self._axes[index].last_status()

    def last_status5(self, index: int) -> VescStatus5 | None:
        """The latest STATUS_5 of motor ``index`` (tachometer and input voltage), or ``None``."""
        return self._axes[index].last_status5()
