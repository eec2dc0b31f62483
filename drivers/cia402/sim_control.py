"""Device control of the simulated CiA 402 drive, as pure parts: the controlword decoded from
its bits, how long each commanded transition takes, the quick stop ramp, and the heartbeat
consumer.  :class:`~drivers.cia402.sim.Cia402Simulator` puts them together.

**Transitions take time.**  A drive confirms a controlword in its statusword only once the
transition is done: switching the power stage on (SWITCHED ON) charges the DC link and
enables the bridge, enabling operation releases the holding brake and closes the control loops.
Real drives take from a few milliseconds to hundreds of milliseconds for these, and their
statusword lags the controlword meanwhile.  :class:`Timing` holds the simulator's delays; its
defaults are assumptions of this project, not figures of a given drive: about two cycles of a
1 kHz drive state machine (2 ms) for any transition, 10 ms to switch the power stage on, 30 ms
to enable operation (of the order of a holding brake's release time, tens of milliseconds).
A test that wants the old instant device passes zeros.

**Quick stop** (CiA 402, object 0x605A "quick stop option code"): 0 disable drive function
(the power stage switches off at once: the motor coasts), 1 slow down on the slow-down ramp
(0x6084 profile deceleration), 2 on the quick-stop ramp (0x6085 quick stop deceleration),
3 at the current limit, 4 at the voltage limit, each then SWITCH ON DISABLED (transition 12,
automatic); 5 to 8 as 1 to 4 but staying in QUICK STOP ACTIVE, from where ENABLE OPERATION
(transition 16) returns to OPERATION ENABLED.  The profile's usual default is 2 (e.g. Beckhoff
AX8000 object 0x605A: default 2, "slow down on quick stop ramp and transit into switch on
disabled").  The simulator models the current and voltage limits as the motor model's own
acceleration limit.

**Heartbeat consumer** (CiA 301, object 0x1016): an entry ``node << 16 | ms`` watches node
``node``'s heartbeat (COB-ID 0x700 + node) from the first one after the entry was written
(CANopenNode ``301/CO_HBconsumer.h``: "Monitoring starts after the reception of the first
HeartBeat (not bootup)"); silence for longer than ``ms`` is a heartbeat event, after which it
waits for the next heartbeat to watch again.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

from drivers.cia402.enums import CobBase, NmtState, State

if TYPE_CHECKING:
    from gateway.core.types import Frame

#: The quick stop option codes (0x605A) after which the drive stays in QUICK STOP ACTIVE.
STAY_IN_QUICK_STOP = range(5, 9)


@dataclass(frozen=True, slots=True)
class Timing:
    """How long the simulated drive takes for a commanded transition (s); see the module.

    :param state_s: any transition not named below.
    :param switch_on_s: into SWITCHED ON (power stage on).
    :param enable_s: into OPERATION ENABLED (brake released, loops closed).
    """

    state_s: float = 0.002
    switch_on_s: float = 0.01
    enable_s: float = 0.03

    def delay(self, target: State) -> float:
        """The time a transition into ``target`` takes."""
        if target is State.OPERATION_ENABLED:
            return self.enable_s
        if target is State.SWITCHED_ON:
            return self.switch_on_s
        return self.state_s


def next_state(state: State, controlword: int, *, rising_reset: bool, fault_active: bool,
               quick_stop_option: int) -> State:
    """Where a controlword takes the drive (CiA 402 "device control commands", decoded from
    the bits, not from the driver's transition table); ``state`` if nowhere.

    :param rising_reset: bit 7 rose with this controlword (fault reset acts on the edge).
    :param fault_active: the cause of a fault is still there (the reset does not take).
    :param quick_stop_option: 0x605A (transition 16 only with 5 to 8).
    """
    if state is State.FAULT:
        return State.SWITCH_ON_DISABLED if rising_reset and not fault_active else state  # 15
    if state in (State.FAULT_REACTION_ACTIVE, State.NOT_READY_TO_SWITCH_ON):
        return state
    switch_on, voltage, no_qs, enable_op = (bool(controlword & b) for b in (0x1, 0x2, 0x4, 0x8))
    if not voltage:  # disable voltage: 7, 9, 10, 12
        return State.SWITCH_ON_DISABLED
    if not no_qs:  # quick stop: 11, or 7 / 10
        if state is State.OPERATION_ENABLED:
            return State.QUICK_STOP_ACTIVE
        if state in (State.READY_TO_SWITCH_ON, State.SWITCHED_ON):
            return State.SWITCH_ON_DISABLED
        return state
    if not switch_on:  # shutdown: 2, 6, 8
        if state in (State.SWITCH_ON_DISABLED, State.SWITCHED_ON, State.OPERATION_ENABLED):
            return State.READY_TO_SWITCH_ON
        return state
    if not enable_op:  # switch on / disable operation: 3, 5
        if state in (State.READY_TO_SWITCH_ON, State.OPERATION_ENABLED):
            return State.SWITCHED_ON
        return state
    if state in (State.READY_TO_SWITCH_ON, State.SWITCHED_ON):
        return State.OPERATION_ENABLED  # enable operation: 3+4, 4
    if state is State.QUICK_STOP_ACTIVE and quick_stop_option in STAY_IN_QUICK_STOP:
        return State.OPERATION_ENABLED  # 16
    return state


def quick_stop_deceleration(option: int, slow_down_rad_s2: float,
                            quick_stop_rad_s2: float) -> float | None:
    """The deceleration (rad/s^2, motor side) of quick stop option code ``option``: the
    slow-down ramp, the quick-stop ramp, ``inf`` at the current or voltage limit, ``None``
    for 0 (disable drive function: no ramp, the motor coasts)."""
    base = option - 4 if option in STAY_IN_QUICK_STOP else option
    if base == 1:
        return slow_down_rad_s2
    if base == 2:
        return quick_stop_rad_s2
    return math.inf if base in (3, 4) else None


@dataclass(slots=True)
class QuickStopRamp:
    """The speed setpoint in QUICK STOP ACTIVE (motor side, rad/s): from the speed at the
    quick stop down to 0 at ``decel_rad_s2``."""

    speed_rad_s: float
    decel_rad_s2: float
    last_s: float

    def step(self, now_s: float) -> float:
        """The setpoint at ``now_s``."""
        dt = max(now_s - self.last_s, 0.0)
        self.last_s = now_s
        left = max(abs(self.speed_rad_s) - self.decel_rad_s2 * dt, 0.0)
        self.speed_rad_s = math.copysign(left, self.speed_rad_s) if left else 0.0
        return self.speed_rad_s


class HeartbeatConsumer:
    """One heartbeat consumer entry (0x1016:01) of a simulated drive."""

    __slots__ = ("_last_s", "events", "node_id", "time_s")

    def __init__(self) -> None:
        #: The watched node (0: the entry is not used).
        self.node_id = 0
        #: The consumer time (s; 0: the entry is not used).
        self.time_s = 0.0
        #: Heartbeat events so far.
        self.events = 0
        self._last_s: float | None = None

    def configure(self, entry: int) -> None:
        """Take a new entry (``node << 16 | ms``); watching starts at the next heartbeat."""
        self.node_id = (entry >> 16) & 0xFF
        self.time_s = (entry & 0xFFFF) / 1000.0
        self._last_s = None

    @property
    def watching(self) -> bool:
        """Whether a heartbeat has been seen since the entry was set (the timer runs)."""
        return self._last_s is not None

    def on_heartbeat(self, frame: Frame, now_s: float) -> None:
        """Take a frame on a heartbeat COB-ID (0x700 + node)."""
        if (not self.time_s or frame.arbitration_id != CobBase.HEARTBEAT + self.node_id
                or len(frame.data) != 1):
            return
        boot_up = frame.data[0] & 0x7F == NmtState.BOOT_UP
        self._last_s = None if boot_up else now_s  # a boot-up starts the watch afresh

    def expired(self, now_s: float) -> bool:
        """Whether a heartbeat event happens at ``now_s`` (once per silence)."""
        last = self._last_s
        if last is None or not self.time_s or now_s - last <= self.time_s:
            return False
        self._last_s = None
        self.events += 1
        return True
