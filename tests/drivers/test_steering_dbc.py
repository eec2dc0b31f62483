"""Steering actuators through the generic DBC driver: options, golden frames, round trips,
absolute position across counter wraps, and driver + simulator on a virtual bus.

Golden frames:

* ODrive through the official DBC (``tests/data/odrive-cansimple-0.5.6.dbc``, pinned):
  the ODrive CAN protocol documentation (docs.odriverobotics.com, can-protocol), worked example
  "Set_Input_Pos, node 0: pos 1.5" (bytes
  0-3 ``00 00 C0 3F``, float32 turns) and the Set_Controller_Mode layout (i32 Control_Mode @0,
  i32 Input_Mode @4; POSITION_CONTROL = 3 and PASSTHROUGH = 1 from the DBC's ``VAL_ 107``
  tables, i.e. ``ODriveEnums.h``).
* A position-commanded variant of the fictional example controller: ``WD_Position_Command``,
  defined below and added to a copy of ``config/example_controller.dbc`` (whose messages other
  tests pin), packed by hand with ``struct`` and cross-checked with cantools.
"""

from __future__ import annotations

import functools
import math
import struct
from typing import TYPE_CHECKING, Any

import cantools
import pytest
from hypothesis import given
from hypothesis import strategies as st

from drivers.dbc import DbcDriver, DbcReading, Role
from drivers.dbc.sim import DbcSimulator
from gateway.core.errors import ConfigError, EncodeError
from gateway.core.types import DriveState, Frame, MotorConfig
from gateway.sim.device import SimFault
from tests import factories
from tests.conftest import CONFIG_DIR
from tests.drivers.test_drivers_dbc import EXAMPLE, ODRIVE_DBC, SETTINGS, TWO_PI, odrive_options
from tests.drivers.test_drivers_dbc_sim import rig

if TYPE_CHECKING:
    from collections.abc import Callable, Mapping
    from pathlib import Path

#: Appended to a copy of the example DBC: a position set-point that also selects the mode.
POSITION_MESSAGE = """
BO_ 896 WD_Position_Command: 8 Master
 SG_ Target_Position : 0|32@1- (1,0) [-2147483648|2147483647] "counts" WD100
 SG_ Position_Mode : 32|8@1+ (1,0) [0|3] "" WD100

BO_ 928 WD_Small_Position_Command: 2 Master
 SG_ Small_Target : 0|16@1- (1,0) [-32768|32767] "counts" WD100
"""
GEAR = 12.8
#: One encoder count of the example controller, as a steering angle (rad).
COUNT_STEER = TWO_PI / 4096 / GEAR
STEER_EXAMPLE: dict[str, object] = {
    **{k: v for k, v in EXAMPLE.items() if not k.startswith("command_")},
    "position_command_message": "WD_Position_Command",
    "position_command_signal": "Target_Position",
    "position_command_unit": "counts",
    "position_mode_message": "WD_Position_Command",
    "position_mode_values": {"Position_Mode": 3},
}


@pytest.fixture
def steer_dbc(tmp_path: Path) -> str:
    """The example DBC with the position-command messages added (before the comments)."""
    text = (CONFIG_DIR / "example_controller.dbc").read_text()
    at = text.index("\nCM_ ")
    path = tmp_path / "steer_controller.dbc"
    path.write_text(text[:at] + POSITION_MESSAGE + text[at:])
    return str(path)


def steer_motor(
    dbc: str,
    node: int = 5,
    zero_rad: float = 0.0,
    invert: bool = False,
    gear: float = GEAR,
    travel: float = math.pi,
    **over: object,
) -> MotorConfig:
    """A steering actuator of the factory (:func:`tests.factories.steer_motor`) on the example
    controller's position command in ``dbc``, travelling ``travel`` either way."""
    return factories.steer_motor(
        "dbc", node, zero_rad=zero_rad, gear_ratio=gear, invert=invert,
        steer_range_rad=(-travel, travel), options={**STEER_EXAMPLE, "dbc": dbc, **over},
    )


def drive_motor(dbc: str, node: int = 1) -> MotorConfig:
    """A drive motor of the factory on the example controller's velocity command in ``dbc``."""
    return factories.motor("dbc", node, "rear", gear_ratio=10.0, options={**EXAMPLE, "dbc": dbc})


def odrive_steer(node: int = 3, zero_rad: float = 0.0, gear: float = GEAR) -> MotorConfig:
    """A steering actuator of the factory on ODrive axis ``node``'s position command."""
    opts = odrive_options(node)
    del opts["command_message"], opts["command_signal"], opts["command_unit"]
    opts.update(
        position_command_message=f"Axis{node}_Set_Input_Pos",
        position_command_signal="Input_Pos",
        position_command_unit="rev",
        position_mode_message=f"Axis{node}_Set_Controller_Mode",
        position_mode_values={"Control_Mode": 3, "Input_Mode": 1},
    )
    return factories.steer_motor("dbc", node, zero_rad=zero_rad, gear_ratio=gear, options=opts)


def counts(motor_rad: float) -> int:
    return round(motor_rad / TWO_PI * 4096)


# ----------------------------------------------------------------------------- golden frames


def test_driver_declares_steering() -> None:
    assert DbcDriver.STEERING is True


def test_odrive_steering_golden_frames() -> None:
    # gear 1, neutral at 0.5 turn: an angle of one turn is motor position 1.5 turns.
    m = odrive_steer(0, zero_rad=0.5 * TWO_PI, gear=1.0)
    drv = DbcDriver([m])
    mode = Frame(0x00B, struct.pack("<ii", 3, 1))
    hold = Frame(0x00C, struct.pack("<fhh", 0.5, 0, 0))
    arm, idle = Frame(0x007, struct.pack("<I4x", 8)), Frame(0x007, struct.pack("<I4x", 1))
    assert drv.enable(0.0) == [mode, hold, arm]
    (frame,) = drv.command([TWO_PI], 0.0)
    assert frame == Frame(0x00C, bytes.fromhex("0000C03F00000000"))  # spec: pos 1.5 = 00 00 C0 3F
    db = cantools.database.load_file(ODRIVE_DBC)
    assert isinstance(db, cantools.database.can.Database)
    assert frame.data == db.encode_message(
        "Axis0_Set_Input_Pos", {"Input_Pos": 1.5, "Vel_FF": 0.0, "Torque_FF": 0.0}
    )
    assert mode.data == db.encode_message(
        "Axis0_Set_Controller_Mode", {"Control_Mode": "POSITION_CONTROL", "Input_Mode": 1}
    )
    # Feedback 1.25 turns: absolute, so the angle is 0.75 turn from neutral (no first-sample
    # subtraction).  The disable holds where it stands, then goes IDLE.
    assert drv.on_frame(Frame(0x009, struct.pack("<ff", 1.25, -0.5), timestamp_s=1.0))
    fb = drv.feedback(0)
    assert fb is not None
    assert (fb.position_rad, fb.velocity_rad_s) == (0.75 * TWO_PI, -0.5 * TWO_PI)
    assert drv.disable(1.0) == [Frame(0x00C, struct.pack("<fhh", 1.25, 0, 0)), idle]
    assert drv.command([TWO_PI], 1.0) == [Frame(0x00C, struct.pack("<fhh", 1.25, 0, 0))]


def test_example_position_command_golden_bytes(steer_dbc: str) -> None:
    m = steer_motor(steer_dbc, node=5, zero_rad=1.0)
    drv = DbcDriver([m])
    # Target_Position i32 LE counts, Position_Mode u8 = 3, 3 bytes unused; ID 0x380 + 5.
    hold = Frame(0x385, struct.pack("<iB3x", counts(1.0), 3))
    assert drv.enable(0.0) == [hold, Frame(0x185, b"\x01")]
    (frame,) = drv.command([0.25], 0.0)
    target = counts(1.0 + 0.25 * GEAR)
    assert frame == Frame(0x385, struct.pack("<iB3x", target, 3))
    db = cantools.database.load_file(steer_dbc)
    assert isinstance(db, cantools.database.can.Database)
    assert frame.data == db.encode_message(
        "WD_Position_Command", {"Target_Position": target, "Position_Mode": 3}
    )


def test_inverted_actuator_turns_the_other_way(steer_dbc: str) -> None:
    drv = DbcDriver([steer_motor(steer_dbc, zero_rad=0.5, invert=True)])
    drv.enable(0.0)
    (frame,) = drv.command([0.25], 0.0)
    assert struct.unpack_from("<i", frame.data)[0] == counts(0.5 - 0.25 * GEAR)


def test_mixed_driver_sends_velocity_and_position_frames(steer_dbc: str) -> None:
    drive, steer = drive_motor(steer_dbc, 1), steer_motor(steer_dbc, 2, zero_rad=0.0)
    drv = DbcDriver([steer, drive])  # any order
    assert drv.enable(0.0) == [
        Frame(0x382, struct.pack("<iB3x", 0, 3)),
        Frame(0x201, struct.pack("<iBHx", 0, 2, 1000)),
        Frame(0x182, b"\x01"),
        Frame(0x181, b"\x01"),
    ]
    frames = drv.command([0.1, 2.0], 0.0)
    rpm_x10 = round(2.0 * 10.0 * 60.0 / TWO_PI * 10)
    assert frames == [
        Frame(0x382, struct.pack("<iB3x", counts(0.1 * GEAR), 3)),
        Frame(0x201, struct.pack("<iBHx", rpm_x10, 2, 1000)),
    ]
    kinds = {
        f.arbitration_id: [r.role for r in drv.codec.decode_request(f) or ()] for f in frames
    }
    assert kinds == {0x382: [Role.POSITION_COMMAND, Role.MODE], 0x201: [Role.COMMAND]}
    assert drv.preview_command([0.1, 2.0]) == frames


@pytest.mark.parametrize("angle", [math.nan, math.inf, -math.inf])
def test_non_finite_steering_angle_is_refused(steer_dbc: str, angle: float) -> None:
    drv = DbcDriver([drive_motor(steer_dbc, 1), steer_motor(steer_dbc, 2)])
    drv.enable(0.0)
    with pytest.raises(EncodeError) as info:
        drv.command([1.0, angle], 0.0)
    assert str(info.value) == (
        'Expected a finite steering angle for DBC node 2 ("front_left steering") in rad, '
        f"but got {angle!r}."
    )


def test_angle_beyond_the_signal_names_signal_and_range(steer_dbc: str) -> None:
    m = steer_motor(steer_dbc, position_command_message="WD_Small_Position_Command",
                    position_command_signal="Small_Target", position_mode_message="",
                    position_mode_values={}, travel=0.5)
    drv = DbcDriver([m])
    drv.enable(0.0)
    with pytest.raises(EncodeError, match=r'"Small_Target" of message "WD_Small_Position_Command"'
                       r' \(0x3A5\) for node 5 .* between -32768 and 32767 counts'):
        drv.command([5.0], 0.0)


# ----------------------------------------------------------------------------- round trips


@SETTINGS
@given(st.floats(-math.pi, math.pi), st.floats(-2.0, 2.0), st.booleans())
def test_position_command_reaches_the_simulator_within_half_a_count(
    steer_dbc: str, angle: float, zero: float, invert: bool
) -> None:
    m = steer_motor(steer_dbc, zero_rad=zero, invert=invert)
    drv, sim = DbcDriver([m]), DbcSimulator(m)
    for frame in drv.enable(0.0) + drv.command([angle], 0.0):
        sim.handle(frame, 0.0)
    assert sim.model.armed and sim.position_mode
    target = sim.model.target_position_rad
    assert target is not None
    assert abs(target - m.steer_to_motor_rad(angle)) <= TWO_PI / 4096 / 2 + 1e-12


@SETTINGS
@given(st.floats(-math.pi, math.pi), st.floats(-3.0, 3.0), st.sampled_from([0, 16, 32]))
def test_feedback_is_absolute_within_one_count(
    steer_dbc: str, angle: float, zero: float, bits: int
) -> None:
    m = steer_motor(steer_dbc, zero_rad=zero, position_wrap_bits=bits)
    drv, sim = DbcDriver([m]), DbcSimulator(m)
    sim.model.position_rad = m.steer_to_motor_rad(angle)
    for frame in sim.tick(0.0):
        drv.on_frame(frame)
    fb = drv.feedback(0)
    assert fb is not None
    assert abs(fb.position_rad - angle) <= COUNT_STEER + 1e-12


@functools.cache
def odrive_pair(zero: float) -> tuple[MotorConfig, DbcDriver, DbcSimulator]:
    """One ODrive steering driver and simulator per neutral (the DBC takes ~30 ms to load)."""
    m = odrive_steer(3, zero_rad=zero)
    return m, DbcDriver([m]), DbcSimulator(m)


@SETTINGS
@given(st.floats(-math.pi, math.pi), st.sampled_from([-10.0, -0.3, 0.0, 2.0, 7.5]))
def test_float32_odrive_round_trip(angle: float, zero: float) -> None:
    m, drv, sim = odrive_pair(zero)
    for frame in drv.enable(0.0) + drv.command([angle], 0.0):
        sim.handle(frame, 0.0)
    target = sim.model.target_position_rad
    assert target is not None
    motor = m.steer_to_motor_rad(angle)
    assert abs(target - motor) <= abs(motor) * 2**-23 + 1e-9
    sim.model.position_rad = motor
    for frame in sim.codec.encode_feedback([DbcReading(3, 0.0, sim.position_raw())]):
        drv.on_frame(frame)
    fb = drv.feedback(0)
    assert fb is not None
    assert abs(fb.position_rad - angle) <= (abs(motor) * 2**-23 + 1e-9) / GEAR


@pytest.mark.parametrize(
    ("zero", "raw", "angle_counts"),
    [
        (-3.0, (counts(-3.0) + 100) % 65536, 100),  # neutral just below the 16-bit wrap
        (-3.0, (counts(-3.0) - 20000) % 65536, -20000),
        (3.0, counts(3.0) + 20000, 20000),
        (0.0, 65535, -1),
    ],
)
def test_first_sample_of_a_wrapping_counter_is_taken_nearest_neutral(
    steer_dbc: str, zero: float, raw: int, angle_counts: int
) -> None:
    m = steer_motor(steer_dbc, zero_rad=zero, position_wrap_bits=16)
    drv = DbcDriver([m])
    drv.on_frame(Frame(0x285, struct.pack("<hiBb", 0, raw, 0, 0)))
    fb = drv.feedback(0)
    assert fb is not None
    expected = m.motor_to_steer_rad(counts(zero) * TWO_PI / 4096) + angle_counts * COUNT_STEER
    assert fb.position_rad == pytest.approx(expected, abs=1e-12)


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
