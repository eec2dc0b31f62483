"""Tests of what binding refuses in a DBC file the driver cannot use: a signal with a scale of
zero (cantools divides by it), and a velocity command signal too narrow for the motor's
``max_rpm`` -- both through the driver and through ``wheelgate check`` (exit 2, no traceback).

The command check agrees with the codec's range check exactly: a motor that binds never has a
speed the driver takes refused by the codec, and one that does not bind has."""

from __future__ import annotations

import dataclasses
import struct
from typing import TYPE_CHECKING
from unittest import mock

import pytest
from hypothesis import event, example, given
from hypothesis import strategies as st

from drivers.dbc import DbcDriver, Role
from drivers.dbc.signals import signal_range
from gateway.cli import main
from gateway.core.errors import ConfigError, EncodeError
from gateway.core.types import Frame
from gateway.drive.setpoints import bounds
from tests.conftest import CONFIG_DIR
from tests.drivers.dbc_helpers import ANGLE, SETTINGS, motor, rpm
from tests.drivers.steering_dbc_helpers import POSITION_MESSAGE, steer_motor

if TYPE_CHECKING:
    from pathlib import Path

    from click.testing import CliRunner

    from gateway.core.types import MotorConfig

DBC_TEXT = (CONFIG_DIR / "example_controller.dbc").read_text()
#: The example's velocity command signal, as its DBC line has it.
TARGET = 'Target_Velocity : 0|32@1- (0.1,0) [-10000|10000] "rpm"'
KEY = "wheels['left'].motor"


def dbc_with(tmp_path: Path, old: str, new: str, name: str = "controller.dbc") -> str:
    """A copy of the example DBC with ``old`` replaced by ``new``; its path."""
    assert old in DBC_TEXT
    path = tmp_path / name
    path.write_text(DBC_TEXT.replace(old, new))
    return str(path)


def with_rpm(m: MotorConfig, max_rpm: float) -> MotorConfig:
    return dataclasses.replace(m, max_rpm=max_rpm)


# ----------------------------------------------------------------------------- zero scale


FEEDBACK, COMMAND = "'WD_Feedback'", "'WD_Velocity_Command'"


@pytest.mark.parametrize(
    ("old", "key", "signal", "message"),
    [
        ("Target_Velocity : 0|32@1- (0.1,0)", "command_signal", "'Target_Velocity'", COMMAND),
        ("Actual_Velocity : 0|16@1- (0.5,0)", "velocity_signal", "'Actual_Velocity'", FEEDBACK),
        ("Enable : 0|8@1+ (1,0)", "enable_signal", "'Enable'", "'WD_Enable'"),
        # The other signals of a message it binds (encoded whole), named once the first
        # signal of the message is bound: signals of other keys, and signals of none.
        ("Position_Count : 16|32@1- (1,0)", "feedback_message",
         "'Position_Count' (beside 'Actual_Velocity')", FEEDBACK),
        ("Fault_Code : 48|8@1+ (1,0)", "feedback_message",
         "'Fault_Code' (beside 'Actual_Velocity')", FEEDBACK),
        ("Accel_Limit : 40|16@1+ (1,0)", "command_message",
         "'Accel_Limit' (beside 'Target_Velocity')", COMMAND),
        ("Drive_Temp : 56|8@1- (1,0)", "feedback_message",
         "'Drive_Temp' (beside 'Actual_Velocity')", FEEDBACK),
    ],
)
def test_a_zero_scale_is_refused(
    tmp_path: Path, old: str, key: str, signal: str, message: str
) -> None:
    dbc = dbc_with(tmp_path, old, old[: old.index("(")] + "(0,0)")
    with pytest.raises(ConfigError) as info:
        DbcDriver([motor(3, dbc=dbc)])
    assert str(info.value) == (
        f"{KEY}.{key}: expected a non-zero scale for signal {signal} of message {message} in "
        f"{dbc}, got 0"
    )


def test_a_zero_scale_of_a_position_signal_in_its_own_message_is_refused(tmp_path: Path) -> None:
    old = "Rotor_Angle : 0|13@1+ (0.0439453125,0)"
    dbc = dbc_with(tmp_path, old, "Rotor_Angle : 0|13@1+ (0,0)")
    with pytest.raises(ConfigError) as info:
        DbcDriver([motor(3, extra=ANGLE, dbc=dbc)])
    assert str(info.value) == (
        f"{KEY}.position_signal: expected a non-zero scale for signal 'Rotor_Angle' of message "
        f"'WD_Angle' in {dbc}, got 0"
    )


def test_a_zero_scale_of_a_position_command_is_refused(tmp_path: Path) -> None:
    old = "Target_Position : 0|32@1- (1,0)"
    at = DBC_TEXT.index("\nCM_ ")
    path = tmp_path / "steer.dbc"
    path.write_text(DBC_TEXT[:at] + POSITION_MESSAGE.replace(old, old[:-5] + "(0.0,0)")
                    + DBC_TEXT[at:])
    with pytest.raises(ConfigError) as info:
        DbcDriver([steer_motor(str(path))])
    assert str(info.value) == (
        "wheels['front_left steering'].motor.position_command_signal: expected a non-zero "
        f"scale for signal 'Target_Position' of message 'WD_Position_Command' in {path}, got 0"
    )


# ----------------------------------------------------------------------------- command range


@pytest.mark.parametrize(
    ("new", "over", "max_rpm", "carries", "needs"),
    [
        # Its bits: 8 signed steps of 0.1 rpm.
        ('Target_Velocity : 0|8@1- (0.1,0) [0|0] "rpm"', {}, 4000, "-12.8 to 12.7 rpm",
         "max_rpm 4000 needs -4000 to 4000 rpm (command_unit rpm)"),
        # Its DBC range.
        ('Target_Velocity : 0|32@1- (0.1,0) [-1|1] "rpm"', {}, 4000, "-1 to 1 rpm",
         "max_rpm 4000 needs -4000 to 4000 rpm (command_unit rpm)"),
        # Unsigned: no reverse.
        ('Target_Velocity : 0|16@1+ (1,0) [0|0] "rpm"', {}, 3000, "0 to 65535 rpm",
         "max_rpm 3000 needs -3000 to 3000 rpm (command_unit rpm)"),
        # Through the unit conversion: wheel side, 10:1 (300 rpm at the wheel), in rad/s.
        ('Target_Velocity : 0|32@1- (0.1,0) [-30|30] "rad/s"',
         {"command_side": "wheel", "command_unit": "rad/s"}, 3000, "-30 to 30 rad/s",
         "max_rpm 3000 needs -31.4159 to 31.4159 rad/s (command_unit rad/s)"),
        # Only just: the slack for rounding (1e-6) is far below 1 step beyond the range.
        ('Target_Velocity : 0|32@1- (1,0) [-2999|2999] "rpm"', {}, 3000, "-2999 to 2999 rpm",
         "max_rpm 3000 needs -3000 to 3000 rpm (command_unit rpm)"),
    ],
)
def test_a_command_signal_too_narrow_for_max_rpm_is_refused(
    tmp_path: Path, new: str, over: dict[str, object], max_rpm: float, carries: str,
    needs: str,
) -> None:
    dbc = dbc_with(tmp_path, TARGET, new)
    with pytest.raises(ConfigError) as info:
        DbcDriver([with_rpm(motor(3, extra=over, dbc=dbc), max_rpm)])
    assert str(info.value) == (
        f"{KEY}.command_signal: signal 'Target_Velocity' of message 'WD_Velocity_Command' in "
        f"{dbc} carries {carries}, but {needs}; use a wider signal or DBC range, or a lower "
        "max_rpm"
    )


@pytest.mark.parametrize("invert", [False, True])
def test_a_range_of_exactly_max_rpm_binds_and_carries_full_speed(
    tmp_path: Path, invert: bool
) -> None:
    # 3000 rpm through the conversions is 3000.0000000000005: sent as the edge, 3000.
    dbc = dbc_with(tmp_path, TARGET, 'Target_Velocity : 0|32@1- (1,0) [-3000|3000] "rpm"')
    drv = DbcDriver([motor(3, gear=7.0, invert=invert, dbc=dbc)])
    drv.enable(0.0)
    (top,) = drv.bounds
    sign = -1 if invert else 1
    for speed in (top, -top):
        (frame,) = drv.command([speed], 0.0)
        raw = 3000 * sign if speed > 0 else -3000 * sign
        assert frame == Frame(0x203, struct.pack("<iBHx", raw, 2, 1000))
    with pytest.raises(EncodeError, match=r"between -3000 and 3000 rpm, but got 3000\.01\."):
        drv.codec.encode_command([3000.01])  # beyond rounding: still refused


def test_the_example_config_binds_and_the_check_reports_ok(runner: CliRunner) -> None:
    result = runner.invoke(main, ["check", "-c", str(CONFIG_DIR / "example_dbc.yaml")])
    assert result.exit_code == 0, result.output
    assert result.output.rstrip().endswith("ok")


@SETTINGS
@given(
    bits=st.sampled_from([8, 12, 16, 32]),
    signed=st.booleans(),
    scale=st.sampled_from([0.1, 0.5, 1, 2, -0.25]),
    dbc_range=st.none() | st.tuples(st.integers(-20000, 0), st.integers(1, 20000)),
    max_rpm=st.floats(1.0, 20000.0),
    gear=st.floats(0.5, 50.0),
    unit=st.sampled_from(["rpm", "rad/s", "rev/s", "deg/s"]),
    side=st.sampled_from(["motor", "wheel"]),
    command_scale=st.sampled_from([1.0, 10.0, -1.0]),
    invert=st.booleans(),
)
@example(bits=16, signed=True, scale=1, dbc_range=(-3000, 3000), max_rpm=3000.0, gear=1.0,
         unit="rpm", side="motor", command_scale=1.0, invert=False)
def test_binding_agrees_with_the_codecs_range_check(
    tmp_path: Path, bits: int, signed: bool, scale: float, dbc_range: tuple[int, int] | None,
    max_rpm: float, gear: float, unit: str, side: str, command_scale: float, invert: bool,
) -> None:
    lo, hi = dbc_range or (0, 0)
    sign = "-" if signed else "+"
    dbc = dbc_with(tmp_path, TARGET,
                   f'Target_Velocity : 0|{bits}@1{sign} ({scale},0) [{lo}|{hi}] "rpm"')
    m = with_rpm(motor(3, gear=gear, invert=invert, dbc=dbc, command_unit=unit,
                       command_side=side, command_scale=command_scale), max_rpm)
    (top,) = bounds((m,))
    speeds = (-top, top, 0.37 * top, -0.81 * top)
    try:
        drv = DbcDriver([m])
    except ConfigError as err:
        event("refused")
        assert str(err).startswith(f"{KEY}.command_signal: signal 'Target_Velocity'")
        with mock.patch("drivers.dbc.binding.check_command"):  # the same motor, unchecked
            unchecked = DbcDriver([m])
        unchecked.enable(0.0)
        with pytest.raises(EncodeError, match=r'Expected signal "Target_Velocity"'):
            for speed in speeds[:2]:  # one of the ends is refused
                unchecked.command([speed], 0.0)
        return
    event("binds")
    drv.enable(0.0)
    ref = drv.bindings[0].command
    assert ref is not None
    low, high = signal_range(ref.signal)
    for speed in speeds:  # every speed it takes goes out, within the signal's range
        (frame,) = drv.command([speed], 0.0)
        (request,) = [r for r in drv.codec.decode_request(frame) or () if r.role == Role.COMMAND]
        assert low <= request.value <= high


# ----------------------------------------------------------------------------- wheelgate check


@pytest.mark.parametrize(
    ("old", "new", "message"),
    [
        (TARGET, TARGET.replace("(0.1,0)", "(0,0)"),
         "expected a non-zero scale for signal 'Target_Velocity' of message "
         "'WD_Velocity_Command' in {dbc}, got 0"),
        (TARGET, TARGET.replace("0|32@1-", "0|8@1-"),
         "signal 'Target_Velocity' of message 'WD_Velocity_Command' in {dbc} carries -12.8 to "
         "12.7 rpm, but max_rpm 4000 needs -4000 to 4000 rpm"),
        (TARGET, TARGET.replace("[-10000|10000]", "[-1|1]"),
         "signal 'Target_Velocity' of message 'WD_Velocity_Command' in {dbc} carries -1 to 1 "
         "rpm, but max_rpm 4000 needs -4000 to 4000 rpm"),
    ],
)
@pytest.mark.parametrize("command", [["check"], ["frames", "--vx", "0.5"]])
def test_check_and_frames_report_it_with_exit_2(
    tmp_path: Path, runner: CliRunner, old: str, new: str, message: str, command: list[str]
) -> None:
    dbc = dbc_with(tmp_path, old, new, "example_controller.dbc")
    config = tmp_path / "example_dbc.yaml"
    config.write_text((CONFIG_DIR / "example_dbc.yaml").read_text())
    result = runner.invoke(main, [command[0], "-c", str(config), *command[1:]])
    assert result.exit_code == 2, result.output
    assert f"{KEY}.command_signal: " + message.format(dbc=dbc) in result.output
    assert "Traceback" not in result.output
    assert not isinstance(result.exception, ZeroDivisionError)


def test_a_speed_within_max_rpm_is_sent_after_the_checks(tmp_path: Path) -> None:
    # (The dual-channel pattern: a narrow DBC range that still carries max_rpm binds.)
    dbc = dbc_with(tmp_path, TARGET, 'Target_Velocity : 0|16@1- (1,0) [-3000|3000] "rpm"')
    drv = DbcDriver([motor(3, gear=1.0, dbc=dbc)])
    drv.enable(0.0)
    assert drv.command([rpm(100.0)], 0.0) == [Frame(0x203, struct.pack("<hxxBHx", 100, 2, 1000))]


def test_a_value_within_the_rounding_slack_goes_out_as_the_edge(tmp_path: Path) -> None:
    # 24 bits of 0.001 rpm: the slack (1e-6 of 8388.607) is more than half a step, so only
    # the clamp keeps the raw value in its bits.
    dbc = dbc_with(tmp_path, TARGET, 'Target_Velocity : 0|24@1- (0.001,0) [0|0] "rpm"')
    codec = DbcDriver([motor(3, dbc=dbc)]).codec
    tail = b"\x00\x02" + (1000).to_bytes(2, "little") + b"\x00"
    for value, raw in ((8388.607 * (1 + 5e-7), 8388607), (-8388.608 * (1 + 5e-7), -8388608)):
        (frame,) = codec.encode_command([value])
        assert frame == Frame(0x203, raw.to_bytes(3, "little", signed=True) + tail)
    with pytest.raises(EncodeError, match=r"between -8388.61 and 8388.61 rpm"):
        codec.encode_command([8388.607 * (1 + 2e-6)])
