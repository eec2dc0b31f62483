"""Steering actuators through the generic DBC driver: the options and their errors, and driver +
simulator on a virtual bus."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import pytest

from drivers.dbc import DbcDriver
from drivers.dbc.sim import DbcSimulator
from gateway.core.errors import ConfigError
from gateway.core.types import DriveState
from gateway.sim.device import SimFault
from tests import factories
from tests.drivers import steering_dbc_helpers
from tests.drivers.dbc_helpers import EXAMPLE
from tests.drivers.steering_dbc_helpers import (
    COUNT_STEER,
    GEAR,
    STEER_EXAMPLE,
    counts,
    drive_motor,
    odrive_steer,
    steer_motor,
)
from tests.drivers.test_drivers_dbc_sim import rig

if TYPE_CHECKING:
    from collections.abc import Callable, Mapping


# The shared fixtures (steering_dbc_helpers.py), bound here so that pytest finds them.
steer_dbc = steering_dbc_helpers.steer_dbc


# ----------------------------------------------------------------------------- configuration


def _error(make: Callable[[], object]) -> str:
    with pytest.raises(ConfigError) as info:
        make()
    return str(info.value)


def test_a_steering_block_needs_a_position_command(steer_dbc: str) -> None:
    opts = {**EXAMPLE, "dbc": steer_dbc}
    m = factories.steer_motor("dbc", 5, wheel="fl steering", options=opts)
    assert _error(lambda: DbcDriver([m])) == (
        "wheels['fl steering'].motor.position_command_message: expected a non-empty name for a "
        "steering actuator's position command (it is commanded in position, not in velocity), "
        "got ''"
    )
    both = {**opts, **{k: STEER_EXAMPLE[k] for k in ("position_command_message",
                                                        "position_command_signal")}}
    m = factories.steer_motor("dbc", 5, wheel="fl steering", options=both)
    assert "motor.command_message: a steering actuator is commanded in position" in _error(
        lambda: DbcDriver([m])
    )


def test_a_drive_block_needs_a_velocity_command(steer_dbc: str) -> None:
    opts = {**STEER_EXAMPLE, "dbc": steer_dbc}
    m = factories.motor("dbc", 1, "rear", options=opts)
    assert _error(lambda: DbcDriver([m])) == (
        "wheels['rear'].motor.command_message: expected a non-empty name for a drive motor's "
        "velocity command, got ''"
    )
    m = factories.motor("dbc", 1, "rear", options={
        **EXAMPLE, "dbc": steer_dbc, "position_command_message": "WD_Position_Command",
        "position_command_signal": "Target_Position"})
    assert "only a steering actuator takes a position command; expected '' for a drive motor" in (
        _error(lambda: DbcDriver([m]))
    )


def test_config_load_needs_one_of_the_commands() -> None:
    opts = {k: v for k, v in EXAMPLE.items() if not k.startswith("command_")}
    assert _error(lambda: DbcDriver.validate_options(opts, "r.yaml: steering.fl")).startswith(
        "r.yaml: steering.fl.command_message: required key is missing (a drive motor names"
    )
    half = {**opts, "position_command_message": "WD_Position_Command"}
    assert _error(lambda: DbcDriver.validate_options(half, "w")) == (
        "w.position_command_signal: required when position_command_message is given"
    )
    assert _error(lambda: DbcDriver.validate_options(
        {**half, "position_command_signal": "T", "position_mode_message": "M"}, "w"
    )) == "w.position_mode_values: required when position_mode_message is given"
    assert _error(lambda: DbcDriver.validate_options(
        {**half, "position_command_signal": "T", "position_mode_values": {"A": True}}, "w"
    )) == "w.position_mode_values.A: expected a number, got True"


@pytest.mark.parametrize(
    ("over", "message"),
    [
        (
            {"position_command_signal": "Target"},
            "motor.position_command_signal: message 'WD_Position_Command' has no signal "
            "'Target'; known signals: Position_Mode, Target_Position (in {dbc})",
        ),
        (
            {"position_mode_values": {"Mode": 3}},
            "motor.position_mode_values: message 'WD_Position_Command' has no signal 'Mode'",
        ),
        (
            {"position_mode_values": {"Position_Mode": 9}},
            "motor.position_mode_values.Position_Mode: expected a value between 0 and 3 for "
            "signal 'Position_Mode' of message 'WD_Position_Command' in {dbc}, got 9.0",
        ),
        (
            {"position_command_message": "WD_Small_Position_Command",
             "position_command_signal": "Small_Target", "position_mode_message": "",
             "position_mode_values": {}, "counts_per_rev": 8192},
            "motor.position_command_signal: signal 'Small_Target' of message "
            "'WD_Small_Position_Command' in {dbc} carries -32768 to 32767, but steering angles "
            "from -3.14159 to 3.14159 rad (motor positions -40.2124 to 40.2124 rad) need "
            "-52428.8 to 52428.8; use a wider signal",
        ),
        (
            {"position_wrap_bits": 15},
            "motor.position_wrap_bits: signal 'Position_Count' of message 'WD_Feedback' in "
            "{dbc} wraps every 32768 (2**15 steps), but the absolute position of steering "
            "angles from -3.14159 to 3.14159 rad",
        ),
        (
            {"position_message": "WD_Angle", "position_signal": "Rotor_Angle",
             "position_unit": "deg", "position_wrap_bits": 13},
            "motor.position_wrap_bits: signal 'Rotor_Angle' of message 'WD_Angle' in {dbc} "
            "wraps every 360",
        ),
    ],
)
def test_steering_config_errors_name_file_message_and_signal(
    steer_dbc: str, over: dict[str, Any], message: str
) -> None:
    text = _error(lambda: DbcDriver([steer_motor(steer_dbc, **over)]))
    assert message.format(dbc=steer_dbc) in text
    assert text.startswith("wheels['front_left steering'].motor.")


def test_small_signal_is_enough_for_a_narrow_travel(steer_dbc: str) -> None:
    m = steer_motor(steer_dbc, position_command_message="WD_Small_Position_Command",
                    position_command_signal="Small_Target", position_mode_message="",
                    position_mode_values={}, travel=1.0)
    DbcDriver([m])
    DbcDriver([steer_motor(steer_dbc, position_wrap_bits=16)])  # 16 motor turns > 12.8


# ----------------------------------------------------------------------------- on the bus


def steers(drv: DbcDriver, sims: Mapping[int, DbcSimulator], tol: float) -> Callable[[float], None]:
    """A check that every fresh steering feedback equals the simulator's ground truth."""

    def check(t: float) -> None:
        for i, sim in sims.items():
            fb = drv.feedback(i)
            if fb is not None and fb.timestamp_s == t:
                assert abs(fb.position_rad - sim.steer_rad) <= tol, (i, t)

    return check


def test_odrive_steering_actuator_reaches_the_angle_faults_and_recovers(channel: str) -> None:
    m = odrive_steer(3, zero_rad=2.0)
    drv, sim = DbcDriver([m]), DbcSimulator(odrive_steer(3, zero_rad=2.0))
    sim.fault_code = 0x40  # MOTOR_FAILED
    tol = 4 * 2**-23 / GEAR  # float32 turns near 1 turn, as a steering angle
    with rig(channel, drv, [sim]) as r:
        r.run(0.05, [0.4])
        assert drv.state(0, r.t) == DriveState.DISABLED
        assert not sim.position_mode and sim.steer_rad == pytest.approx(0.0)
        r.send(drv.enable(r.t))
        r.run(0.5, [0.4], steers(drv, {0: sim}, tol))
        assert sim.position_mode and drv.state(0, r.t) == DriveState.ENABLED
        fb = drv.feedback(0)
        assert fb is not None
        assert fb.position_rad == pytest.approx(0.4, abs=1e-3)
        assert sim.steer_rad == pytest.approx(0.4, abs=1e-3)
        assert abs(fb.velocity_rad_s) < 1e-2
        sim.inject(SimFault.FAULT)
        r.run(0.05, [-0.3])
        status = drv.status(r.t)[0]
        assert (status.state, status.detail) == (DriveState.FAULT, "Axis_Error=MOTOR_FAILED")
        sim.clear(SimFault.FAULT)
        r.send(drv.enable(r.t))
        r.run(0.5, [-0.3], steers(drv, {0: sim}, tol))
        assert drv.state(0, r.t) == DriveState.ENABLED
        fb = drv.feedback(0)
        assert fb is not None and fb.position_rad == pytest.approx(-0.3, abs=1e-3)
        assert sim.steer_rad == pytest.approx(-0.3, abs=1e-3)


def test_mixed_driver_on_the_bus_across_a_16_bit_wrap(channel: str, steer_dbc: str) -> None:
    # Neutral at -3 rad: raw 63580 of 65536, so steering to +0.4 crosses the counter's wrap.
    drive = drive_motor(steer_dbc, 1)
    steer = steer_motor(steer_dbc, 2, zero_rad=-3.0, position_wrap_bits=16)
    drv = DbcDriver([drive, steer])
    sims = [DbcSimulator(drive), DbcSimulator(steer)]
    with rig(channel, drv, sims) as r:
        r.run(0.05, [1.0, 0.4])
        assert sims[1].position_raw() == counts(-3.0) % 65536
        fb = drv.feedback(1)
        assert fb is not None and fb.position_rad == pytest.approx(0.0, abs=COUNT_STEER)
        r.send(drv.enable(r.t))
        r.run(0.6, [1.0, 0.4], steers(drv, {1: sims[1]}, COUNT_STEER))
        assert sims[1].position_raw() < 2000  # wrapped through 65535 -> 0
        assert [s.state for s in drv.status(r.t)] == [DriveState.ENABLED] * 2
        fb = drv.feedback(1)
        assert fb is not None and fb.position_rad == pytest.approx(0.4, abs=2 * COUNT_STEER)
        wheel = drv.feedback(0)
        assert wheel is not None and wheel.velocity_rad_s == pytest.approx(1.0, abs=0.01)
        sims[1].inject(SimFault.FAULT)
        r.run(0.05, [1.0, -0.2])
        assert [s.state for s in drv.status(r.t)] == [DriveState.ENABLED, DriveState.FAULT]
        sims[1].clear(SimFault.FAULT)
        r.send(drv.enable(r.t))
        r.run(0.6, [1.0, -0.2], steers(drv, {1: sims[1]}, COUNT_STEER))
        assert drv.state(1, r.t) == DriveState.ENABLED
        assert sims[1].steer_rad == pytest.approx(-0.2, abs=2 * COUNT_STEER)
        r.send(drv.disable(r.t))
        r.run(0.1, [1.0, 0.3])
        assert not sims[1].model.armed and drv.state(1, r.t) == DriveState.DISABLED
        assert sims[1].steer_rad == pytest.approx(-0.2, abs=0.01)  # released where it stood
