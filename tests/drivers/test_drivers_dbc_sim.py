"""Tests of the generic DBC driver with its simulator on a python-can virtual bus.

Everything runs in simulated time (``SimulatedControllers.step``), so no assertion depends on
the wall clock.  Motor blocks and constants come from :mod:`tests.drivers.dbc_helpers`.
"""

from __future__ import annotations

import contextlib
import dataclasses
import struct
from typing import TYPE_CHECKING

import can
import pytest

from drivers.dbc import DbcDriver
from drivers.dbc.sim import DbcSimulator, simulator_for
from gateway.bus.can_bus import drain, send_frames
from gateway.core.errors import ConfigError
from gateway.core.types import DriveFault, DriveState, Frame
from gateway.sim.bus import SimulatedControllers
from gateway.sim.device import SimFault
from tests.drivers.dbc_helpers import ANGLE, COUNT_RAD, GEAR, TWO_PI, motor, odrive_motor

if TYPE_CHECKING:
    from collections.abc import Callable, Iterator

#: Simulated time step (s); the simulators send feedback at 100 Hz.
DT = 0.001


@dataclasses.dataclass
class Rig:
    """A gateway bus, stepped simulators and a driver in simulated time."""

    gw: can.BusABC
    ctl: SimulatedControllers
    drv: DbcDriver
    t: float = 0.0

    def send(self, frames: list[Frame]) -> None:
        send_frames(self.gw, frames)

    def run(
        self,
        seconds: float,
        speeds: list[float] | None,
        check: Callable[[float], None] | None = None,
    ) -> None:
        """Step for ``seconds``; command ``speeds`` each step (``None``: send nothing)."""
        for _ in range(round(seconds / DT)):
            self.t = round(self.t + DT, 9)
            self.ctl.step(self.t)
            got = False
            for frame in drain(self.gw):
                got |= self.drv.on_frame(frame.stamped(self.t))
            if got and check is not None:
                check(self.t)
            if speeds is not None:
                self.send(self.drv.poll(self.t) + self.drv.command(speeds, self.t))


@contextlib.contextmanager
def rig(channel: str, drv: DbcDriver, sims: list[DbcSimulator]) -> Iterator[Rig]:
    gw = can.Bus(interface="virtual", channel=channel)
    try:
        with SimulatedControllers(sims, channel) as ctl:
            yield Rig(gw, ctl, drv)
    finally:
        gw.shutdown()


def tracks(drv: DbcDriver, sims: list[DbcSimulator], tol: float) -> Callable[[float], None]:
    """A check that every fresh feedback position equals the simulator's ground truth."""

    def check(t: float) -> None:
        for i, sim in enumerate(sims):
            fb = drv.feedback(i)
            if fb is not None and fb.timestamp_s == t:
                assert abs(fb.position_rad - sim.wheel_position_rad) <= tol, (i, t)

    return check


def test_enable_drive_and_track_position_across_the_int32_wrap(channel: str) -> None:
    motors = [motor(3), motor(4, "right", invert=True)]
    drv = DbcDriver(motors)
    sims = [DbcSimulator(motors[0], initial_raw=2**31 - 3000), DbcSimulator(motors[1])]
    with rig(channel, drv, sims) as r:
        r.run(0.1, [3.0, -2.0])
        assert [s.state for s in drv.status(r.t)] == [DriveState.DISABLED] * 2
        assert not sims[0].model.armed and sims[0].last_command == 0.0
        r.send(drv.enable(r.t))
        r.run(1.0, [3.0, -2.0], tracks(drv, sims, COUNT_RAD))
        assert [s.state for s in drv.status(r.t)] == [DriveState.ENABLED] * 2
        assert sims[0].position_raw() < 0  # the counter wrapped through 2**31
        for i, speed in enumerate([3.0, -2.0]):
            fb = drv.feedback(i)
            assert fb is not None and fb.velocity_rad_s == pytest.approx(speed, abs=0.01)
            assert sims[i].wheel_velocity_rad_s == pytest.approx(speed, abs=0.01)
        assert sims[0].wheel_position_rad == pytest.approx(3.0 * 1.0, abs=0.1)
        assert sims[1].model.velocity_rad_s > 0.0  # inverted: the motor turns forwards
        r.send(drv.disable(r.t))
        r.run(0.2, [3.0, -2.0], tracks(drv, sims, COUNT_RAD))
        assert [s.state for s in drv.status(r.t)] == [DriveState.DISABLED] * 2
        assert not sims[1].model.armed and sims[1].last_command == 0.0
        assert abs(sims[0].model.velocity_rad_s) < 1e-6


def test_13_bit_angle_feedback_tracks_over_several_turns(channel: str) -> None:
    m = motor(3, extra=ANGLE)
    drv, sim = DbcDriver([m]), DbcSimulator(m, initial_raw=8100)
    with rig(channel, drv, [sim]) as r:
        r.send(drv.enable(0.0))
        r.run(0.5, [20.0], tracks(drv, [sim], TWO_PI / 8192 / GEAR))
        assert sim.model.position_rad > 5 * TWO_PI  # several motor turns, i.e. wraps
        fb = drv.feedback(0)
        assert fb is not None and fb.velocity_rad_s == pytest.approx(20.0, abs=0.01)


def test_fault_is_reported_and_cleared_by_enable(channel: str) -> None:
    motors = [motor(3), motor(4, "right")]
    drv = DbcDriver(motors)
    sims = [DbcSimulator(m) for m in motors]
    with rig(channel, drv, sims) as r:
        r.send(drv.enable(0.0))
        r.run(0.3, [2.0, 2.0])
        sims[0].inject(SimFault.FAULT)
        r.run(0.3, [2.0, 2.0], tracks(drv, sims, COUNT_RAD))
        left, right = drv.status(r.t)
        assert left.state == DriveState.FAULT
        assert left.faults == DriveFault.OVER_TEMPERATURE
        assert left.detail == "Fault_Code=OVER_TEMPERATURE"
        assert right.state == DriveState.ENABLED and right.faults == DriveFault.NONE
        assert abs(sims[0].model.velocity_rad_s) < 1e-3  # disarmed, stopped
        r.send(drv.enable(r.t))  # the condition persists: the device stays faulted
        r.run(0.1, [2.0, 2.0])
        assert drv.state(0, r.t) == DriveState.FAULT and not sims[0].model.armed
        sims[0].clear(SimFault.FAULT)
        r.run(0.1, [2.0, 2.0])
        assert drv.state(0, r.t) == DriveState.FAULT  # latched until armed again
        r.send(drv.enable(r.t))
        r.run(0.3, [2.0, 2.0], tracks(drv, sims, COUNT_RAD))
        assert drv.status(r.t)[0].state == DriveState.ENABLED
        assert drv.status(r.t)[0].detail == ""
        assert sims[0].wheel_velocity_rad_s == pytest.approx(2.0, abs=0.01)


def test_fault_without_enable_signal_clears_with_the_condition(channel: str) -> None:
    m = motor(3, enable_message="", enable_signal="")
    drv, sim = DbcDriver([m]), DbcSimulator(m, fault_code=6)
    assert sim.model.armed  # nothing to arm with: follows commands from the start
    with rig(channel, drv, [sim]) as r:
        assert drv.enable(0.0) == [Frame(0x203, struct.pack("<iBHx", 0, 2, 1000))]
        r.run(0.2, [1.0])
        sim.inject(SimFault.FAULT)
        r.run(0.1, [1.0])
        assert drv.status(r.t)[0].faults == DriveFault.OVER_CURRENT | DriveFault.ENCODER
        sim.clear()
        r.run(0.1, [1.0])
        assert drv.state(0, r.t) == DriveState.DISABLED  # the driver disarmed on the fault
        r.send(drv.enable(r.t))
        r.run(0.1, [1.0])
        assert drv.state(0, r.t) == DriveState.ENABLED


def test_silence_goes_offline_and_recovers_with_continuous_position(channel: str) -> None:
    m = motor(3, liveness_s=0.1)
    drv, sim = DbcDriver([m]), DbcSimulator(m)
    with rig(channel, drv, [sim]) as r:
        r.send(drv.enable(0.0))
        r.run(0.2, [1.5])
        assert drv.state(0, r.t) == DriveState.ENABLED
        sim.inject(SimFault.SILENT)
        r.run(0.09, [1.5])
        assert drv.state(0, r.t) == DriveState.ENABLED
        r.run(0.03, [1.5])
        assert drv.state(0, r.t) == DriveState.OFFLINE
        assert drv.status(r.t)[0].feedback_age_s == pytest.approx(0.12, abs=0.011)
        sim.clear(SimFault.SILENT)
        r.run(0.05, [1.5], tracks(drv, [sim], COUNT_RAD))
        assert drv.state(0, r.t) == DriveState.ENABLED


def test_dropped_frames_still_track(channel: str) -> None:
    m = motor(3)
    drv, sim = DbcDriver([m]), DbcSimulator(m, rate_hz=200.0)
    sim.inject(SimFault.DROP)
    with rig(channel, drv, [sim]) as r:
        r.send(drv.enable(0.0))
        r.run(0.3, [4.0], tracks(drv, [sim], COUNT_RAD))
        assert drv.state(0, r.t) == DriveState.ENABLED


def test_simulator_stops_when_commands_stop(channel: str) -> None:
    m = motor(3)
    drv, sim = DbcDriver([m]), DbcSimulator(m, command_timeout_s=0.1)
    with rig(channel, drv, [sim]) as r:
        r.send(drv.enable(0.0))
        r.run(0.2, [2.0])
        assert sim.wheel_velocity_rad_s == pytest.approx(2.0, abs=0.01)
        r.run(0.09, None)
        assert sim.model.target_rad_s != 0.0
        r.run(0.2, None)
        assert sim.model.target_rad_s == 0.0 and abs(sim.model.velocity_rad_s) < 1e-3


def test_odrive_dbc_drives_a_simulated_odrive(channel: str) -> None:
    m = odrive_motor(3)
    drv = DbcDriver([m])
    sim = simulator_for(m)
    sim.fault_code = 0x40  # MOTOR_FAILED
    with rig(channel, drv, [sim]) as r:
        r.run(0.05, [TWO_PI])
        assert drv.state(0, r.t) == DriveState.DISABLED
        r.send(drv.enable(r.t))
        r.run(0.5, [2.0 * TWO_PI], tracks(drv, [sim], 1e-5))
        assert sim.last_command == pytest.approx(2.0)  # rev/s
        fb = drv.feedback(0)
        assert fb is not None and fb.velocity_rad_s == pytest.approx(2.0 * TWO_PI, abs=1e-3)
        sim.inject(SimFault.FAULT)
        r.run(0.05, [2.0 * TWO_PI])
        status = drv.status(r.t)[0]
        assert (status.state, status.detail) == (DriveState.FAULT, "Axis_Error=MOTOR_FAILED")


def test_simulator_rejects_bad_arguments() -> None:
    with pytest.raises(ValueError, match="rate above 0 Hz"):
        DbcSimulator(motor(3), rate_hz=0.0)
    with pytest.raises(ValueError, match="non-zero fault code"):
        DbcSimulator(motor(3), fault_code=0)
    with pytest.raises(ConfigError, match="no message 'X'"):
        DbcSimulator(motor(3, command_message="X"))
