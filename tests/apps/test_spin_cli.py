"""``wheelgate spin`` on python-can's virtual bus, against the real shaft: the motor's simulated
controller made from the *true* configuration, while spin is given one with a mistake in it.

The encoder agrees with the command whatever ``invert`` and ``gear_ratio`` say (wheelgate turns
both through them), so the mistakes show only in what the operator sees: the tests' operator
answers from the simulated shaft (:class:`tests.apps.spin_helpers.Operator`).  What reaches the
bus and the simulated wheel is checked, not only what spin prints.
"""

from __future__ import annotations

import json
import math
from typing import TYPE_CHECKING, Any

import pytest

from gateway.cli import main
from gateway.sim.device import SimFault
from tests.apps.spin_helpers import Listener, Operator, Shaft, robot_config

if TYPE_CHECKING:
    from pathlib import Path

    from click.testing import CliRunner, Result

pytestmark = pytest.mark.timeout(60)

#: A short spin: 0.2 s ramps, 0.8 s measured.
SHORT = ["--duration", "1.5"]


def spin(runner: CliRunner, config: Path, *args: str, stdin: Any = None) -> Result:
    return runner.invoke(main, ["spin", "-c", str(config), *args], input=stdin)


def verdict(result: Result) -> dict[str, Any]:
    """The JSON verdict: the last line of stdout (a prompt's echo may come before)."""
    doc: dict[str, Any] = json.loads(result.stdout.strip().splitlines()[-1])
    return doc


def test_a_wrong_invert_is_seen_and_advised(runner: CliRunner, channel: str,
                                            tmp_path: Path) -> None:
    true = robot_config(tmp_path / "true.yaml", channel)  # right: invert: true
    wrong = robot_config(tmp_path / "wrong.yaml", channel, motors={"right": {"invert": False}})
    with Shaft(true, "right") as shaft:
        operator = Operator(shaft.answer)
        result = spin(runner, wrong, "right", *SHORT, "--json", stdin=operator)
        turned = shaft.turned()
    assert result.exit_code == 4, result.output
    assert operator.asked.is_set()
    doc = verdict(result)
    # The controller followed (the encoder agrees), the wheel turned the other way.
    assert doc["measured"]["ratio"] == pytest.approx(1.0, abs=0.1)
    assert turned < -1.0
    assert [f["check"] for f in doc["findings"]] == ["invert"]
    assert doc["findings"][0]["advice"].endswith(
        "for +1.00 rad/s: set invert: true on right")
    assert doc["findings"][0]["advice"].startswith("seen -1.0")


def test_a_wrong_gear_ratio_is_seen_and_the_true_one_advised(runner: CliRunner, channel: str,
                                                             tmp_path: Path) -> None:
    true = robot_config(tmp_path / "true.yaml", channel)  # gear_ratio 1.0
    wrong = robot_config(tmp_path / "wrong.yaml", channel, motors={"left": {"gear_ratio": 10.0}})
    with Shaft(true, "left") as shaft:
        result = spin(runner, wrong, "left", *SHORT, stdin=Operator(shaft.answer))
        turned = shaft.turned()
    assert result.exit_code == 4, result.output
    assert turned > 0
    lines = result.stdout.strip().splitlines()
    assert lines[-1].startswith("left: seen +3.")  # 10x the commanded 0.32 rad/s
    assert "x the command): check gear_ratio on left: 10 would be about 1" in lines[-1]


def test_a_steering_actuator_with_a_wrong_invert(runner: CliRunner, channel: str,
                                                 tmp_path: Path) -> None:
    true = robot_config(tmp_path / "true.yaml", channel, base="ackermann.yaml")
    wrong = robot_config(tmp_path / "wrong.yaml", channel, base="ackermann.yaml",
                         steering={"front_axle": {"invert": True}})
    with Shaft(true, "front_axle steering") as shaft:
        result = spin(runner, wrong, "front_axle_steering", "--duration", "2.5", "--speed", "0.5",
                      "--json", stdin=Operator(shaft.answer))
        peak = shaft.turned()
    assert result.exit_code == 4, result.output
    doc = verdict(result)
    assert doc["role"] == "steer" and doc["commanded"] == pytest.approx(math.radians(15))
    assert peak == pytest.approx(-math.radians(15), abs=math.radians(2))
    assert [f["check"] for f in doc["findings"]] == ["invert"]
    assert doc["findings"][0]["advice"].endswith("set invert: false on front_axle steering")


def test_a_right_configuration_agrees(runner: CliRunner, channel: str, tmp_path: Path) -> None:
    config = robot_config(tmp_path / "robot.yaml", channel)
    with Shaft(config, "right") as shaft:
        result = spin(runner, config, "right", *SHORT, stdin=Operator(shaft.answer))
    assert result.exit_code == 0, result.output
    assert result.stdout.strip().splitlines()[-1] == (
        "right: agrees: measured +1.00 rad/s for +1.00 rad/s, and the wheel did as described")
    assert "rolling the robot forward" in result.stderr
    assert "virtual bus exists only inside this process, so only simulators in it" in (
        result.stderr)


def test_no_ask_judges_the_controller_alone_and_says_so(runner: CliRunner, channel: str,
                                                         tmp_path: Path) -> None:
    true = robot_config(tmp_path / "true.yaml", channel)
    wrong = robot_config(tmp_path / "wrong.yaml", channel, motors={"right": {"invert": False}})
    with Shaft(true, "right") as shaft:
        operator = Operator(shaft.answer)
        result = spin(runner, wrong, "right", *SHORT, "--no-ask", stdin=operator)
    assert result.exit_code == 0, result.output
    assert not operator.asked.is_set()
    assert result.stdout.splitlines()[0] == (
        "right: the controller agrees: measured +1.00 rad/s for +1.00 rad/s; invert and "
        "gear_ratio were not checked by a person (--no-ask)")
    assert "note: invert and gear_ratio were not checked" in result.stdout


@pytest.mark.parametrize("json_out", [False, True])
def test_no_answer_without_no_ask_does_not_pass(runner: CliRunner, channel: str,
                                                tmp_path: Path, json_out: bool) -> None:
    """Standard input at its end (a script, a pipe): the question goes unanswered, so invert
    and gear_ratio went unchecked: exit 1, saying so, not a silent 0."""
    config = robot_config(tmp_path / "robot.yaml", channel)
    with Shaft(config, "right"):
        result = spin(runner, config, "right", *SHORT, *(["--json"] if json_out else []),
                      stdin="")
    assert result.exit_code == 1, result.output
    assert ("spin: not checked: invert and gear_ratio of right (no answer: standard input "
            "ended); run spin where you can watch the wheel and answer, or give --no-ask") in (
        " ".join(result.stderr.split()))
    if json_out:
        doc = verdict(result)
        assert doc["ok"] is False and not doc["config_checked"]  # "ok" is exit status 0
        assert doc["unchecked"] == "no answer: standard input ended"
    else:
        assert "right: the controller agrees: measured +1.00 rad/s for +1.00 rad/s; invert " \
               "and gear_ratio were not checked by a person (no answer: standard input " \
               "ended)" in result.stdout


def test_a_stalled_wheel_did_not_turn(runner: CliRunner, channel: str, tmp_path: Path) -> None:
    config = robot_config(tmp_path / "robot.yaml", channel)
    with Shaft(config, "left") as shaft:
        shaft.sim.inject(SimFault.STALL)
        result = spin(runner, config, "left", *SHORT, "--json")
    assert result.exit_code == 4, result.output
    assert [f["check"] for f in verdict(result)["findings"]] == ["no_motion"]


def test_sim_agrees_and_the_simulator_answers(runner: CliRunner, channel: str,
                                              tmp_path: Path) -> None:
    config = robot_config(tmp_path / "robot.yaml", channel, base="mecanum.yaml")
    result = spin(runner, config, "front_left", "--sim", *SHORT, "--json")
    assert result.exit_code == 0, result.output
    doc = verdict(result)
    assert doc["ok"] and doc["seen_ratio"] == pytest.approx(1.0, abs=0.05)


def test_a_motor_that_does_not_answer_did_not_enable(runner: CliRunner, channel: str,
                                                     tmp_path: Path) -> None:
    config = robot_config(tmp_path / "robot.yaml", channel, gateway={"enable_timeout_s": 0.5})
    with Listener(channel) as bus:
        result = spin(runner, config, "left", *SHORT)
        sent = bus.frames()
    assert result.exit_code == 1, result.output
    assert ("Error: left (odrive node 1) did not enable within 0.5 s "
            "(gateway.enable_timeout_s): no feedback from it") in result.stderr
    # After the error, that the stop went out.
    error = result.stderr.index("Error: left (odrive node 1) did not enable")
    assert result.stderr.index("spin: stop sent (zero and disarm) after the error") > error
    result = spin(runner, config, "left", *SHORT, "--json")
    assert result.exit_code == 1, result.output
    doc = json.loads(result.stdout)
    assert doc["ok"] is False and doc["error"]["code"] == "not_enabled"
    assert doc["error"]["message"].endswith("; stop sent (zero and disarm) after the error")
    # The stop went out all the same: the ODrive's Set_Axis_State IDLE (cmd 0x07, state 1).
    assert any(f.arbitration_id == (1 << 5 | 0x07) and f.data[:4] == bytes([1, 0, 0, 0])
               for f in sent), [f.to_cansend() for f in sent]


@pytest.mark.parametrize(("args", "hint", "text"), [
    (["lfet"], "MOTOR", "did you mean 'left'? expected a motor of turtlebot3_burger: "
                        "'left', 'right'; got 'lfet'"),
    # At most half the limit (6.39 rad/s), as --help says.
    (["left", "--speed", "4"], "--speed", "expected 0.1 to 3.19 rad/s at the wheel either way "
                                          "(a spin goes at most half the limit, 6.39, of"),
    (["left", "--speed", "0.05"], "--speed", "expected 0.1 to 3.19"),
    (["left", "--duration", "0.5"], "--duration", "expected 1 to 30 s, got 0.5"),
    (["left", "--duration", "nan"], "--duration", "expected a finite number"),
])
def test_usage_errors(runner: CliRunner, channel: str, tmp_path: Path, args: list[str],
                      hint: str, text: str) -> None:
    config = robot_config(tmp_path / "robot.yaml", channel)
    result = spin(runner, config, *args)
    assert result.exit_code == 2, result.output
    assert hint in result.stderr and text in " ".join(result.stderr.split())
    # with --json, the same error as a JSON object on stdout
    doc = json.loads(spin(runner, config, *args, "--json").stdout)
    assert doc["ok"] is False and doc["error"]["code"] == "bad_usage"
    assert hint in doc["error"]["message"] and text in " ".join(doc["error"]["message"].split())


def test_a_passive_wheel_has_no_motor(runner: CliRunner, channel: str, tmp_path: Path) -> None:
    config = robot_config(tmp_path / "robot.yaml", channel, base="differential_castor.yaml")
    result = spin(runner, config, "castor")
    assert result.exit_code == 2, result.output
    assert "wheel 'castor' is passive (no motor)" in result.stderr


def test_a_speed_the_vesc_does_not_control_is_refused(runner: CliRunner, channel: str,
                                                      tmp_path: Path) -> None:
    config = robot_config(tmp_path / "robot.yaml", channel, base="differential_tub.yaml")
    result = spin(runner, config, "left", "--speed", "1.0")
    assert result.exit_code == 2, result.output
    assert "does not speed-control" in result.stderr and "at least 2.69 rad/s" in result.stderr
