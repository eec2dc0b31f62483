"""A generic device simulator for any controller described by a DBC file.

It reads the same motor block as :class:`drivers.dbc.DbcDriver`, decodes the command (and
arming) message with the same DBC, drives a :class:`~gateway.sim.device.MotorModel` and emits the
feedback message(s) periodically.  Like a real encoder, the position is quantised to the
signal's scale (or to float32 for float signals) and wraps: modulo ``2**position_wrap_bits``,
else modulo the signal's bit width.  ``initial_raw`` starts the counter anywhere, e.g. next to
its wrap point.

Device behaviour: with an enable signal configured the motor is disarmed until the enable value
arrives, and the disable value disarms it; without one it follows commands from the start.  An
injected ``SimFault.FAULT`` disarms the motor and reports ``fault_code`` in the fault signal;
the code stays latched until the fault is cleared in the simulator *and* (with an enable
signal) the enable value arrives again.

**Command timeout.**  The simulator stands for the user's controller, which has whatever the
motor block states was set on it: with ``controller_timeout_s`` (the controller's own timeout,
set with the vendor's tool), the motor stops (target speed 0) when no command frame arrives for
that long, and follows the next command again.  With none stated, nothing is known to stop the
real controller, so the simulator assumes the worst and holds the last command for ever: it is
never kinder than what the configuration states.  ``command_timeout_s`` overrides the block.

A steering actuator (``motor.steering``) follows the position command instead: each value sets
``model.target_position_rad`` (the model's position loop), once position control is selected,
which is from the start without ``position_mode_message`` and otherwise when a frame carries
every configured ``position_mode_values`` (another value deselects it: the motor stops where it
stands).  Its position signal reports the ABSOLUTE motor position in the controller's frame
(``initial_raw`` 0, the signal's offset undone), quantised and wrapped as above.  Without
commands for ``command_timeout_s`` it holds where it stands.
"""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING

from drivers.dbc.binding import bind_motor
from drivers.dbc.codec import DbcCodec, DbcReading, Role
from drivers.dbc.database import DatabaseCache
from drivers.dbc.options import motor_where, parse_options
from drivers.dbc.units import UnitConversion
from gateway.core.errors import DecodeError
from gateway.sim.device import DeviceSimulator, SimFault

if TYPE_CHECKING:
    from gateway.core.types import Frame, MotorConfig
    from gateway.sim.device import MotorModel

log = logging.getLogger(__name__)


class DbcSimulator(DeviceSimulator):
    """The device side of one ``driver: dbc`` motor.

    :param motor: the motor block (the same one the driver gets).
    :param model: the motor physics; a default model when omitted.
    :param rate_hz: how often the feedback message(s) are sent (Hz, > 0).
    :param initial_raw: raw position signal value at motor angle 0.
    :param command_timeout_s: stop after this long without a command (s); 0 = never;
        ``None`` (default): the block's ``controller_timeout_s``, i.e. never when not stated.
    :param fault_code: raw value of the fault signal while a fault is latched (non-zero).
    :raises ConfigError: as :class:`drivers.dbc.DbcDriver` for a bad motor block.
    :raises ValueError: for a rate that is not positive or a zero fault code.
    """

    def __init__(
        self,
        motor: MotorConfig,
        model: MotorModel | None = None,
        *,
        rate_hz: float = 100.0,
        initial_raw: int | float = 0,
        command_timeout_s: float | None = None,
        fault_code: int = 1,
    ) -> None:
        super().__init__(motor, model)
        if not rate_hz > 0.0:
            raise ValueError(f"Expected a feedback rate above 0 Hz, but got {rate_hz!r}.")
        if fault_code == 0:
            raise ValueError("Expected a non-zero fault code, but got 0.")
        where = motor_where(motor)
        opts = parse_options(motor.options, where, motor.role)
        self.binding = bind_motor(motor, opts, DatabaseCache(), where)
        self.codec = DbcCodec([self.binding])
        self.units = UnitConversion.build(motor, opts)
        self.period_s = 1.0 / rate_hz
        self.initial_raw = initial_raw
        #: Stop after this long without a command frame (s); 0: never.
        self.command_timeout_s = (
            opts.controller_timeout_s if command_timeout_s is None else command_timeout_s
        )
        self.fault_code = fault_code
        pos = self.binding.position
        self._wrap_bits = 0 if pos.is_float else (opts.position_wrap_bits or pos.signal.length)
        self._signed_wrap = bool(pos.signal.is_signed) and self._wrap_bits == pos.signal.length
        self._latched = 0
        self._last_command_s: float | None = None
        self._next_emit_s: float | None = None
        self.model.armed = self.binding.enable is None
        #: Whether position control is selected (a steering actuator).
        self.position_mode = not self.binding.mode
        #: Last command signal value received (signal units), ``None`` before the first.
        self.last_command: float | None = None
        #: Malformed frames of the configured command messages.
        self.rejected = 0

    def position_raw(self) -> int | float:
        """The raw position signal value for the model's current angle."""
        value = self.units.motor_to_position(self.model.position_rad)
        if self.motor.steering:
            value -= float(self.binding.position.signal.offset)
        step = value / self.binding.position.scale
        if not self._wrap_bits:
            return self.initial_raw + step
        raw = (int(self.initial_raw) + round(step)) % (1 << self._wrap_bits)
        if self._signed_wrap and raw >= 1 << (self._wrap_bits - 1):
            raw -= 1 << self._wrap_bits
        return raw

    def clear(self, fault: SimFault = ~SimFault.NONE) -> None:
        """Remove injected faults; without an enable signal this also unlatches the code."""
        super().clear(fault)
        if self.binding.enable is None and not self.faults & SimFault.FAULT and self._latched:
            self._latched = 0
            self.model.armed = True

    # ----------------------------------------------------------------- hooks

    def _on_frame(self, frame: Frame, now_s: float) -> list[Frame]:
        try:
            requests = self.codec.decode_request(frame)
        except DecodeError as err:
            self.rejected += 1
            log.debug(
                "simulated node %d rejects %s: %s", self.motor.node_id, frame.to_cansend(), err
            )
            return []
        mine = [r for r in requests or () if r.node_id == self.motor.node_id]
        self._select_mode([r.value for r in mine if r.role == Role.MODE])
        for req in mine:
            if req.role == Role.COMMAND:
                self.last_command = req.value
                self._last_command_s = now_s
                self.model.target_rad_s = self.units.command_to_motor(req.value)
            elif req.role == Role.POSITION_COMMAND:
                self.last_command = req.value
                self._last_command_s = now_s
                if self.position_mode:
                    self.model.target_position_rad = self.units.target_to_motor(req.value)
            elif req.role == Role.ENABLE:
                self._arm(req.value)
        return []

    def _select_mode(self, values: list[float]) -> None:
        """Select or deselect position control from the mode signals of one frame."""
        if not values:
            return
        wanted = self.binding.mode
        on = len(values) == len(wanted) and all(
            abs(got - want) <= abs(ref.scale) / 2.0
            for got, (ref, want) in zip(values, wanted, strict=True)
        )
        if on and not self.position_mode:
            self.model.target_position_rad = self.model.position_rad
        elif not on:
            self.model.target_position_rad = None
            self.model.target_rad_s = 0.0
        self.position_mode = on

    def _arm(self, value: float) -> None:
        enable = self.binding.enable
        if enable is None:
            return
        tol = abs(enable.scale) / 2.0
        if abs(value - self.binding.enable_value) <= tol:
            if not self.faults & SimFault.FAULT:
                self._latched = 0
            self.model.armed = not self._latched
        elif abs(value - self.binding.disable_value) <= tol:
            self.model.armed = False

    def _on_tick(self, now_s: float) -> list[Frame]:
        if (
            self.command_timeout_s > 0.0
            and self._last_command_s is not None
            and now_s - self._last_command_s > self.command_timeout_s
        ):
            self.model.target_rad_s = 0.0
            if self.model.target_position_rad is not None:
                self.model.target_position_rad = self.model.position_rad
        due = self._next_emit_s = self.due(self._next_emit_s, now_s, self.period_s)
        if now_s < due - 1e-9:
            return []
        # Keep the cadence; restart it after a gap longer than one period.
        start = now_s if now_s - due > self.period_s else due
        self._next_emit_s = start + self.period_s
        vel = self.binding.velocity
        velocity = self.units.motor_to_velocity(self.model.velocity_rad_s)
        reading = DbcReading(
            node_id=self.motor.node_id,
            velocity=min(max(velocity, vel.minimum), vel.maximum),
            position_raw=self.position_raw(),
            fault=self._latched if self.binding.fault is not None else None,
        )
        return list(self.codec.encode_feedback([reading]))

    def _on_fault(self) -> None:
        self._latched = self.fault_code


def simulator_for(motor: MotorConfig) -> DbcSimulator:
    """A generic simulator of ``motor`` that speaks its DBC messages and stops the motor
    ``controller_timeout_s`` after the last command, if the block states one (else never)
    (registered in :data:`drivers.BUILTIN_SIMULATORS`)."""
    return DbcSimulator(motor)
