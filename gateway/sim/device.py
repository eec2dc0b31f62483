"""Device simulators: the controller side of each protocol, for tests and ``--sim``.

A simulator is driven by two calls, both given the time explicitly so tests are deterministic:
:meth:`DeviceSimulator.handle` for every frame the gateway sends, and
:meth:`DeviceSimulator.tick` to advance the motor and emit periodic frames.  Protocol
simulators fill in the ``_on_frame`` and ``_on_tick`` hooks; the base applies the injected
faults (silence, garbage, dropped frames, latency) to whatever they emit.
:mod:`gateway.sim.bus` puts them on a python-can bus.
"""

from __future__ import annotations

import abc
import collections
import enum
import math
import random
from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from gateway.core.types import Frame, MotorConfig


@dataclass(slots=True)
class MotorModel:
    """A motor with first-order velocity dynamics and an acceleration limit (motor side).

    .. math::

        \\dot v = \\operatorname{clip}\\left(\\frac{v_{target} - v}{\\tau},
        -a_{max}, a_{max}\\right), \\qquad \\dot p = v

    In position mode (:attr:`target_position_rad` set, a steering actuator) the speed target is
    a proportional position loop with velocity feed-forward, as in the controllers' firmware:
    :math:`v_{target} = \\operatorname{clip}(v_{ff} + k_p (p_{target} - p), \\pm v_{max})`.
    With the default gain and time constant the loop is damped at 0.71 of critical.

    :param time_constant_s: velocity time constant tau (s).
    :param max_accel_rad_s2: acceleration limit (rad/s^2, motor side).
    """

    time_constant_s: float = 0.01
    max_accel_rad_s2: float = 2000.0
    #: Commanded motor speed (rad/s).
    target_rad_s: float = 0.0
    #: Actual motor speed (rad/s).
    velocity_rad_s: float = 0.0
    #: Motor shaft angle (rad), the ground truth for odometry.
    position_rad: float = 0.0
    #: Whether the motor is driven; a disarmed motor coasts to a stop.
    armed: bool = False
    #: Position mode: the commanded shaft angle (rad); ``None`` in velocity mode.
    target_position_rad: float | None = None
    #: Position mode: the speed feed-forward (rad/s).
    velocity_ff_rad_s: float = 0.0
    #: Position mode: the loop gain (rad/s per rad).
    position_gain_1_s: float = 50.0
    #: Position mode: the speed limit (rad/s).
    max_speed_rad_s: float = math.inf

    #: The longest step of the position loop (s); longer steps are split.
    POSITION_STEP_S = 0.0005

    def step(self, dt_s: float) -> None:
        """Advance the model by ``dt_s`` seconds (exact for the linear part)."""
        if dt_s <= 0.0:
            return
        if self.target_position_rad is not None and self.armed:
            n = max(1, math.ceil(dt_s / self.POSITION_STEP_S - 1e-9))
            for _ in range(n):
                error = self.target_position_rad - self.position_rad
                speed = self.velocity_ff_rad_s + self.position_gain_1_s * error
                limit = self.max_speed_rad_s
                self.target_rad_s = min(max(speed, -limit), limit)
                self._step(dt_s / n)
            return
        self._step(dt_s)

    def _step(self, dt_s: float) -> None:
        target = self.target_rad_s if self.armed else 0.0
        v0 = self.velocity_rad_s
        v1 = target + (v0 - target) * math.exp(-dt_s / self.time_constant_s)
        limit = self.max_accel_rad_s2 * dt_s
        v1 = min(max(v1, v0 - limit), v0 + limit)
        self.position_rad += 0.5 * (v0 + v1) * dt_s
        self.velocity_rad_s = v1


#: The golden ratio's fraction, (sqrt(5) - 1) / 2.
_GOLDEN_FRACTION = (math.sqrt(5.0) - 1.0) / 2.0


def spread_phase(k: int) -> float:
    """The phase (:attr:`DeviceSimulator.phase`) of a robot's ``k``-th device: ``k`` times the
    golden ratio's fraction modulo 1, so that devices in a row spread over the period (the
    multiples of an irrational number spread evenly modulo 1, Weyl; this one's the most
    evenly) and runs repeat."""
    return (k * _GOLDEN_FRACTION) % 1.0


class SimFault(enum.IntFlag):
    """Faults a test can inject into a simulator."""

    NONE = 0
    #: The device stops sending anything.
    SILENT = enum.auto()
    #: The device reports a fault and disarms (protocol-specific error bits).
    FAULT = enum.auto()
    #: Every second frame the device sends is lost.
    DROP = enum.auto()
    #: Every frame the device sends is held for ``latency_s`` before it goes out (in order).
    LATE = enum.auto()
    #: Every frame the device sends is replaced by random bytes of random length (0 to 8)
    #: on the same identifier, from the simulator's seeded ``garbage_rng``.
    GARBAGE = enum.auto()
    #: The wheel is blocked: the shaft stands still whatever the command, while the device
    #: keeps reporting healthy (no fault code, still armed).
    STALL = enum.auto()
    #: Every frame the device sends is lost (a broken transmit path), while it still hears
    #: and acts on everything (``SILENT`` is a dead device: it hears nothing either).
    MUTE = enum.auto()


class DeviceSimulator(abc.ABC):
    """The device side of one motor controller.

    :param motor: the motor block this simulator answers for.
    :param model: the motor physics; a default model when omitted.
    """

    def __init__(self, motor: MotorConfig, model: MotorModel | None = None) -> None:
        self.motor = motor
        self.model = model if model is not None else MotorModel()
        if motor.steering:
            # A steering actuator starts with its wheels at their neutral angle, and holds
            # position once armed (until the first angle command, where it stands).
            self.model.position_rad = motor.zero_rad
            self.model.target_position_rad = motor.zero_rad
            self.model.max_speed_rad_s = motor.max_rpm * 2.0 * math.pi / 60.0
        self.faults = SimFault.NONE
        self._last_tick_s: float | None = None
        self._drop_toggle = False
        #: Frames the simulator received, for assertions.
        self.received = 0
        #: How long ``SimFault.LATE`` holds every frame the device sends (s).
        self.latency_s = 0.02
        #: The random source of ``SimFault.GARBAGE``, seeded with the node ID so runs repeat.
        self.garbage_rng = random.Random(motor.node_id)
        #: Garbage frames sent (``SimFault.GARBAGE``), for assertions.
        self.garbage_sent = 0
        self._held: collections.deque[tuple[float, Frame]] = collections.deque()
        #: Where the device's cyclic frames start within their period after its first tick
        #: (a fraction, 0 to 1, see :meth:`due`): its power-up's offset.  A real
        #: controller's timers run from its own power-up, so two controllers never send in
        #: step (each ODrive's estimates at a phase of their own):
        #: :func:`gateway.sim.registry.simulators_for` gives the devices of a robot phases
        #: apart (:func:`spread_phase`).  A device alone starts at its first tick.
        self.phase = 0.0

    # ----------------------------------------------------------------- public

    def handle(self, frame: Frame, now_s: float) -> list[Frame]:
        """Take a frame from the bus; return the frames the device answers with."""
        self.received += 1
        if self.faults & SimFault.SILENT:
            self._held.clear()
            return []
        out = self._on_frame(frame, now_s)
        if self.faults & SimFault.MUTE:
            self._held.clear()
            return []
        return self._emit(out, now_s)

    def tick(self, now_s: float) -> list[Frame]:
        """Advance the motor to ``now_s``; return the periodic frames due."""
        if self._last_tick_s is not None:
            self._move(now_s - self._last_tick_s)
        self._last_tick_s = now_s
        out = self._on_tick(now_s)
        if self.faults & (SimFault.SILENT | SimFault.MUTE):
            self._held.clear()
            return []
        return self._emit(out, now_s)

    def advance(self, now_s: float) -> None:
        """Advance the motor to ``now_s`` (after its first tick, never back), sending nothing:
        what it measures when a frame arrives at ``now_s`` between two ticks (a CiA 402
        drive's TPDO samples its position at the SYNC)."""
        last = self._last_tick_s
        if last is not None and now_s > last:
            self._move(now_s - last)
            self._last_tick_s = now_s

    def _move(self, dt_s: float) -> None:
        if self.faults & SimFault.STALL:
            self.model.velocity_rad_s = 0.0  # blocked: the shaft does not turn
        else:
            self.model.step(dt_s)

    def due(self, due_s: float | None, now_s: float, period_s: float) -> float:
        """When a cyclic frame of period ``period_s`` is due: ``due_s`` once scheduled; the
        first one (``due_s`` ``None``, at the first tick ``now_s``) :attr:`phase` of a period
        later."""
        return now_s + self.phase * period_s if due_s is None else due_s

    def inject(self, fault: SimFault) -> None:
        """Add ``fault`` to the active faults (FAULT also disarms the motor)."""
        self.faults |= fault
        if fault & SimFault.FAULT:
            self.model.armed = False
            self._on_fault()

    def clear(self, fault: SimFault = ~SimFault.NONE) -> None:
        """Remove ``fault`` (all by default) from the active faults.

        A reported controller fault stays latched in the device until the protocol's clear
        command arrives, as on the real controllers.  Frames held by ``LATE`` go out, in
        order and ahead of newer ones, at the next :meth:`handle` or :meth:`tick`.
        """
        self.faults &= ~fault

    @property
    def wheel_position_rad(self) -> float:
        """Ground truth: the wheel angle in rad (motor angle through gear ratio and sign)."""
        return self.motor.motor_to_wheel_rad_s(self.model.position_rad)

    @property
    def wheel_velocity_rad_s(self) -> float:
        """Ground truth: the wheel speed in rad/s."""
        return self.motor.motor_to_wheel_rad_s(self.model.velocity_rad_s)

    @property
    def steer_rad(self) -> float:
        """Ground truth of a steering actuator: the steering angle in rad."""
        return self.motor.motor_to_steer_rad(self.model.position_rad)

    # ----------------------------------------------------------------- hooks

    @abc.abstractmethod
    def _on_frame(self, frame: Frame, now_s: float) -> list[Frame]:
        """Protocol reaction to a received frame."""

    @abc.abstractmethod
    def _on_tick(self, now_s: float) -> list[Frame]:
        """Protocol periodic output; also applies command timeouts."""

    def _on_fault(self) -> None:  # noqa: B027 - optional hook
        """Latch the protocol's fault state (override to set error bits)."""

    @property
    def held(self) -> int:
        """Frames ``SimFault.LATE`` holds back now."""
        return len(self._held)

    # ----------------------------------------------------------------- internals

    def _emit(self, frames: list[Frame], now_s: float) -> list[Frame]:
        """Apply GARBAGE, DROP and LATE (in that order) to what the device emits now."""
        faults = self.faults
        if not faults and not self._held:
            return frames
        if faults & SimFault.GARBAGE:
            frames = [self._garble(f) for f in frames]
        frames = self._filter(frames)
        held = self._held
        if faults & SimFault.LATE:
            due = now_s + self.latency_s
            held.extend((due, f) for f in frames)
            out = []
            while held and held[0][0] <= now_s + 1e-12:
                out.append(held.popleft()[1])
            return out
        if not held:
            return frames
        # LATE was cleared: what it still holds goes out first, then the new frames.
        out = [f for _, f in held]
        held.clear()
        return out + frames

    def _garble(self, frame: Frame) -> Frame:
        rng = self.garbage_rng
        self.garbage_sent += 1
        data = rng.randbytes(rng.randint(0, 8))
        return type(frame)(frame.arbitration_id, data, frame.is_extended_id)

    def _filter(self, frames: list[Frame]) -> list[Frame]:
        if not frames or not self.faults & SimFault.DROP:
            return frames
        kept = []
        for f in frames:
            self._drop_toggle = not self._drop_toggle
            if self._drop_toggle:
                kept.append(f)
        return kept
