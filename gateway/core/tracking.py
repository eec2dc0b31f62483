"""Tracking-error check: a wheel that answers but does not follow its command.

A motor controller can keep reporting "enabled, no error" while its wheel does something else:
a blocked wheel, a drive that released its motor without a fault code (VESC has none), a
host-side speed loop made unstable by late feedback (DJI C620/C610).  Heartbeats and fault
flags cannot see that; comparing the measured wheel speed with the command can.

The rule is CiA 402's velocity window (objects 0x606D *velocity window* and 0x606E *velocity
window time*), with a window that widens with speed: wheel ``i`` is off its command when

.. math::

    |\\omega_{meas,i} - \\omega_{cmd,i}| > tol_{abs} + tol_{rel} \\, |\\omega_{cmd,i}|

The time a wheel spends outside its window counts up, the time inside counts down (to no less
than zero): a fault when the count reaches ``time_s``.  A *runaway* -- a wheel turning faster,
either way, than any command it had in the last ``time_s`` (to ``2 time_s``) plus its window
-- counts up in proportion to how far outside it is, up to :data:`RUNAWAY_WEIGHT_MAX` times as
fast: a wheel at full speed against a small command is stopped in a tenth of ``time_s``.  A
wheel that only lags -- a heavy robot accelerating, a reversal without acceleration limits, a
blocked wheel, a wheel still coasting when its motor is enabled again (the speed each wheel has
at the first check counts as a recent command) -- turns no faster than it was recently told
to and counts at the plain rate, so slow acceleration does not trip it. This is the
counter-based debouncing of automotive diagnostics (AUTOSAR DEM): a wheel that only passes
through its window, as an oscillating speed loop does a few milliseconds per swing, is still
caught, while a ramp through the acceleration limits or a motor's own lag leaves the window
only briefly, which ``time_s`` absorbs. One check adds at most a tenth of ``time_s``, so a
stalled loop's long gap between two checks cannot make a fault out of one sample. The command
is the one sent the cycle before (the one the feedback answers).

Steering actuators get the same rule on their angle (:class:`SteerMonitor`): an actuator is
off its command when the measured steering angle differs from the one commanded the cycle
before by more than ``steer_tolerance_rad``; the gateway limits the commanded angle's rate, so
a healthy actuator follows within its own lag, and one that is blocked or has lost its zero
leaves the drive wheels pushing along a heading the robot does not have.

Pure: no clock, no I/O; the loop calls :meth:`TrackingMonitor.check` once a cycle while the
drives are running and :meth:`TrackingMonitor.reset` whenever they are not.  A check whose
commands and feedback objects are those of the check before, when every wheel was inside its
window with a count of zero, changes nothing but the time of the last check (and the runaway
test's period): :meth:`TrackingMonitor.check` then skips the per-wheel work (most cycles: the
feedback comes at a fraction of the loop rate).
"""

from __future__ import annotations

import operator
from dataclasses import dataclass
from typing import TYPE_CHECKING

from gateway.core.numfmt import fixed

if TYPE_CHECKING:
    from collections.abc import Sequence

    from gateway.core.settings import TrackingLimits
    from gateway.core.types import WheelFeedback


#: The most a runaway wheel's count may advance per second (see the module docstring).
RUNAWAY_WEIGHT_MAX = 10.0


@dataclass(frozen=True, slots=True)
class TrackingFault:
    """A wheel that stayed off its command for too long.

    :param index: position of the wheel's motor in the checked sequence.
    :param command_rad_s: the wheel speed commanded (rad/s).
    :param measured_rad_s: the wheel speed the controller reports (rad/s).
    :param window_rad_s: the allowed error for that command (rad/s).
    :param duration_s: the wheel's count: time outside its window less time inside (s).
    """

    index: int
    command_rad_s: float
    measured_rad_s: float
    window_rad_s: float
    duration_s: float

    def describe(self) -> str:
        """The fault in words, without the wheel's name.

        >>> TrackingFault(0, 10.0, 2.5, 4.5, 0.5).describe().split(" (")
        ... # doctest: +NORMALIZE_WHITESPACE
        ['does not follow its command: 2.50 rad/s measured, 10.00 rad/s commanded',
         'error 7.50 rad/s, window 4.50 rad/s) for a net 0.500 s']
        """
        error = abs(self.measured_rad_s - self.command_rad_s)
        return (
            f"does not follow its command: {fixed(self.measured_rad_s, 2)} rad/s measured, "
            f"{fixed(self.command_rad_s, 2)} rad/s commanded (error {error:.2f} rad/s, "
            f"window {self.window_rad_s:.2f} rad/s) for a net {self.duration_s:.3f} s"
        )


def _inside(feedback: Sequence[WheelFeedback | None],
            windows: Sequence[tuple[float, float]]) -> bool:
    """Whether every wheel with feedback is inside its window (``not <=``: NaN is outside),
    ``windows`` each wheel's (checked command, window)."""
    for fb, (command, window) in zip(feedback, windows):  # noqa: B905 - lengths checked
        if fb is not None and not abs(fb.velocity_rad_s - command) <= window:
            return False
    return True


class TrackingMonitor:
    """Watches every driven wheel's speed against its command.

    :param limits: the window and the time.
    """

    def __init__(self, limits: TrackingLimits) -> None:
        self.limits = limits
        #: Each wheel's count (s): time outside its window less time inside, at least 0.
        self._count: list[float] = []
        self._last_s: float | None = None
        #: Each wheel's largest |command| in the current and the previous period of ``time_s``
        #: (the runaway test's "recent commands", two floats a wheel).
        self._peak: list[float] = []
        self._peak_before: list[float] = []
        self._period_start_s: float | None = None
        #: The largest error / window ratio seen so far (above 1: a wheel left its window), to
        #: tune the window against a real robot.
        self.worst_ratio = 0.0
        #: Per wheel, the speeds its controller does not speed-control (``(low, high)`` rad/s,
        #: :meth:`gateway.drive.driver.MotorDriver.uncontrolled_band`; ``None``: none): a command
        #: there is checked as zero, which is what the controller does with it.
        self.dead_bands: Sequence[tuple[float, float] | None] = ()
        # The last full check, when it left every wheel inside its window with a zero count
        # (``None`` otherwise): its commands, feedback, dead bands, each wheel's peak after
        # a new runaway period, and each wheel's (checked command, window) (see ``check``).
        self._quiet: tuple[tuple[float, ...], tuple[WheelFeedback | None, ...],
                           Sequence[tuple[float, float] | None], list[float],
                           list[tuple[float, float]]] | None = None

    def reset(self) -> None:
        """Forget every wheel's history (the drives stopped following commands)."""
        if self._last_s is None:
            return  # nothing checked since the last reset (called every cycle while idle)
        self._count = [0.0] * len(self._count)
        self._last_s = None
        self._period_start_s = None
        self._quiet = None

    def check(
        self,
        command_rad_s: Sequence[float],
        feedback: Sequence[WheelFeedback | None],
        now_s: float,
    ) -> TrackingFault | None:
        """Compare each wheel's latest feedback with its command; the first fault, if any.

        :param command_rad_s: every checked wheel's commanded speed.
        :param feedback: every checked wheel's latest feedback (``None``: none yet, skipped).
        :param now_s: the time of this check (s).
        """
        quiet = self._quiet
        if (
            quiet is not None
            and (command_rad_s is quiet[0] or command_rad_s == quiet[0])
            and len(feedback) == len(quiet[1])
            and self.dead_bands is quiet[2]
        ):
            # The commands are those of a check that left every wheel inside its window with
            # a zero count; when every wheel's feedback is the same, or new and inside its
            # window again (then kept, so that the next cycles find it the same), this check
            # would leave every count at zero and every peak as it is.
            if not all(map(operator.is_, feedback, quiet[1])):
                if not _inside(feedback, quiet[4]):
                    return self._check_all(command_rad_s, feedback, now_s)
                self._quiet = quiet = (quiet[0], tuple(feedback), quiet[2], quiet[3], quiet[4])
            self._last_s = now_s
            start = self._period_start_s
            if start is not None and now_s - start >= self.limits.time_s:
                self._peak_before, self._peak, self._period_start_s = (
                    self._peak, list(quiet[3]), now_s)
            return None
        return self._check_all(command_rad_s, feedback, now_s)

    def _check_all(
        self,
        command_rad_s: Sequence[float],
        feedback: Sequence[WheelFeedback | None],
        now_s: float,
    ) -> TrackingFault | None:
        """:meth:`check`, wheel by wheel (the general path)."""
        self._quiet = None
        limits = self.limits
        if not limits.enabled:
            return None
        n = len(command_rad_s)
        count = self._count
        if len(count) != n:
            count = self._count = [0.0] * n
            self._period_start_s = None
        hold = limits.time_s
        last, self._last_s = self._last_s, now_s
        dt = _interval(last, now_s, hold)
        start = self._period_start_s
        if start is None:
            # The first check since the drives started: a wheel still turning from before (a
            # released motor coasting when it is enabled again) is not a runaway while it
            # slows down from there, so its speed then counts as a recent command.
            self._peak, self._period_start_s = [0.0] * n, now_s
            self._peak_before = [0.0 if fb is None or fb.velocity_rad_s != fb.velocity_rad_s
                                 else abs(fb.velocity_rad_s) for fb in feedback]
        elif now_s - start >= hold:
            self._peak_before, self._peak, self._period_start_s = self._peak, [0.0] * n, now_s
        peak, before = self._peak, self._peak_before
        abs_tol, ratio = limits.tolerance_rad_s, limits.tolerance_ratio
        fault: TrackingFault | None = None
        bands = self.dead_bands
        outside = False
        fresh = [0.0] * n  # each wheel's peak at the start of a new period, after this check
        windows = []  # each wheel's (checked command, window), for ``check``'s skip
        n_bands = len(bands)
        for i, (command, fb) in enumerate(zip(command_rad_s, feedback, strict=True)):
            cmd, size = command, abs(command)
            if i < n_bands and (band := bands[i]) is not None and band[0] < size < band[1]:
                # In a band the controller does not speed-control, it stops the motor instead.
                cmd = size = 0.0
            # (max written out: peak[i] = max(peak[i], size), fresh[i] = max(0.0, size).)
            if size > peak[i]:  # noqa: PLR1730 - max() is a call per wheel per cycle
                peak[i] = size
            if size > 0.0:
                fresh[i] = size
            window = abs_tol + ratio * size
            windows.append((cmd, window))
            if fb is None:
                count[i] = 0.0
                continue
            measured = fb.velocity_rad_s
            error = abs(measured - cmd)
            # ``not <=`` so that a NaN speed counts as outside the window.
            if not error <= window:
                outside = True
                off = error / window if window > 0.0 else RUNAWAY_WEIGHT_MAX
                self.worst_ratio = max(self.worst_ratio, off)
                # A runaway counts by how far off it is (capped); lagging at the plain rate.
                runaway = abs(measured) > max(peak[i], before[i]) + window
                count[i] += dt * (min(off, RUNAWAY_WEIGHT_MAX) if runaway else 1.0)
                if fault is None and count[i] >= hold:
                    fault = TrackingFault(i, cmd, fb.velocity_rad_s, window, count[i])
            elif (c := count[i]):  # max(c - dt, 0.0), written out (steady: c is 0)
                count[i] = c - dt if c > dt else 0.0
        if not outside and not any(count):
            self._quiet = (tuple(command_rad_s), tuple(feedback), bands, fresh, windows)
        return fault


def _interval(last_s: float | None, now_s: float, hold_s: float) -> float:
    """The time a check counts: since the last one, at most a tenth of ``hold_s``."""
    return 0.0 if last_s is None else min(max(now_s - last_s, 0.0), 0.1 * hold_s)


@dataclass(frozen=True, slots=True)
class SteerFault:
    """A steering actuator that stayed off its commanded angle for too long.

    :param index: position of the actuator in the checked sequence.
    :param command_rad: the steering angle commanded (rad).
    :param measured_rad: the steering angle the actuator reports (rad).
    :param window_rad: the allowed error (rad).
    :param duration_s: the actuator's count: time outside its window less time inside (s).
    """

    index: int
    command_rad: float
    measured_rad: float
    window_rad: float
    duration_s: float

    def describe(self) -> str:
        """The fault in words, without the actuator's name.

        >>> print(SteerFault(0, 1.5, 0.25, 0.2, 0.5).describe())
        ... # doctest: +NORMALIZE_WHITESPACE
        does not reach its angle: 0.250 rad measured, 1.500 rad commanded
        (error 1.250 rad, window 0.200 rad) for a net 0.500 s
        """
        error = abs(self.measured_rad - self.command_rad)
        return (
            f"does not reach its angle: {fixed(self.measured_rad, 3)} rad measured, "
            f"{fixed(self.command_rad, 3)} rad commanded (error {error:.3f} rad, "
            f"window {self.window_rad:.3f} rad) for a net {self.duration_s:.3f} s"
        )


class SteerMonitor:
    """Watches every steering actuator's angle against its command (see the module docstring).

    :param limits: ``steer_tolerance_rad`` and ``time_s``.
    """

    def __init__(self, limits: TrackingLimits) -> None:
        self.limits = limits
        self._count: list[float] = []
        self._last_s: float | None = None
        #: The largest error / window ratio seen so far.
        self.worst_ratio = 0.0

    def reset(self) -> None:
        """Forget every actuator's history (the drives stopped following commands)."""
        self._count = [0.0] * len(self._count)
        self._last_s = None

    def check(
        self,
        command_rad: Sequence[float],
        feedback: Sequence[WheelFeedback | None],
        now_s: float,
    ) -> SteerFault | None:
        """Compare each actuator's measured angle with its command; the first fault, if any.

        :param command_rad: every actuator's commanded steering angle (rad).
        :param feedback: every actuator's latest feedback (``None``: none yet, skipped).
        :param now_s: the time of this check (s).
        """
        limits = self.limits
        if not limits.enabled:
            return None
        count = self._count
        if len(count) != len(command_rad):
            count = self._count = [0.0] * len(command_rad)
        last, self._last_s = self._last_s, now_s
        dt = _interval(last, now_s, limits.time_s)
        window = limits.steer_tolerance_rad
        fault: SteerFault | None = None
        for i, (cmd, fb) in enumerate(zip(command_rad, feedback, strict=True)):
            if fb is None:
                count[i] = 0.0
                continue
            error = abs(fb.position_rad - cmd)
            if not error <= window:  # a NaN angle is outside
                self.worst_ratio = max(self.worst_ratio, error / window if window else 1e9)
                count[i] += dt
                if fault is None and count[i] >= limits.time_s:
                    fault = SteerFault(i, cmd, fb.position_rad, window, count[i])
            elif (c := count[i]):  # max(c - dt, 0.0), written out (steady: c is 0)
                count[i] = c - dt if c > dt else 0.0
        return fault
