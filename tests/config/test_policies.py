"""The configuration's choices are enums (:class:`gateway.core.settings.Choice`): read from
the YAML values, equal to them, printed as them, and checked however a LoopConfig is made."""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING

import pytest
import yaml

from gateway.config import load_config, parse_config
from gateway.config.keys import GATEWAY_KEYS, LINKAGE_KEYS
from gateway.core.errors import ConfigError
from gateway.core.protection import WatchdogPolicy
from gateway.core.settings import (
    LOOP_CHOICES,
    EstopRelease,
    FaultAction,
    FeedbackRecovery,
    InfeasiblePolicy,
    Linkage,
    LoopConfig,
)
from tests.conftest import CONFIG_DIR

if TYPE_CHECKING:
    import enum

BASE = yaml.safe_load((CONFIG_DIR / "turtlebot3_burger.yaml").read_text())


def test_the_yaml_values_become_enums() -> None:
    block = {"infeasible_policy": "project", "feedback_recovery": "manual",
             "fault_action": "disarm", "estop_release": "any", "controller_watchdog": "warn"}
    loop = parse_config({**BASE, "gateway": block}, "robot.yaml").loop
    assert loop.infeasible_policy is InfeasiblePolicy.PROJECT
    assert loop.feedback_recovery is FeedbackRecovery.MANUAL
    assert loop.fault_action is FaultAction.DISARM
    assert loop.estop_release is EstopRelease.ANY
    assert loop.controller_watchdog is WatchdogPolicy.WARN
    # Equal to, hashed as and printed as their YAML values: comparisons with the YAML text and
    # messages that print them stay as they were.
    for key, value in block.items():
        member = getattr(loop, key)
        assert member == value and hash(member) == hash(value)
        if key != "controller_watchdog":  # WatchdogPolicy is older and prints as a plain Enum
            assert str(member) == value and f"{member}|{member:>8}" == f"{value}|{value:>8}"


def test_the_defaults_are_enums() -> None:
    loop = LoopConfig()
    for key, kind in LOOP_CHOICES.items():
        assert type(getattr(loop, key)) is kind, key


@pytest.mark.parametrize(("key", "value", "member"), [
    ("infeasible_policy", "project", InfeasiblePolicy.PROJECT),
    ("feedback_recovery", "manual", FeedbackRecovery.MANUAL),
    ("fault_action", "disarm", FaultAction.DISARM),
    ("estop_release", "any", EstopRelease.ANY),
    ("controller_watchdog", "warn", WatchdogPolicy.WARN),
])
def test_a_loop_config_made_in_code_takes_the_values(key: str, value: str,
                                                     member: enum.Enum) -> None:
    loop = dataclasses.replace(LoopConfig(), **{key: value})  # type: ignore[arg-type]
    assert getattr(loop, key) is member


def test_a_loop_config_made_in_code_refuses_other_values() -> None:
    with pytest.raises(ConfigError) as info:
        LoopConfig(fault_action="stop")  # type: ignore[arg-type]
    assert str(info.value) == "gateway.fault_action: expected one of 'zero', 'disarm', got 'stop'"


def test_the_key_tables_offer_the_enums_values() -> None:
    loop = LoopConfig()
    for key, kind in LOOP_CHOICES.items():
        spec = GATEWAY_KEYS[key]
        assert spec.choices == tuple(m.value for m in kind)
        assert spec.default == getattr(loop, key).value
    assert LINKAGE_KEYS["linkage"].choices == ("direct", "ackermann")


def test_linkages_are_enums() -> None:
    (actuator,) = load_config(CONFIG_DIR / "ackermann.yaml").steering
    assert type(actuator.linkage) is Linkage
    assert actuator.linkage == "ackermann"
    assert {a.linkage for a in load_config(CONFIG_DIR / "swerve.yaml").steering} == {
        Linkage.DIRECT}


def test_a_bad_linkage_is_named() -> None:
    raw = yaml.safe_load((CONFIG_DIR / "ackermann.yaml").read_text())
    (name,) = raw["steering"]
    raw["steering"][name]["linkage"] = "chain"
    with pytest.raises(ConfigError) as info:
        parse_config(raw, "car.yaml")
    assert str(info.value) == (f"car.yaml: steering.{name}.linkage: expected one of 'direct', "
                               f"'ackermann', got 'chain'")
