"""``wheelgate spin`` says what went wrong, and ``--json`` agrees with the exit status: a
configuration that leaves no spin possible is refused before anything is sent (no travel to
sweep, no speed its controller controls within its limit); what can only be known once armed
is an error after the stop; the gateway's refusal to arm a motor is not the controller's fault;
``"ok"`` is true exactly when the exit status is 0."""

from __future__ import annotations

import dataclasses
import functools
import json
import os
import signal
import time
from typing import TYPE_CHECKING, Any

import pytest
import yaml

from gateway.apps.spin.plan import steer_plan
from gateway.cli import main
from gateway.cli.commands import spin as spin_module
from gateway.sim.device import SimFault
from tests.apps.spin_helpers import (
    IDLE,
    Listener,
    Operator,
    Shaft,
    assert_stopped,
    robot_config,
    when_turning,
)

if TYPE_CHECKING:
    from pathlib import Path

    from click.testing import CliRunner, Result

    from gateway.core.settings import GatewayConfig
    from gateway.core.types import MotorConfig

pytestmark = pytest.mark.timeout(60)

SHORT = ["--duration", "1.5"]
#: The ackermann robot's steering actuator (ODrive node 3): Set_Axis_State.
STEER_AXIS_STATE = 3 << 5 | 0x07


def spin(runner: CliRunner, config: Path, *args: str, stdin: Any = None) -> Result:
    return runner.invoke(main, ["spin", "-c", str(config), *args], input=stdin)


def last_json(result: Result) -> dict[str, Any]:
    doc: dict[str, Any] = json.loads(result.stdout.strip().splitlines()[-1])
    return doc


# ----------------------------------------------------------------------------- "ok" and the exit


def test_ctrl_c_is_not_ok_in_json(runner: CliRunner, channel: str, tmp_path: Path) -> None:
    config = robot_config(tmp_path / "robot.yaml", channel)
    with Shaft(config, "left") as shaft, Listener(channel) as bus:
        when_turning(shaft, lambda: os.kill(os.getpid(), signal.SIGINT))
        result = spin(runner, config, "left", "--duration", "10", "--json")
        assert_stopped(shaft, bus.frames())
    assert result.exit_code == 130, result.output
    doc = last_json(result)
    assert doc["ok"] is False and doc["judged"] is False and doc["stopped_by"] == "Ctrl-C"


def test_not_seen_is_not_ok_in_json(runner: CliRunner, channel: str, tmp_path: Path) -> None:
    config = robot_config(tmp_path / "robot.yaml", channel)
    with Shaft(config, "right"):
        operator = Operator(lambda: "s")
        result = spin(runner, config, "right", *SHORT, "--json", stdin=operator)
    assert operator.asked.is_set()
    assert result.exit_code == 1, result.output
    doc = last_json(result)
    assert doc["ok"] is False and doc["judged"] is True and doc["findings"] == []
    assert doc["unchecked"] == "answered: not seen" and doc["config_checked"] is False


# ----------------------------------------------------------------------------- no room to sweep


def test_a_steering_actuator_without_travel_is_refused_before_arming(
        runner: CliRunner, channel: str, tmp_path: Path) -> None:
    config = robot_config(tmp_path / "robot.yaml", channel, base="ackermann.yaml",
                          geometry={"max_steer": 0.03})
    with Listener(channel) as bus:
        result = spin(runner, config, "front_axle_steering", "--sim")
        doc = json.loads(spin(runner, config, "front_axle_steering", "--json").stdout)
        assert bus.frames() == []
    assert result.exit_code == 2, result.output
    assert (f"Error: {config}: front_axle steering: no room to sweep: expected 2.5 deg "
            f"(0.0436 rad) of travel on one side of its neutral angle") in result.stderr
    assert "from geometry max_steer 0.03 rad" in result.stderr
    assert "enabled in" not in result.stderr and "Ctrl-C stops" not in result.stderr
    assert doc["ok"] is False and doc["error"]["code"] == "bad_config"
    assert "no room to sweep" in doc["error"]["message"]


def test_no_room_where_the_wheels_stand_is_an_error_after_the_stop(
        runner: CliRunner, channel: str, tmp_path: Path,
        monkeypatch: pytest.MonkeyPatch) -> None:
    # A travel of -0.01..+0.05 rad (steer_min/steer_max of a generic robot) has room from the
    # middle, but not from +0.02 rad, where the wheels stand: known only once armed.
    def lopsided(cfg: GatewayConfig, motor: MotorConfig, speed: float | None,
                 duration_s: float) -> Any:
        return steer_plan(dataclasses.replace(motor, steer_range_rad=(-0.01, 0.05)), speed,
                          duration_s, 1.0)

    monkeypatch.setattr(spin_module, "make_plan", lopsided)
    config = robot_config(tmp_path / "robot.yaml", channel, base="ackermann.yaml")
    for as_json in (False, True):
        with Shaft(config, "front_axle steering") as shaft, Listener(channel) as bus:
            model, stand = shaft.sim.model, shaft.sim.motor.steer_to_motor_rad(0.02)
            shaft.ctl.snapshot(functools.partial(setattr, model, "position_rad", stand))
            result = spin(runner, config, "front_axle_steering",
                          *(["--json"] if as_json else []))
            sent = bus.frames()
            deadline = time.monotonic() + 2.0
            while shaft.sim.model.armed:
                assert time.monotonic() < deadline, "the actuator was left armed"
                time.sleep(0.01)
        assert any(f.arbitration_id == STEER_AXIS_STATE and f.data[:4] == IDLE for f in sent)
        assert result.exit_code == 1, result.output
        assert "spin: enabled in" in result.stderr
        assert "spin: stop sent (zero and disarm) after the error" in result.stderr
        said = ("front_axle steering: its wheels stand at +1.1 deg within its travel "
                "-0.6..+2.9 deg: expected 2.5 deg of room on one side")
        if as_json:
            error = json.loads(result.stdout)["error"]
            assert error["code"] == "no_room" and error["message"].startswith(said)
        else:
            assert f"Error: {said}" in result.stderr and "Usage:" not in result.stderr


# ----------------------------------------------------------------------------- no speed


def test_a_vesc_whose_dead_band_passes_the_limit_has_no_spin_speed(
        runner: CliRunner, tmp_path: Path) -> None:
    # `init --drive differential --driver vesc`: TurtleBot wheels (max_rpm 61: 6.39 rad/s) on a
    # VESC at the factory's min_erpm 900 (13.46 rad/s at the wheel).
    config = tmp_path / "v.yaml"
    made = runner.invoke(main, ["init", "--drive", "differential", "--driver", "vesc", "-o",
                                str(config)])
    assert made.exit_code == 0, made.output
    raw = yaml.safe_load(config.read_text())
    assert raw["motor_defaults"]["min_erpm"] == 900 and raw["motor_defaults"]["max_rpm"] == 61
    said = ("left: no spin speed is possible: its vesc controller does not speed-control wheel "
            "speeds below 13.5 rad/s (min_erpm 900 through pole_pairs 7 and gear_ratio 1), and "
            "a spin goes at most 3.19 rad/s at the wheel (half the limit, 6.39, of max_rpm 61 "
            "through gear_ratio 1 and the robot's wheel speeds); lower min_erpm")
    for speed in ([], ["--speed", "13.5"], ["--speed", "3"]):
        result = spin(runner, config, "left", "--sim", *speed)
        assert result.exit_code == 2, result.output
        assert f"Error: {config}: {said}" in " ".join(result.stderr.split())
        assert "Invalid value for --speed" not in result.stderr
        assert "enabled in" not in result.stderr
    doc = json.loads(spin(runner, config, "left", "--sim", "--json").stdout)
    assert doc["ok"] is False and doc["error"]["code"] == "bad_config"
    assert said in doc["error"]["message"]


# ----------------------------------------------------------------------------- not armed


def test_a_watchdog_for_other_firmware_is_the_gateways_refusal(
        runner: CliRunner, channel: str, tmp_path: Path) -> None:
    # The axis reports firmware 0.6.10; the configuration's endpoint IDs are for 0.0.0 (the
    # shipped example's): the gateway writes nothing and does not arm it.
    endpoints = {"fw_version": "0.6.10", "enable_watchdog": 1, "watchdog_timeout": 2}
    true = robot_config(tmp_path / "true.yaml", channel, base="ackermann.yaml",
                        steering={"front_axle": {"watchdog_endpoints": endpoints}})
    config = robot_config(tmp_path / "robot.yaml", channel, base="ackermann.yaml")
    for as_json in (False, True):
        with Shaft(true, "front_axle steering") as shaft, Listener(channel) as bus:
            result = spin(runner, config, "front_axle_steering",
                          *(["--json"] if as_json else []))
            sent = bus.frames()
            assert not shaft.sim.model.armed
        assert any(f.arbitration_id == STEER_AXIS_STATE and f.data[:4] == IDLE for f in sent)
        assert result.exit_code == 1, result.output
        said = ("front_axle steering (odrive node 3) did not enable: the gateway did not arm "
                "it: its controller watchdog was not confirmed: the axis reports firmware "
                "0.6.10 (hardware 0.0.0), the endpoint IDs are for firmware 0.0.0; nothing was "
                "written (gateway.controller_watchdog: required arms no motor without it)")
        if as_json:
            error = json.loads(result.stdout)["error"]
            assert error["code"] == "not_armed", error
            assert error["message"] == f"{said}; stop sent (zero and disarm) after the error"
        else:
            assert f"Error: {said}" in result.stderr
            assert "reports a fault" not in result.stderr


def test_a_controller_fault_is_still_a_fault(runner: CliRunner, channel: str,
                                             tmp_path: Path) -> None:
    config = robot_config(tmp_path / "robot.yaml", channel)
    with Shaft(config, "left") as shaft:
        shaft.sim.inject(SimFault.FAULT)
        result = spin(runner, config, "left", *SHORT, "--json")
    assert result.exit_code == 1, result.output
    error = json.loads(result.stdout)["error"]
    assert error["code"] == "fault"
    assert error["message"].startswith("left (odrive node 1) did not enable: it reports a fault: "
                                       "'axis error 0x00000020: DRV_FAULT'")
