"""The stateful VESC driver: wheel rad/s to eRPM, tachometer odometry, liveness.

Protocol reference: https://github.com/vedderb/bldc/blob/master/documentation/comm_can.md and
``comm/comm_can.c`` (section 2 of ``can-protocols.md``); the frames are built and parsed by
:mod:`drivers.vesc.codec`.

Behaviour that follows from the protocol:

* **No enable or arm state.**  A VESC drives the motor on any valid command.  :meth:`enable`
  therefore only starts the command stream (SET_RPM 0 to every motor) and marks the driver
  enabled; :meth:`disable` sends SET_CURRENT 0, which releases the motor (below
  ``cc_min_current`` the firmware stops switching), and stops the stream.  A motor reads
  ENABLING after :meth:`enable` until both status frames have arrived again, then ENABLED.
* **Controller-side protection (stated).**  The VESC releases the motor, which coasts, when no
  command arrives for its app configuration's ``timeout_msec`` (VESC Tool: App Settings >
  General > Timeout; 1000 ms from the factory, ``applications/appconf_default.h``; brake
  current ``timeout_brake_current``, 0 A; ``timeout.c``).  It is written only with the whole
  app configuration, not by a simple CAN command, so wheelgate can neither set nor read it:
  the configuration states it as ``controller_timeout_s`` (:meth:`protection`: STATED, or
  UNSTATED with a warning when 0, the default).
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
  step).  Both streams are needed; the VESC sends neither until they are ticked in VESC Tool
  (App Settings > General: Can Messages Rate 1, Status 1 and Status 5; ``can_status_msgs_r1``
  bits 0 and 4; none from the factory, and the motor setup wizard ticks Status 1 to 4 only).
  A motor missing a stream says so in its status detail, and the driver logs it once after
  enable.  ``status_rate_hz`` states the rate that was set (Can Status Rate 1).
* **Faults.**  The simple status frames carry no fault code (that takes COMM_GET_VALUES over
  the multi-frame buffer protocol, not implemented).  A VESC fault releases the motor, makes the
  firmware ignore commands for ``m_fault_stop_time_ms`` and then clears itself; the gateway sees
  only the motor not following.  What the driver does detect is silence: a motor whose STATUS
  or STATUS_5 stream is older than ``liveness_s`` is OFFLINE.  FAULT is never reported.
* **Controller reset.**  A power-cycled VESC restarts its tachometer at 0; the protocol does not
  say so, and the unwrap takes the jump as motion.  Re-create the driver after a reset.
"""

from __future__ import annotations

import collections
import dataclasses
import logging
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar, cast

from drivers.vesc.codec import (
    RPM_PER_RAD_S,
    TACHO_STEPS_PER_EREV,
    CanPacketId,
    VescStatus,
    VescStatus5,
    decode,
    make_set_current,
    make_set_rpm,
    wrap_int32,
)
from drivers.vesc.min_erpm import BELOW_MIN_ERPM, BandWatch, uncontrolled_band
from drivers.vesc.settings import (
    FACTORY_STATUS_MSGS,
    FACTORY_STATUS_RATE_HZ,
    FACTORY_TIMEOUT_S,
    OPTIONS,
    STATUS_1,
    STATUS_5,
    TIMEOUT_ACTION,
    TIMEOUT_FIX,
    UNSTATED_HOW,
    check_options,
    check_validated,
    missing_status,
)
from drivers.vesc.sim import VescSimulator
from gateway.core.errors import DecodeError, EncodeError
from gateway.core.protection import Guard, Protection
from gateway.core.types import DriveState, WheelFeedback
from gateway.drive.driver import MotorDriver
from gateway.drive.filters import CanFilter

if TYPE_CHECKING:
    from collections.abc import Mapping, Sequence

    from gateway.core.options import OptionSpec
    from gateway.core.types import Frame, MotorConfig
    from gateway.sim.device import DeviceSimulator

log = logging.getLogger(__name__)

#: Status packets a VESC may send that this driver does not decode.
_UNUSED_STATUS = frozenset(
    {CanPacketId.STATUS_2, CanPacketId.STATUS_3, CanPacketId.STATUS_4, CanPacketId.STATUS_6}
)
#: Every status packet :meth:`VescDriver.on_frame` takes, in packet order.
_RECEIVED_STATUS = tuple(sorted({CanPacketId.STATUS, CanPacketId.STATUS_5, *_UNUSED_STATUS}))


@dataclass(frozen=True, slots=True)
class _Options:
    pole_pairs: int
    command_period_s: float
    liveness_s: float
    min_erpm: float


@dataclass(slots=True)
class _Track:
    """What the driver keeps per motor."""

    erpm: int = 0
    sent_s: float | None = None
    tacho: int | None = None
    steps: int = 0
    velocity_rad_s: float = 0.0
    status: VescStatus | None = None
    status_s: float | None = None
    status5: VescStatus5 | None = None
    status5_s: float | None = None
    hinted: bool = False


class VescDriver(MotorDriver):
    """Every VESC on one bus, commanded in electrical RPM.

    :param motors: the motor blocks, each with ``driver: vesc`` and its protocol keys.
    :raises ConfigError: for a node ID outside 0..254, a node ID used twice, or bad options.
    """

    OPTIONS: ClassVar[Mapping[str, OptionSpec]] = OPTIONS
    #: VESC controller IDs; 255 is broadcast.
    NODE_ID_RANGE: ClassVar[tuple[int, int]] = (0, 254)
    #: After :meth:`enable`, how long status frames may be missing before the hint is logged.
    STATUS_HINT_AFTER_S: ClassVar[float] = 1.0
    PROTOCOL: ClassVar[str] = "VESC"
    TIMEOUT_ACTION: ClassVar[str] = TIMEOUT_ACTION
    TIMEOUT_FIX: ClassVar[str] = TIMEOUT_FIX
    #: Seconds between two log lines about commands below ``min_erpm``.
    BAND_LOG_EVERY_S: ClassVar[float] = 5.0

    def __init__(self, motors: Sequence[MotorConfig]) -> None:
        super().__init__(motors)
        opts: list[_Options] = []
        for m in self.motors:
            where = f"motor {m.wheel!r}"
            raw = self.validate_options(m.options, where)
            opts.append(
                _Options(
                    pole_pairs=cast("int", raw["pole_pairs"]),
                    command_period_s=cast("float", raw["command_period_s"]),
                    liveness_s=cast("float", raw["liveness_s"]),
                    min_erpm=cast("float", raw["min_erpm"]),
                )
            )
        self._opts: tuple[_Options, ...] = tuple(opts)
        #: (speed limit in rad/s, gear ratio, sign, pole pairs) per motor, for erpm_for.
        self._scale = tuple(
            (m.max_wheel_rad_s, m.gear_ratio, m.sign, o.pole_pairs)
            for m, o in zip(self.motors, self._opts, strict=True)
        )
        self._node_ids = tuple(m.node_id for m in self.motors)
        self._min_erpm = tuple(o.min_erpm for o in self._opts)
        self._track = [_Track() for _ in self.motors]
        self._enabled = False
        self._enabled_at_s: float | None = None
        #: Commands sent that the VESC does not follow as given, by reason (``below_min_erpm``:
        #: SET_RPM nonzero and below ``min_erpm``, counted once per :meth:`command`).
        self.command_counts: collections.Counter[str] = collections.Counter()
        self._band_watch = BandWatch(self.BAND_LOG_EVERY_S)
        for i in range(len(self.motors)):
            self._say_missing_status(i)

    @classmethod
    def validate_options(cls, raw: Mapping[str, object], where: str) -> dict[str, object]:
        """Validate the protocol keys (:mod:`drivers.vesc.settings`); check
        ``command_period_s`` against the VESC's timeout and ``liveness_s`` against the stated
        status rate.

        :raises ConfigError: for an unknown, missing or bad key (``timeout_s`` with its new
            name), a keep-alive period too long for the VESC's timeout, or a liveness time
            shorter than two status periods.
        """
        check_options(raw, where)
        out = super().validate_options(raw, where)
        check_validated(out, where)
        return out

    @classmethod
    def make_simulator(cls, motor: MotorConfig) -> DeviceSimulator:
        """A :class:`~drivers.vesc.sim.VescSimulator` for ``motor``, as the motor block says
        the device was set up in VESC Tool: its stated timeout (``controller_timeout_s``, else
        the factory 1 s), status messages (STATUS and STATUS_5 at ``status_rate_hz``, else
        none, as from the factory) and ``min_erpm``."""
        o = cls.validate_options(motor.options, f"motor {motor.wheel!r}")
        rate = cast("float", o["status_rate_hz"])
        return VescSimulator(
            motor,
            status_msgs=STATUS_1 | STATUS_5 if rate else FACTORY_STATUS_MSGS,
            status_rate_hz=rate or FACTORY_STATUS_RATE_HZ,
            timeout_s=cast("float", o["controller_timeout_s"]) or FACTORY_TIMEOUT_S,
            min_erpm=cast("float", o["min_erpm"]),
        )

    # ----------------------------------------------------------------- protection

    def protection(self, index: int) -> Protection:
        """STATED from ``controller_timeout_s``; else UNSTATED, saying what is known (the
        factory timeout, which wheelgate cannot read) and how to state it."""
        prot = super().protection(index)
        if prot.guard is not Guard.UNSTATED:
            return prot
        return dataclasses.replace(prot, how=UNSTATED_HOW)

    def uncontrolled_band(self, index: int) -> tuple[float, float] | None:
        """The wheel speeds (rad/s) motor ``index``'s VESC does not speed-control: ``(0.0,
        high)`` for every speed with ``0 < |speed| < high`` (``high`` is ``min_erpm`` at the
        wheel); ``None`` when ``min_erpm`` is 0 (:mod:`drivers.vesc.min_erpm`)."""
        _, gear, _, pole_pairs = self._scale[index]
        return uncontrolled_band(self._opts[index].min_erpm, pole_pairs, gear)

    # ----------------------------------------------------------------- units

    @property
    def keepalive_period_s(self) -> float:
        """Call :meth:`poll` at least this often (s) to keep every VESC from timing out."""
        return min((o.command_period_s for o in self._opts), default=math.inf)

    def erpm_for(self, index: int, wheel_rad_s: float) -> int:
        """The SET_RPM value for a wheel speed.

        :param index: the motor's position in :attr:`motors`.
        :param wheel_rad_s: wheel speed in rad/s, within the motor's ``max_rpm``.
        :raises EncodeError: if the speed is not finite or beyond ``max_rpm``.
        """
        # Per-motor constants from __init__; the same arithmetic as m.max_wheel_rad_s and
        # m.wheel_to_motor_rad_s (w * gear * sign).
        limit, gear, sign, pole_pairs = self._scale[index]
        if not (math.isfinite(wheel_rad_s) and -limit <= wheel_rad_s <= limit):
            m = self.motors[index]
            raise EncodeError(
                f'Expected velocity for node {m.node_id} ("{m.wheel}") between {-limit:.1f} and '
                f"{limit:.1f} rad/s, but got {wheel_rad_s!r}."
            )
        return round(wheel_rad_s * gear * sign * RPM_PER_RAD_S * pole_pairs)

    def wheel_rad_s_for(self, index: int, erpm: float) -> float:
        """The wheel speed in rad/s for an eRPM reading of motor ``index``."""
        # Per-motor constants from __init__; the same arithmetic as
        # m.motor_to_wheel_rad_s(erpm / pole_pairs / RPM_PER_RAD_S) (x * sign / gear).
        _, gear, sign, pole_pairs = self._scale[index]
        return erpm / pole_pairs / RPM_PER_RAD_S * sign / gear

    def wheel_rad_for(self, index: int, steps: int) -> float:
        """The wheel angle in rad for ``steps`` tachometer steps of motor ``index``."""
        _, gear, sign, pole_pairs = self._scale[index]
        revs = steps / (TACHO_STEPS_PER_EREV * pole_pairs)
        return revs * 2.0 * math.pi * sign / gear

    # ----------------------------------------------------------------- hooks

    def enable(self, now_s: float) -> list[Frame]:
        """Start the command stream: SET_RPM 0 to every motor (VESC has no arm state)."""
        self._enabled = True
        self._enabled_at_s = now_s
        out = []
        for i, m in enumerate(self.motors):
            track = self._track[i]
            track.erpm = 0
            track.sent_s = now_s
            track.hinted = False
            self.set_armed(i, True)
            out.append(make_set_rpm(m.node_id, 0))
        return out

    def disable(self, now_s: float) -> list[Frame]:
        """SET_CURRENT 0 to every motor, which releases it, and stop the command stream."""
        self._enabled = False
        self._enabled_at_s = None
        for i, track in enumerate(self._track):
            track.erpm = 0
            track.sent_s = None
            self.set_armed(i, False)
        return [make_set_current(m.node_id, 0.0) for m in self.motors]

    def command(self, wheel_rad_s: Sequence[float], now_s: float) -> list[Frame]:
        """SET_RPM for every motor; nothing while disabled (the speeds are checked anyway).

        :raises EncodeError: for the wrong number of speeds, or a speed that is not finite or
            beyond the motor's ``max_rpm``.
        """
        if len(wheel_rad_s) != len(self.motors):
            raise EncodeError(
                f"Expected {len(self.motors)} wheel speeds for the VESC driver, "
                f"but got {len(wheel_rad_s)}."
            )
        erpm_for = self.erpm_for
        erpms = [erpm_for(i, w) for i, w in enumerate(wheel_rad_s)]
        if not self._enabled:
            return []
        out = []
        for i, (node_id, track, erpm, min_erpm) in enumerate(
            zip(self._node_ids, self._track, erpms, self._min_erpm, strict=True)
        ):
            if erpm and -min_erpm < erpm < min_erpm:  # in_band, inlined (every cycle)
                self._below_min_erpm(i, erpm, now_s)
            track.erpm = erpm
            track.sent_s = now_s
            out.append(make_set_rpm(node_id, erpm))
        return out

    def _below_min_erpm(self, index: int, erpm: int, now_s: float) -> None:
        """Count (and at most every :attr:`BAND_LOG_EVERY_S` log) a command in the band."""
        self.command_counts[BELOW_MIN_ERPM] += 1
        m = self.motors[index]
        line = self._band_watch.note(m.node_id, m.wheel, erpm, self._min_erpm[index], now_s)
        if line is not None:
            log.warning("%s", line)

    def poll(self, now_s: float) -> list[Frame]:
        """Resend the last command to every motor not commanded for ``command_period_s``."""
        out: list[Frame] = []
        if not self._enabled:
            return out
        for i, (m, track) in enumerate(zip(self.motors, self._track, strict=True)):
            if track.sent_s is None or now_s - track.sent_s >= self._opts[i].command_period_s:
                track.sent_s = now_s
                out.append(make_set_rpm(m.node_id, track.erpm))
            if track.status_s is None or track.status5_s is None:
                self._hint(i, now_s)  # (once both streams were seen, it has nothing to say)
        return out

    def receive_filters(self) -> tuple[CanFilter, ...]:
        """What :meth:`on_frame` takes, as 29-bit filters (``packet << 8 | controller ID``):
        per controller, STATUS and STATUS_5 (used) and STATUS_2/3/4/6 (claimed), exact; and
        every PONG, whatever pinger's ID is in its low byte (the answering controller is in
        the payload, so the identifier cannot tell ours from another's; PONGs answer a PING,
        which the gateway never sends, so they are rare).  A command another master sends one
        of our controllers does not pass."""
        return (
            *(CanFilter.exact(packet << 8 | m.node_id, True)
              for m in self.motors for packet in _RECEIVED_STATUS),
            CanFilter(CanPacketId.PONG << 8, 0x1FFFFF00, True),
        )

    def on_frame(self, frame: Frame) -> bool:
        """Take the frames this driver's VESCs send (STATUS, STATUS_5 used; others claimed).

        :return: whether the frame came from one of them (malformed ones are counted in
            :attr:`rejected`).
        """
        try:
            msg = decode(frame)
        except DecodeError as err:
            if self.index_of(frame.arbitration_id & 0xFF) is None:
                return False
            self.reject("malformed", err)
            return True
        if msg is None:
            # STATUS_2/3/4/6 of our VESCs are ours too, but carry nothing the gateway uses.
            return (
                frame.is_extended_id
                and frame.arbitration_id >> 8 in _UNUSED_STATUS
                and self.index_of(frame.arbitration_id & 0xFF) is not None
            )
        index = self._index.get(msg.node_id)  # index_of, inlined (every frame)
        if index is None:
            return False
        track = self._track[index]
        if type(msg) is VescStatus:
            first = track.status_s is None
            track.status = msg
            track.status_s = frame.timestamp_s
            track.velocity_rad_s = self.wheel_rad_s_for(index, msg.erpm)
        elif type(msg) is VescStatus5:
            first = track.status5_s is None
            if track.tacho is not None:
                track.steps += wrap_int32(msg.tachometer - track.tacho)
            track.tacho = msg.tachometer
            track.status5 = msg
            track.status5_s = frame.timestamp_s
        else:  # a PONG: proof of life, but liveness is defined by the status streams
            return True
        if first:
            self._say_missing_status(index)
        if track.status_s is not None and track.status5_s is not None:
            # Stamped with the older of the two frames, so a stalled stream shows its age.
            stamp = min(track.status_s, track.status5_s)
            position = self.wheel_rad_for(index, track.steps)
            self._feedback[index] = WheelFeedback(position, track.velocity_rad_s, stamp)
        return True

    # ----------------------------------------------------------------- state

    def state(self, index: int, now_s: float) -> DriveState:
        """OFFLINE unless both status streams are fresh; ENABLING until they arrive after
        :meth:`enable`; then ENABLED (DISABLED when not enabled).  Never FAULT (see module).
        """
        track = self._track[index]
        if track.status_s is None or track.status5_s is None:
            return DriveState.OFFLINE
        oldest = min(track.status_s, track.status5_s)
        if now_s - oldest > self._opts[index].liveness_s:
            return DriveState.OFFLINE
        if not self._enabled:
            return DriveState.DISABLED
        if self._enabled_at_s is not None and oldest < self._enabled_at_s:
            return DriveState.ENABLING
        return DriveState.ENABLED

    def last_status(self, index: int) -> VescStatus | None:
        """The latest STATUS of motor ``index`` (current and duty), or ``None``."""
        return self._track[index].status

    def last_status5(self, index: int) -> VescStatus5 | None:
        """The latest STATUS_5 of motor ``index`` (tachometer and input voltage), or ``None``."""
        return self._track[index].status5

    def _missing_status(self, index: int) -> str:
        """What motor ``index`` has never sent and how to switch it on ("" if nothing)."""
        track = self._track[index]
        return missing_status(track.status_s is not None, track.status5_s is not None)

    def _say_missing_status(self, index: int) -> None:
        """Put what motor ``index`` has never sent in its status detail (or clear it)."""
        self.set_fault(index, self._faults[index], self._missing_status(index))

    def _hint(self, index: int, now_s: float) -> None:
        track = self._track[index]
        if track.hinted or self._enabled_at_s is None:
            return
        if now_s - self._enabled_at_s < self.STATUS_HINT_AFTER_S:
            return
        missing = self._missing_status(index)
        if missing:
            track.hinted = True
            log.warning(
                "VESC %d (%r), %.1f s after enable: %s (and check that it is on the bus in "
                "CAN_MODE_VESC with this ID)",
                self.motors[index].node_id,
                self.motors[index].wheel,
                now_s - self._enabled_at_s,
                missing,
            )
