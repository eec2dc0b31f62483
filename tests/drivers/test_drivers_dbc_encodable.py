"""Tests that binding refuses, at configuration load, a DBC file whose frames the driver could
never send, and that what it accepts reaches the bus as configured:

* a bound signal that is a multiplexer switch (cantools refuses the frames of the other switch
  value, e.g. the disarming one);
* a message the driver sends that cantools cannot encode (an unbound signal whose initial value,
  ``GenSigStartValue``, is outside its DBC range): every message is encoded once when the driver
  is built;
* an enable, disable or mode value between two steps of its signal (it would go out as another
  value), or an enable and a disable value that go out as the same raw value;
* a scale too large for a float (the range of the signal cannot be computed).

Each refusal is a :class:`~gateway.core.errors.ConfigError` naming the key, the DBC file, the
message, the signal, what was expected and what came; ``wheelgate check`` reports it with exit
code 2 and no traceback."""

from __future__ import annotations

from typing import TYPE_CHECKING

import pytest

from drivers.dbc import DbcDriver
from gateway.cli import main
from gateway.core.errors import ConfigError
from tests import factories
from tests.conftest import CONFIG_DIR
from tests.drivers import steering_dbc_helpers
from tests.drivers.dbc_helpers import ANGLE, EXAMPLE, EXAMPLE_DBC, motor
from tests.drivers.steering_dbc_helpers import steer_motor

if TYPE_CHECKING:
    from pathlib import Path

    from click.testing import CliRunner

    from gateway.core.types import Frame

DBC_TEXT = (CONFIG_DIR / "example_controller.dbc").read_text()
KEY = "wheels['left'].motor"
steer_dbc = steering_dbc_helpers.steer_dbc
ENABLE = 'BO_ 384 WD_Enable: 1 Master\n SG_ Enable : 0|8@1+ (1,0) [0|1] "" WD100'
ENABLE_VAL = 'VAL_ 384 Enable 0 "DISABLE" 1 "ENABLE" ;\n'
TARGET = 'Target_Velocity : 0|32@1- (0.1,0) [-10000|10000] "rpm"'
ACCEL = 'Accel_Limit : 40|16@1+ (1,0) [0|60000] "rpm/s"'
ACCEL_START = 'BA_ "GenSigStartValue" SG_ 512 Accel_Limit 1000;'
#: The example's enable signal as a multiplexer switch, with a signal only under value 1.
MUX_ENABLE = (
    'BO_ 384 WD_Enable: 2 Master\n SG_ Enable M : 0|8@1+ (1,0) [0|1] "" WD100\n'
    ' SG_ Enable_Profile m1 : 8|8@1+ (1,0) [0|255] "" WD100'
)


def dbc_with(tmp_path: Path, *edits: tuple[str, str], name: str = "controller.dbc") -> str:
    """A copy of the example DBC with each ``(old, new)`` of ``edits`` replaced; its path."""
    text = DBC_TEXT
    for old, new in edits:
        assert old in text
        text = text.replace(old, new)
    path = tmp_path / name
    path.write_text(text)
    return str(path)


def refusal(dbc: str, **over: object) -> str:
    with pytest.raises(ConfigError) as info:
        DbcDriver([motor(3, extra=over, dbc=dbc)])
    return str(info.value)


def sent(frames: list[Frame]) -> list[str]:
    return [f.to_cansend() for f in frames]


# ----------------------------------------------------------------------------- multiplexer


def test_an_enable_signal_that_is_a_multiplexer_switch_is_refused(tmp_path: Path) -> None:
    dbc = dbc_with(tmp_path, (ENABLE, MUX_ENABLE), (ENABLE_VAL, ""))
    assert refusal(dbc) == (
        f"{KEY}.enable_signal: expected a signal that is not multiplexed, got signal 'Enable' "
        f"of message 'WD_Enable' in {dbc}, a multiplexer switch (of 'Enable_Profile'); this "
        "driver does not support multiplexed messages"
    )


def test_a_signal_under_a_multiplexer_is_still_refused(tmp_path: Path) -> None:
    dbc = dbc_with(tmp_path, (ENABLE, MUX_ENABLE), (ENABLE_VAL, ""))
    assert refusal(dbc, enable_signal="Enable_Profile") == (
        f"{KEY}.enable_signal: expected a signal that is not multiplexed, got signal "
        f"'Enable_Profile' of message 'WD_Enable' in {dbc}, multiplexed by 'Enable' (values "
        "1); this driver does not support multiplexed messages"
    )


# ----------------------------------------------------------------------------- trial encode


def test_an_initial_value_outside_its_range_is_refused(tmp_path: Path) -> None:
    dbc = dbc_with(tmp_path, (ACCEL_START, ACCEL_START.replace("1000", "65000")))
    assert refusal(dbc) == (
        f"{KEY}.command_message: cannot send message 'WD_Velocity_Command' of {dbc}: signal "
        "'Accel_Limit', which no key configures, goes out with its initial value "
        "(GenSigStartValue); expected a value between 0 and 60000, got 65000"
    )


def test_a_bound_signal_may_have_an_initial_value_outside_its_range(tmp_path: Path) -> None:
    # The value the driver sets replaces it in every frame: enable and disable go out.
    start = 'BA_ "GenSigStartValue" SG_ 384 Enable 7;\n'
    dbc = dbc_with(tmp_path, (ACCEL_START, ACCEL_START + "\n" + start))
    drv = DbcDriver([motor(3, dbc=dbc)])
    assert sent(drv.enable(0.0)) == ["203#0000000002E80300", "183#01"]
    assert sent(drv.disable(0.1)) == ["203#0000000002E80300", "183#00"]


def test_a_shared_message_is_tried_with_every_motors_values(tmp_path: Path) -> None:
    # A dual-channel command message: each motor's signal has an initial value outside its
    # range, but every frame carries both motors' values.
    dbc = dbc_with(
        tmp_path,
        (f" SG_ {TARGET} WD100", f" SG_ {TARGET} WD100\n SG_ Right_Velocity : 32|16@1- (1,0) "
         '[-5000|5000] "rpm" WD100'),
        (" SG_ Control_Mode : 32|8@1+", " SG_ Control_Mode : 48|8@1+"),
        (" SG_ Accel_Limit : 40|16@1+", " SG_ Accel_Limit : 56|8@1+"),
        ("[0|60000]", "[0|255]"),
        (ACCEL_START, 'BA_ "GenSigStartValue" SG_ 512 Accel_Limit 10;\n'
         'BA_ "GenSigStartValue" SG_ 512 Right_Velocity 9000;'),
    )
    common: dict[str, object] = {
        "node_id_in_frame": "none", "fault_signal": "", "enable_message": "", "enable_signal": ""
    }
    left = motor(3, extra=common, dbc=dbc)
    right = motor(4, "right", dbc=dbc, extra={
        **common, **ANGLE, "command_signal": "Right_Velocity", "feedback_message": "WD_Angle",
        "velocity_signal": "Bus_Voltage"})
    with pytest.raises(ConfigError, match=r"signal 'Right_Velocity', which no key configures"):
        DbcDriver([left])  # alone, the right channel goes out with its initial value
    drv = DbcDriver([left, right])
    assert sent(drv.enable(0.0)) == ["200#000000000000020A"]


#: An unconfigured multiplexer switch in the command message, with a signal only under 1.
PROFILE = (
    f' SG_ {ACCEL} WD100\n SG_ Profile M : 56|4@1+ (1,0) [0|15] "" WD100\n'
    ' SG_ Profile_Gain m1 : 60|4@1+ (1,0) [0|15] "" WD100'
)


def test_a_message_cantools_cannot_encode_is_refused_with_its_error(tmp_path: Path) -> None:
    dbc = dbc_with(tmp_path, (f" SG_ {ACCEL} WD100", PROFILE))
    assert refusal(dbc) == (
        f"{KEY}.command_message: cannot send message 'WD_Velocity_Command' of {dbc} (commands "
        'at rest, armed): Cannot encode message "WD_Velocity_Command" (0x203): Expected '
        'multiplexer id in {1}, for multiplexer "Profile" but got 0'
    )


def test_an_unconfigured_switch_that_selects_its_signals_binds(tmp_path: Path) -> None:
    start = '\nBA_ "GenSigStartValue" SG_ 512 Profile 1;'
    dbc = dbc_with(tmp_path, (f" SG_ {ACCEL} WD100", PROFILE), (ACCEL_START, ACCEL_START + start))
    drv = DbcDriver([motor(3, dbc=dbc)])
    assert sent(drv.enable(0.0)) == ["203#0000000002E80301", "183#01"]


# ----------------------------------------------------------------------------- steps


@pytest.mark.parametrize(
    ("value", "goes"), [(0.5, "0 (raw 0)"), (0.4, "0 (raw 0)"), (0.75, "1 (raw 1)")]
)
def test_an_enable_value_between_steps_is_refused(
    tmp_path: Path, value: float, goes: str
) -> None:
    assert refusal(EXAMPLE_DBC, enable_value=value) == (
        f"{KEY}.enable_value: expected a value on a step of signal 'Enable' of message "
        f"'WD_Enable' in {EXAMPLE_DBC} (scale 1, offset 0), got {value!r}, which goes out "
        f"as {goes}"
    )


def test_an_enable_value_that_goes_out_as_the_disable_value_is_refused() -> None:
    assert refusal(EXAMPLE_DBC, enable_value=1e-300) == (
        f"{KEY}.disable_value: expected a value that goes out other than enable_value 1e-300 "
        f"(raw 0) in signal 'Enable' of message 'WD_Enable' in {EXAMPLE_DBC}, got 0.0, "
        "which goes out as raw 0 too"
    )


def test_float32_values_that_round_together_are_refused(tmp_path: Path) -> None:
    dbc = dbc_with(
        tmp_path,
        (ENABLE, 'BO_ 384 WD_Enable: 4 Master\n SG_ Enable : 0|32@1- (1,0) [0|2] "" WD100'),
        (ENABLE_VAL, "SIG_VALTYPE_ 384 Enable : 1;\n"),
    )
    assert refusal(dbc, enable_value=1.00000001, disable_value=1.0) == (
        f"{KEY}.disable_value: expected a value that goes out other than enable_value "
        f"1.00000001 (raw 1) in signal 'Enable' of message 'WD_Enable' in {dbc}, got 1.0, "
        "which goes out as raw 1 too"
    )


def test_values_on_a_step_go_out_as_configured(tmp_path: Path) -> None:
    # 0.3 is not 3 * 0.1 in floating point, but it is on a step.
    dbc = dbc_with(tmp_path, (ENABLE, ENABLE.replace("(1,0) [0|1]", "(0.1,0) [0|25.5]")))
    drv = DbcDriver([motor(3, dbc=dbc, enable_value=0.3, disable_value=0.0)])
    assert sent(drv.enable(0.0))[-1] == "183#03"
    assert sent(drv.disable(0.1))[-1] == "183#00"


def test_a_mode_value_between_steps_is_refused(steer_dbc: str) -> None:
    with pytest.raises(ConfigError) as info:
        DbcDriver([steer_motor(steer_dbc, position_mode_values={"Position_Mode": 2.5})])
    assert str(info.value).endswith(
        ".motor.position_mode_values.Position_Mode: expected a value on "
        "a step of signal 'Position_Mode' of message 'WD_Position_Command' in "
        f"{steer_dbc} (scale 1, offset 0), got 2.5, which goes out as 2 (raw 2)"
    )


# ----------------------------------------------------------------------------- scale


@pytest.mark.parametrize(
    ("old", "new", "key", "signal", "what"),
    [
        (TARGET, TARGET.replace("(0.1,0)", "(1e308,0)"), "command_signal", "'Target_Velocity'",
         "scale 1e+308 and offset 0 over 32 bits (raw -2147483648 to 2147483647)"),
        (TARGET, TARGET.replace("(0.1,0)", "(1e300,0.5)"), "command_signal",
         "'Target_Velocity'",
         "scale 1e+300 and offset 0.5 over 32 bits (raw -2147483648 to 2147483647)"),
        (ACCEL, ACCEL.replace("(1,0)", "(1e308,0)"), "command_message",
         "'Accel_Limit' (beside 'Target_Velocity')",
         "scale 1e+308 and offset 0 over 16 bits (raw 0 to 65535)"),
    ],
)
def test_a_scale_too_large_for_a_float_is_refused(
    tmp_path: Path, old: str, new: str, key: str, signal: str, what: str
) -> None:
    dbc = dbc_with(tmp_path, (old, new))
    assert refusal(dbc) == (
        f"{KEY}.{key}: expected a signal whose values a float holds, got signal {signal} of "
        f"message 'WD_Velocity_Command' in {dbc}: {what}"
    )


# ----------------------------------------------------------------------------- wheelgate check


@pytest.mark.parametrize(
    ("edits", "message"),
    [
        (((ENABLE, MUX_ENABLE), (ENABLE_VAL, "")),
         "enable_signal: expected a signal that is not multiplexed, got signal 'Enable'"),
        (((ACCEL_START, ACCEL_START.replace("1000", "65000")),),
         "command_message: cannot send message 'WD_Velocity_Command' of {dbc}: signal "
         "'Accel_Limit'"),
        (((TARGET, TARGET.replace("(0.1,0)", "(1e308,0)")),),
         "command_signal: expected a signal whose values a float holds, got signal "
         "'Target_Velocity' of message 'WD_Velocity_Command' in {dbc}: scale 1e+308"),
    ],
)
def test_check_reports_it_with_exit_2(
    tmp_path: Path, runner: CliRunner, edits: tuple[tuple[str, str], ...], message: str
) -> None:
    dbc = dbc_with(tmp_path, *edits, name="example_controller.dbc")
    config = tmp_path / "example_dbc.yaml"
    config.write_text((CONFIG_DIR / "example_dbc.yaml").read_text())
    result = runner.invoke(main, ["check", "-c", str(config)])
    assert result.exit_code == 2, result.output
    assert f"{KEY}.{message.format(dbc=dbc)}" in result.output
    assert "Traceback" not in result.output


def test_the_enable_value_of_the_cli_example_is_checked(
    tmp_path: Path, runner: CliRunner
) -> None:
    config = tmp_path / "example_dbc.yaml"
    text = (CONFIG_DIR / "example_dbc.yaml").read_text()
    config.write_text(text.replace("  enable_signal: Enable\n",
                                   "  enable_signal: Enable\n  enable_value: 0.5\n"))
    dbc_with(tmp_path, name="example_controller.dbc")
    result = runner.invoke(main, ["check", "-c", str(config)])
    assert result.exit_code == 2, result.output
    assert f"{KEY}.enable_value: expected a value on a step of signal 'Enable'" in result.output


def test_a_factory_motor_without_enable_binds(tmp_path: Path) -> None:
    opts = {**EXAMPLE, "enable_message": "", "enable_signal": ""}
    drv = DbcDriver([factories.motor("dbc", 3, options=opts)])
    assert sent(drv.enable(0.0)) == ["203#0000000002E80300"]
