"""What ``wheelgate spin`` commands, pure: the speed profile of a drive motor or the sweep of a
steering actuator, their bounds, the words that tell the operator what to watch, and the bus
traffic that means someone else drives the motor.

A spin turns a motor at most at half its limit (:data:`SPEED_SHARE`): slowly, a lifted wheel
whose ``gear_ratio`` or ``invert`` may still be wrong.  A drive motor ramps to ``speed`` (rad/s
at the wheel) in ``ramp_s``, holds it and ramps back to
zero by ``duration_s``; the encoder is judged over the hold, from :data:`SETTLE_S` after the
ramp.  A steering actuator turns its wheels from where they stand by ``amplitude`` (15 degrees,
less where its travel ends sooner) at ``speed`` (rad/s of steering angle), holds, and turns
back; the encoder is judged over the hold.  Nothing here does I/O or reads the clock.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

from gateway.core.errors import ConfigError, GatewayError

if TYPE_CHECKING:
    from collections.abc import Iterable

    from gateway.core.can_ids import CanIds
    from gateway.core.kinematics import Wheel
    from gateway.core.types import Frame, MotorConfig

#: The largest share of a motor's speed limit a spin asks for (given or default).
SPEED_SHARE = 0.5
#: A drive motor's speed when none is given (rad/s at the wheel; at most half its limit).
DEFAULT_SPEED_RAD_S = 1.0
#: A steering actuator's rate when none is given (rad/s of steering angle).
DEFAULT_STEER_RATE_RAD_S = 0.3
#: The default, shortest and longest spin (s).
DEFAULT_DURATION_S = 3.0
MIN_DURATION_S = 1.0
MAX_DURATION_S = 30.0
#: The slowest speed judged (rad/s): slower, an encoder's counts say too little.
MIN_SPEED_RAD_S = 0.1
#: The shortest ramp of a drive motor (s), when the robot states no acceleration limit.
MIN_RAMP_S = 0.2
#: How long after the ramp the motion is left to settle before it is judged (s).
SETTLE_S = 0.3
#: The shortest time the steady motion must be measured for (s).
MIN_WINDOW_S = 0.4
#: A steering actuator's sweep, and the smallest one worth judging (rad).
STEER_AMPLITUDE_RAD = math.radians(15.0)
MIN_STEER_AMPLITUDE_RAD = math.radians(2.0)
#: The share of the travel left on a side that a short sweep takes (clear of the end stop).
STEER_ROOM_SHARE = 0.8
#: The compass words of a heading in the body frame, from forward, counter-clockwise.
_COMPASS = ("forward", "forward-left", "left", "backward-left", "backward", "backward-right",
            "right", "forward-right")


class SpinUsageError(GatewayError, ValueError):
    """A spin that cannot be commanded as asked; :attr:`option` names the option to change.

    :param message: what was expected and what came.
    :param option: the command-line option (``--speed``), for the usage error.
    """

    def __init__(self, message: str, option: str) -> None:
        super().__init__(message)
        self.option = option


class NoSpinError(ConfigError):
    """The configuration leaves no spin of the motor possible, whatever the options (no speed
    within its limits that its controller speed-controls, no travel to sweep); the message
    names the keys to change.  Raised before anything is sent."""


class NoRoomError(GatewayError):
    """A steering actuator's wheels, found where they stand once it is enabled, leave no room
    to sweep on either side (the spin's stop then goes out)."""


@dataclass(frozen=True, slots=True)
class SpinPlan:
    """One spin's command.

    :param motor: the motor turned.
    :param speed_rad_s: a drive motor's wheel speed (signed), a steering actuator's rate (> 0).
    :param duration_s: how long the command lasts, ramps included (s).
    :param ramp_s: a drive motor's ramp; a steering actuator's time to sweep out (s).
    :param amplitude_rad: a steering actuator's sweep from ``origin_rad`` (signed; 0 for a drive
        motor).
    :param origin_rad: where a steering actuator's wheels stood when the spin began (rad).
    :param floor_rad_s: a drive motor's slowest speed commanded on the ramps: slower ones are
        commanded as zero (the top of the speeds its controller does not speed-control).
    """

    motor: MotorConfig
    speed_rad_s: float
    duration_s: float
    ramp_s: float
    amplitude_rad: float = 0.0
    origin_rad: float = 0.0
    floor_rad_s: float = 0.0

    @property
    def steering(self) -> bool:
        """Whether a steering actuator is swept (else a wheel turned)."""
        return self.motor.steering

    @property
    def commanded(self) -> float:
        """What the steady motion is compared with: the wheel speed (rad/s), or the sweep's
        offset from the origin (rad)."""
        return self.amplitude_rad if self.steering else self.speed_rad_s

    @property
    def window(self) -> tuple[float, float]:
        """When the motion is steady (s from the start of the command)."""
        return self.ramp_s + SETTLE_S, self.duration_s - self.ramp_s

    @property
    def travel_rad(self) -> float:
        """The wheel's turn the command asks for (rad; a sweep: its offset)."""
        if self.steering:
            return self.amplitude_rad
        return self.speed_rad_s * (self.duration_s - self.ramp_s)

    def setpoint(self, t_s: float) -> float:
        """The setpoint ``t_s`` seconds into the command: wheel rad/s, or a steering angle."""
        if t_s <= 0.0 or t_s >= self.duration_s:
            shape = 0.0
        else:
            shape = min(1.0, t_s / self.ramp_s, (self.duration_s - t_s) / self.ramp_s)
        if self.steering:
            return self.origin_rad + self.amplitude_rad * shape
        speed = self.speed_rad_s * shape
        return speed if abs(speed) >= self.floor_rad_s else 0.0

    def from_origin(self, origin_rad: float) -> SpinPlan:
        """A steering sweep from where the wheels stand: towards the side with room (the
        counter-clockwise side when both have), at most the planned amplitude.

        :raises NoRoomError: when neither side has room for :data:`MIN_STEER_AMPLITUDE_RAD`.
        """
        if not self.steering:
            return self
        lo, hi = self.motor.steer_range_rad
        amplitude = sweep(lo, hi, origin_rad, abs(self.amplitude_rad) or STEER_AMPLITUDE_RAD)
        if abs(amplitude) < MIN_STEER_AMPLITUDE_RAD:
            raise NoRoomError(
                f"{self.motor.wheel}: its wheels stand at {math.degrees(origin_rad):+.1f} deg "
                f"within its travel {math.degrees(lo):+.1f}..{math.degrees(hi):+.1f} deg: "
                f"expected {math.degrees(MIN_STEER_AMPLITUDE_RAD / STEER_ROOM_SHARE):.3g} deg "
                f"of room on one side to sweep {math.degrees(MIN_STEER_AMPLITUDE_RAD):g} deg "
                f"clear of the end stop; steer them towards the middle first (wheelgate jog)")
        ramp = abs(amplitude) / self.speed_rad_s
        return dataclasses.replace(self, amplitude_rad=amplitude, origin_rad=origin_rad,
                                   ramp_s=ramp)


def sweep(lo: float, hi: float, origin: float, want: float) -> float:
    """The sweep (signed, rad) from ``origin`` within the travel ``lo..hi``: ``want`` towards
    the side with room (the counter-clockwise side when both have), else
    :data:`STEER_ROOM_SHARE` of the longer side (possibly too short to judge).

    >>> round(sweep(-0.1, 0.1, 0.0, 0.26), 3), sweep(-1.0, 0.1, 0.0, 0.5)
    (0.08, -0.5)
    """
    room_up, room_down = hi - origin, origin - lo
    if room_up >= want:
        return want
    if room_down >= want:
        return -want
    return STEER_ROOM_SHARE * (room_up if room_up >= room_down else -room_down)


def drive_plan(motor: MotorConfig, speed: float | None, duration_s: float, limit_rad_s: float,
               accel_rad_s2: float, band: tuple[float, float] | None) -> SpinPlan:
    """A drive motor's spin.

    :param speed: the wheel speed asked for (rad/s, signed); ``None``: the default, at most half
        ``limit_rad_s``, above the uncontrolled ``band``.
    :param limit_rad_s: the wheel's speed limit (its ``max_rpm`` and the robot's limit).
    :param accel_rad_s2: the wheels' acceleration limit (``inf``: none).
    :param band: the speeds the controller does not speed-control (``low < |v| < high``).
    :raises NoSpinError: when no speed at all is allowed: the band reaches beyond half the
        limit (or half the limit is below :data:`MIN_SPEED_RAD_S`), whatever ``speed`` is.
    :raises SpinUsageError: for a speed beyond half the limit, below :data:`MIN_SPEED_RAD_S` or
        in the band, or a duration too short to ramp and measure.
    """
    _check_duration(duration_s)
    _check_some_speed(motor, limit_rad_s, band)
    if speed is None:
        speed = min(DEFAULT_SPEED_RAD_S, SPEED_SHARE * limit_rad_s)
        if band is not None and band[0] < speed < band[1]:
            speed = min(1.25 * band[1], SPEED_SHARE * limit_rad_s)
    _check_speed(motor, speed, limit_rad_s, "rad/s at the wheel", "the robot's wheel speeds")
    if band is not None and band[0] < abs(speed) < band[1]:
        raise SpinUsageError(
            f"{motor.wheel}: expected a speed outside {band[0]:.3g}..{band[1]:.3g} rad/s, which "
            f"its {motor.driver} controller does not speed-control (its minimum speed), got "
            f"{speed:g}; at least {band[1]:.3g} rad/s", "--speed")
    ramp = max(abs(speed) / accel_rad_s2, MIN_RAMP_S)
    plan = SpinPlan(motor, speed, duration_s, ramp, floor_rad_s=band[1] if band else 0.0)
    _check_window(plan)
    return plan


def steer_plan(motor: MotorConfig, rate: float | None, duration_s: float,
               limit_rad_s: float, travel_keys: str = "its wheels' steer_min and steer_max"
               ) -> SpinPlan:
    """A steering actuator's sweep, as from its neutral angle (its origin and side are chosen
    at the start, :meth:`SpinPlan.from_origin`, where the wheels stand).

    :param rate: the steering rate asked for (rad/s, > 0); ``None``: the default.
    :param limit_rad_s: the steering rate limit (its wheels' and its ``max_rpm``).
    :param travel_keys: the configuration's keys that set its travel, for the error.
    :raises NoSpinError: when its travel leaves no room for a sweep from its neutral angle.
    :raises SpinUsageError: for a rate beyond half the limit or a duration too short.
    """
    _check_duration(duration_s)
    amplitude = abs(_neutral_sweep(motor, travel_keys))
    if rate is None:
        rate = min(DEFAULT_STEER_RATE_RAD_S, SPEED_SHARE * limit_rad_s)
    _check_speed(motor, rate, limit_rad_s, "rad/s of steering angle",
                 "its wheels' max_steer_rate")
    if rate < 0:
        raise SpinUsageError(f"{motor.wheel}: expected a positive steering rate (the sweep "
                             f"turns out and back), got {rate:g}", "--speed")
    plan = SpinPlan(motor, rate, duration_s, amplitude / rate, amplitude)
    _check_window(plan)
    return plan


def _neutral_sweep(motor: MotorConfig, travel_keys: str) -> float:
    """The sweep from the neutral angle (0, or the nearest end of the travel).

    :raises NoSpinError: when it is too short to judge.
    """
    lo, hi = motor.steer_range_rad
    amplitude = sweep(lo, hi, min(max(0.0, lo), hi), STEER_AMPLITUDE_RAD)
    if abs(amplitude) < MIN_STEER_AMPLITUDE_RAD:
        need = MIN_STEER_AMPLITUDE_RAD / STEER_ROOM_SHARE
        raise NoSpinError(
            f"{motor.wheel}: no room to sweep: expected {math.degrees(need):.3g} deg "
            f"({need:.3g} rad) of travel on one side of its neutral angle, to sweep "
            f"{math.degrees(MIN_STEER_AMPLITUDE_RAD):g} deg clear of the end stop, but its "
            f"travel is {math.degrees(lo):+.2f}..{math.degrees(hi):+.2f} deg, from "
            f"{travel_keys}; widen it if its steering turns further")
    return amplitude


def _check_duration(duration_s: float) -> None:
    if not MIN_DURATION_S <= duration_s <= MAX_DURATION_S:
        raise SpinUsageError(f"expected {MIN_DURATION_S:g} to {MAX_DURATION_S:g} s, got "
                             f"{duration_s:g}", "--duration")


def _check_some_speed(motor: MotorConfig, limit: float, band: tuple[float, float] | None
                      ) -> None:
    """That some speed is left to a drive motor's spin: between :data:`MIN_SPEED_RAD_S` (and
    the top of the ``band`` its controller does not speed-control) and half the ``limit``.

    :raises NoSpinError: naming the keys behind both ends.
    """
    most = SPEED_SHARE * limit
    least = max(MIN_SPEED_RAD_S, band[1] if band is not None else 0.0)
    if least <= most or f"{least:.3g}" == f"{most:.3g}":
        return
    if band is not None and band[1] > MIN_SPEED_RAD_S:
        keys = [f"{k} {motor.options[k]:g}" for k in ("min_erpm", "pole_pairs")
                if isinstance(motor.options.get(k), (int, float))]
        low = (f"its {motor.driver} controller does not speed-control wheel speeds below "
               f"{band[1]:.3g} rad/s ({' through '.join(keys) or 'its minimum speed'} and "
               f"gear_ratio {motor.gear_ratio:g})")
        fix = ("lower min_erpm (on the controller, then in the configuration)" if keys else
               "lower the controller's minimum speed")
        fix += ", or check pole_pairs, gear_ratio and max_rpm (the motor's own)"
    else:
        low = (f"a spin goes at least {MIN_SPEED_RAD_S:g} rad/s (slower, an encoder says too "
               f"little)")
        fix = "check max_rpm and gear_ratio"
    raise NoSpinError(
        f"{motor.wheel}: no spin speed is possible: {low}, and a spin goes at most "
        f"{most:.3g} rad/s at the wheel (half the limit, {limit:.3g}, of max_rpm "
        f"{motor.max_rpm:g} through gear_ratio {motor.gear_ratio:g} and the robot's wheel "
        f"speeds); {fix}")


def _check_speed(motor: MotorConfig, speed: float, limit: float, unit: str, whose: str) -> None:
    """At least :data:`MIN_SPEED_RAD_S`, at most :data:`SPEED_SHARE` of ``limit`` (a hair
    over it passes: the limit as printed, rounded, is accepted)."""
    most = SPEED_SHARE * limit
    if abs(speed) < MIN_SPEED_RAD_S or (abs(speed) > most
                                        and f"{abs(speed):.3g}" != f"{most:.3g}"):
        raise SpinUsageError(
            f"{motor.wheel}: expected {MIN_SPEED_RAD_S:g} to {most:.3g} {unit} either way "
            f"(a spin goes at most half the limit, {limit:.3g}, of max_rpm {motor.max_rpm:g} "
            f"through gear_ratio {motor.gear_ratio:g} and {whose}), got {speed:g}", "--speed")


def _check_window(plan: SpinPlan) -> None:
    start, end = plan.window
    if end - start < MIN_WINDOW_S:
        least = plan.duration_s + MIN_WINDOW_S - (end - start)
        what = "sweep out and back" if plan.steering else "ramp up and down"
        raise SpinUsageError(
            f"{plan.motor.wheel}: expected a duration that leaves {MIN_WINDOW_S:g} s to measure "
            f"after it takes {plan.ramp_s:.2g} s each way to {what}, got {plan.duration_s:g} s; "
            f"at least {least:.2g} s (or a slower --speed)", "--duration")


def compass(heading_rad: float) -> str:
    """The word for a direction in the body frame (x forward, y left).

    >>> compass(0.0), compass(math.pi / 2), compass(-3.0)
    ('forward', 'left', 'backward')
    """
    sector = round(heading_rad / (math.pi / 4)) % len(_COMPASS)
    return _COMPASS[sector]


def way(plan: SpinPlan, wheel: Wheel | None, travel_rad: float) -> str:
    """Which way a turn of ``travel_rad`` goes, in words: a sweep's side seen from above, a
    wheel's direction of rolling the robot (its positive way, without its ``wheel``)."""
    if plan.steering:
        return ("left (counter-clockwise seen from above)" if travel_rad >= 0
                else "right (clockwise seen from above)")
    if wheel is None:
        return "its positive way" if travel_rad >= 0 else "against its positive way"
    heading = wheel.heading() + (0.0 if travel_rad >= 0 else math.pi)
    neutral = " (at its neutral steering angle)" if wheel.steered else ""
    return f"rolling the robot {compass(heading)}{neutral}"


def describe(plan: SpinPlan, wheel: Wheel | None) -> str:
    """What the operator should see, in a sentence (``wheel``: a drive motor's wheel, for the
    direction it rolls the robot).

    >>> from gateway.core.types import MotorConfig
    >>> plan = SpinPlan(MotorConfig("left", "odrive", 1), 1.0, 3.0, 0.2)
    >>> describe(plan, None)
    '+1.00 rad/s for 3.0 s: the wheel turns 0.45 turns (160 deg) its positive way'
    """
    if plan.steering:
        return (f"its wheels turn {way(plan, wheel, plan.amplitude_rad)} by up to "
                f"{math.degrees(abs(plan.amplitude_rad)):.0f} deg at {plan.speed_rad_s:.2f} "
                f"rad/s, hold, and turn back")
    travel = plan.travel_rad
    return (f"{plan.speed_rad_s:+.2f} rad/s for {plan.duration_s:.1f} s: the wheel turns "
            f"{abs(travel) / math.tau:.2f} turns ({math.degrees(abs(travel)):.0f} deg) "
            f"{way(plan, wheel, travel)}")


def command_ids(frames: Iterable[Frame]) -> frozenset[tuple[int, bool]]:
    """The identifiers of a motor's command frames (its driver's ``preview_command``)."""
    return frozenset((f.arbitration_id, f.is_extended_id) for f in frames)


def someone_else(heard: Iterable[Frame], commands: frozenset[tuple[int, bool]],
                 ids: CanIds, motor: MotorConfig) -> str | None:
    """Why the bus is driven by someone else, from the frames heard before arming: a command
    to this motor's controller (our own are not echoed), or a wheelgate's odometry, status or
    error (a daemon runs on this bus); ``None``: nothing of the kind.

    >>> from gateway.core.can_ids import CanIds
    >>> from gateway.core.types import Frame, MotorConfig
    >>> m = MotorConfig("left", "odrive", 1)
    >>> someone_else([Frame(0x103, bytes(8))], frozenset(), CanIds(), m)
    'heard 103#0000000000000000 (WG_Status of a running wheelgate) on the bus'
    """
    names = {ids.status: "WG_Status", ids.odom_pose: "WG_Odom_Pose",
             ids.odom_velocity: "WG_Odom_Velocity", ids.error: "WG_Error"}
    for frame in heard:
        key = (frame.arbitration_id, frame.is_extended_id)
        if key in commands:
            return (f"heard {frame.to_cansend()} (a command to {motor.wheel}'s {motor.driver} "
                    f"node {motor.node_id} from another sender) on the bus")
        if frame.is_extended_id == ids.extended and frame.arbitration_id in names:
            return (f"heard {frame.to_cansend()} ({names[frame.arbitration_id]} of a running "
                    f"wheelgate) on the bus")
    return None
