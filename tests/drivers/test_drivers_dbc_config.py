"""Tests of the generic DBC driver's configuration and binding: option errors, colliding motors,
messages shared by several motors, claims, a config file, and each motor's liveness."""

from __future__ import annotations

import struct
import subprocess
import sys
from typing import TYPE_CHECKING

import pytest

from drivers.dbc import (
    DbcCodec,
    DbcDriver,
    DbcReading,
    parse_options,
)
from drivers.dbc.sim import DbcSimulator
from gateway.core.errors import ConfigError
from gateway.core.types import Frame, MotorConfig
from gateway.drive.claims import FrameClaim
from tests import factories
from tests.conftest import CONFIG_DIR, DATA_DIR, REPO
from tests.drivers.dbc_helpers import (
    ANGLE,
    EXAMPLE,
    EXAMPLE_DBC,
    TWO_PI,
    motor,
    rpm,
)

if TYPE_CHECKING:
    from pathlib import Path


# ----------------------------------------------------------------------------- configuration

KNOWN_MESSAGES = "WD_Angle, WD_Enable, WD_Feedback, WD_Velocity_Command"


@pytest.mark.parametrize(
    ("over", "message"),
    [
        ({"dbc": "/nonexistent/x.dbc"}, "motor.dbc: cannot read DBC file '/nonexistent/x.dbc'"),
        (
            {"command_message": "WD_Speed"},
            f"motor.command_message: no message 'WD_Speed' in {EXAMPLE_DBC}; "
            f"known messages: {KNOWN_MESSAGES}",
        ),
        (
            {"feedback_message": "Nope"},
            f"known messages: {KNOWN_MESSAGES}",
        ),
        (
            {"command_signal": "Speed"},
            "motor.command_signal: message 'WD_Velocity_Command' has no signal 'Speed'; "
            "known signals: Accel_Limit, Control_Mode, Target_Velocity",
        ),
        ({"velocity_signal": "Rpm"}, "motor.velocity_signal: message 'WD_Feedback' has no"),
        ({"position_signal": "Rotor_Angle"}, "motor.position_signal: message 'WD_Feedback'"),
        ({"enable_signal": "On"}, "motor.enable_signal: message 'WD_Enable' has no signal"),
        ({"fault_signal": "Err"}, "motor.fault_signal: message 'WD_Feedback' has no signal"),
        ({"enable_value": 5}, "motor.enable_value: expected a value between 0 and 1"),
        (
            {**ANGLE, "position_wrap_bits": 16},
            "motor.position_wrap_bits: expected 0 or 1..13 for signal 'Rotor_Angle', got 16",
        ),
        ({"command_unit": "kph"}, "motor.command_unit: expected one of 'rad/s', 'rpm'"),
        ({"position_unit": "turns"}, "motor.position_unit: expected one of"),
        ({"counts_per_rev": 0}, "motor.counts_per_rev: expected at least 1, got 0"),
        ({"command_scale": 0}, "motor.command_scale: expected a non-zero factor"),
        ({"node_id_in_frame": "or"}, "motor.node_id_in_frame: expected one of 'add', 'none'"),
        ({"enable_signal": ""}, "motor.enable_signal: required when enable_message is given"),
        (
            {"enable_message": "", "enable_signal": "Enable"},
            "motor.enable_message: required when enable_signal is given",
        ),
        ({"disable_value": 1}, "motor.disable_value: expected a value other than enable_value"),
        ({"fault_signal": "", "fault_message": "WD_Feedback"}, "motor.fault_signal: required"),
        (
            {"node_id_in_frame": "none", "node_id_shift": 5},
            "motor.node_id_shift: only used with node_id_in_frame 'add'",
        ),
        ({"colour": "red"}, "motor.colour: unknown key"),
        ({"command_signal": ""}, "motor.command_signal: expected a non-empty name"),
        ({"dbc": 3}, "motor.dbc: expected str, got 3"),
    ],
)
def test_config_errors_name_the_key(over: dict[str, object], message: str) -> None:
    with pytest.raises(ConfigError) as info:
        DbcDriver([motor(3, extra=over, validate=False)])
    assert message in str(info.value)
    assert str(info.value).startswith("wheels['left'].motor.")


def test_missing_required_key() -> None:
    opts = {k: v for k, v in EXAMPLE.items() if k != "position_signal"}
    with pytest.raises(ConfigError, match=r"motor\.position_signal: required key is missing"):
        DbcDriver([factories.motor("dbc", 3, validate=False, options=opts)])


def test_invalid_dbc_file(tmp_path: Path) -> None:
    bad = tmp_path / "bad.dbc"
    bad.write_text("this is not a DBC file\n")
    with pytest.raises(ConfigError, match=r"motor\.dbc: '.*bad\.dbc' is not a valid DBC file"):
        DbcDriver([motor(3, dbc=str(bad))])


def test_relative_dbc_path_uses_config_dir(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    DbcDriver([motor(3, dbc="example_controller.dbc", config_dir=str(CONFIG_DIR))])
    with pytest.raises(ConfigError, match=r"cannot read DBC file 'example_controller\.dbc'"):
        DbcDriver([motor(3, dbc="example_controller.dbc")])
    (tmp_path / "example_controller.dbc").write_bytes(
        (CONFIG_DIR / "example_controller.dbc").read_bytes()
    )
    DbcDriver([motor(3, dbc="example_controller.dbc")])  # cwd-relative


@pytest.mark.parametrize(
    ("motors", "message"),
    [
        ([motor(3), motor(3, "right")], "node 3 is already used by wheel 'left'"),
        (
            [motor(0x7FF)],
            "expected a frame ID of at most 0x7FF for message 'WD_Velocity_Command' (0x200) "
            "with node 2047, got 0x9FF",
        ),
        ([motor(0x800)], ".node_id: expected int 0..2047, got 2048"),
        # 0x180 + 0x83 = 0x203, the command ID of node 3.
        ([motor(3), motor(0x83, "right")], "frame ID 0x203 of node 131 ('right') message"),
        (
            [motor(3, node_id_in_frame="none"), motor(4, "right", node_id_in_frame="none")],
            'signal "Target_Velocity" of message "WD_Velocity_Command" (0x200) is configured '
            "for node 3 ('left') and node 4 ('right')",
        ),
        (
            [
                motor(
                    3,
                    feedback_message="WD_Velocity_Command",
                    velocity_signal="Accel_Limit",
                    position_message="WD_Feedback",
                    fault_signal="",
                )
            ],
            "frame ID 0x203 is configured both as a command",
        ),
    ],
)
def test_motors_that_collide_are_refused(motors: list[MotorConfig], message: str) -> None:
    with pytest.raises(ConfigError) as info:
        DbcDriver(motors)
    assert message in str(info.value)


def test_validate_options_fills_defaults_and_checks_rules_between_keys() -> None:
    out = DbcDriver.validate_options(EXAMPLE, "robot.yaml: wheels[0].motor")
    assert out["node_id_in_frame"] == "add" and out["liveness_s"] == 0.25
    assert out["position_message"] == ""  # resolved to feedback_message when parsed
    assert parse_options(out, "w").position_message == "WD_Feedback"
    with pytest.raises(ConfigError, match=r"robot\.yaml: wheels\[0\]\.motor\.fault_signal"):
        DbcDriver.validate_options(
            {**EXAMPLE, "fault_signal": "", "fault_message": "X"}, "robot.yaml: wheels[0].motor"
        )


# ----------------------------------------------------------------------------- shared messages

DUAL_DBC = str(DATA_DIR / "dual_controller.dbc")


def dual_motors() -> list[MotorConfig]:
    motors = []
    for node, side in ((1, "Left"), (2, "Right")):
        opts: dict[str, object] = {
            "dbc": DUAL_DBC,
            "node_id_in_frame": "none",
            "command_message": "Dual_Command",
            "command_signal": f"{side}_Speed",
            "feedback_message": "Dual_Status",
            "velocity_signal": f"{side}_Rpm",
            "position_signal": f"{side}_Ticks",
            "position_unit": "counts",
            "counts_per_rev": 100,
            "position_wrap_bits": 16,
            "enable_message": "Dual_Command",
            "enable_signal": "Drive_Enable",
        }
        motors.append(factories.motor("dbc", node, side.lower(), options=opts))
    return motors


def test_two_motors_share_one_command_and_one_extended_status_message() -> None:
    drv = DbcDriver(dual_motors())
    # Mode has no initial value and a range of 5..9, so it is sent as 5 (0 clamped).
    assert drv.enable(0.0) == [Frame(0x110, struct.pack("<hhBBxx", 0, 0, 1, 5))]
    frames = drv.command([rpm(100.0), rpm(-250.0)], 0.0)
    assert frames == [Frame(0x110, struct.pack("<hhBBxx", 100, -250, 1, 5))]
    assert drv.disable(0.0) == [Frame(0x110, struct.pack("<hhBBxx", 0, 0, 0, 5))]
    status = Frame(0x18FF0120, struct.pack("<hhHH", 10, -20, 65535, 3), is_extended_id=True)
    assert drv.codec.decode(status) == (DbcReading(1, 10.0, 65535), DbcReading(2, -20.0, 3))
    drv.on_frame(status.stamped(1.0))
    drv.on_frame(
        Frame(
            0x18FF0120,
            struct.pack("<hhHH", 10, -20, 4, 65533),
            is_extended_id=True,
            timestamp_s=1.01,
        )
    )
    left, right = drv.feedback(0), drv.feedback(1)
    assert left is not None and right is not None
    assert left.position_rad == pytest.approx(5 * TWO_PI / 100)  # 65535 -> 4 wraps: +5
    assert right.position_rad == pytest.approx(-6 * TWO_PI / 100)  # 3 -> 65533: -6
    # The same number as an 11-bit ID is another device's frame, not a malformed one.
    assert not drv.on_frame(status._replace(is_extended_id=False))


def test_codec_is_reusable_on_its_own() -> None:
    drv = DbcDriver([motor(3)])
    codec = DbcCodec(drv.bindings)
    assert codec.encode_command([150.0]) == [Frame(0x203, struct.pack("<iBHx", 1500, 2, 1000))]
    assert codec.encode_enable(True) == [Frame(0x183, b"\x01")]
    assert codec.decode(Frame(0x7FF, b"")) is None


def test_feedback_frames_carry_only_the_given_motors() -> None:
    codec = DbcDriver([motor(3), motor(4, "right")]).codec
    (frame,) = codec.encode_feedback([DbcReading(4, 1.5, 7, 0)])
    assert frame == Frame(0x284, struct.pack("<hiBb", 3, 7, 0, 0))


# ----------------------------------------------------------------------------- claims


def test_claims_are_the_bound_messages_with_their_dbc_names() -> None:
    drv = DbcDriver([motor(1, extra=ANGLE), motor(2, "right")])
    assert drv.claims() == (
        FrameClaim.exact(0x281, False, 0),  # WD_Feedback, feedback first, by ID
        FrameClaim.exact(0x282, False, 1),
        FrameClaim.exact(0x301, False, 0),  # WD_Angle
        FrameClaim.exact(0x201, False, 0, receive=False),  # WD_Velocity_Command
        FrameClaim.exact(0x181, False, 0, receive=False),  # WD_Enable
        FrameClaim.exact(0x202, False, 1, receive=False),
        FrameClaim.exact(0x182, False, 1, receive=False),
    )
    assert [str(f) for f in drv.receive_filters()] == ["281/7FF", "282/7FF", "301/7FF"]
    names = {c.can_id: drv.message_name(c.can_id, c.extended) for c in drv.claims()}
    assert names == {0x281: "WD_Feedback", 0x282: "WD_Feedback", 0x301: "WD_Angle",
                     0x201: "WD_Velocity_Command", 0x202: "WD_Velocity_Command",
                     0x181: "WD_Enable", 0x182: "WD_Enable"}
    assert drv.message_name(0x281, True) is None  # the other ID type
    assert drv.message_name(0x283, False) is None  # another node's


def test_a_shared_message_is_claimed_for_no_single_motor() -> None:
    drv = DbcDriver(dual_motors())
    assert drv.claims() == (
        FrameClaim.exact(0x18FF0120, True, None),
        FrameClaim.exact(0x110, False, None, receive=False),
    )
    assert drv.message_name(0x18FF0120, True) == "Dual_Status"
    assert drv.message_name(0x110, False) == "Dual_Command"


def test_every_frame_the_driver_sends_or_takes_is_claimed() -> None:
    m = motor(3, extra=ANGLE)
    drv, sim = DbcDriver([m]), DbcSimulator(m)
    sent = drv.enable(0.0) + drv.command([1.0], 0.0) + drv.disable(0.0)
    received = sim.tick(0.0)
    claims = drv.claims()
    for frame, receive in [*((f, False) for f in sent), *((f, True) for f in received)]:
        assert [c.receive for c in claims
                if c.matches(frame.arbitration_id, frame.is_extended_id)] == [receive], frame
        assert drv.on_frame(frame) is receive


def test_the_driver_never_imports_its_simulator() -> None:
    code = ("import sys, drivers.dbc; "
            "print(sorted(m for m in sys.modules if m.startswith(('drivers.dbc.sim', "
            "'gateway.sim'))))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, cwd=REPO)
    assert out.stdout.strip() == "[]"


def test_a_config_file_with_dbc_motors_loads_and_builds_the_driver(tmp_path: Path) -> None:
    from gateway.config import load_config

    protocol = "\n".join(f"  {k}: {v}" for k, v in EXAMPLE.items())
    (tmp_path / "robot.yaml").write_text(
        "drive: generic\nmotor_defaults:\n  driver: dbc\n  gear_ratio: 10.0\n  max_rpm: 3000\n"
        f"{protocol}\n"
        "wheels:\n"
        "  - {name: left, type: fixed, alpha: 1.5707963267948966, l: 0.2, beta: 0.0,\n"
        "     radius: 0.05, motor: {node_id: 1}}\n"
        "  - {name: right, type: fixed, alpha: -1.5707963267948966, l: 0.2,\n"
        "     beta: 3.141592653589793, radius: 0.05,\n"
        "     motor: {node_id: 2, controller_timeout_s: 0.3}}\n"
        "  - {name: castor, type: castor, alpha: 3.141592653589793, l: 0.25,\n"
        "     beta: -1.5707963267948966, radius: 0.025, d: 0.03}\n"
    )
    cfg = load_config(tmp_path / "robot.yaml")
    motors = [m for m in cfg.motors if m is not None]
    assert motors[1].options["controller_timeout_s"] == 0.3
    assert motors[0].options["command_scale"] == 1.0
    drv = DbcDriver(motors)
    assert [drv.opts[i].controller_timeout_s for i in (0, 1)] == [0.0, 0.3]
    drv.enable(0.0)
    assert [f.arbitration_id for f in drv.command([rpm(15.0), rpm(15.0)], 0.0)] == [0x201, 0x202]
    bad = (tmp_path / "robot.yaml").read_text().replace("velocity_unit: rpm", "velocity_unit: x")
    (tmp_path / "bad.yaml").write_text(bad)
    with pytest.raises(ConfigError,  # (named once where it is written: in the defaults)
                       match=r"bad\.yaml: motor_defaults\.velocity_unit: expected one of"):
        load_config(tmp_path / "bad.yaml")


def test_each_motor_keeps_its_own_liveness() -> None:
    drv = DbcDriver([motor(1), motor(2, "right", liveness_s=1.0)])
    assert drv.live.limits == [0.25, 1.0]
    assert drv.live.liveness_s == 1.0
