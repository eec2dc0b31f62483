"""ROS 2 names: validation as ``rmw`` does it, and resolution to fully qualified topic names."""

from __future__ import annotations

import re

import pytest

from gateway.core.errors import ConfigError
from gateway.wire.ros2 import (
    resolve_topic_name,
    validate_full_topic_name,
    validate_namespace,
    validate_node_name,
    validate_topic_name,
)


@pytest.mark.parametrize(("name", "namespace", "full"), [
    ("cmd_vel", "/", "/cmd_vel"),
    ("cmd_vel", "", "/cmd_vel"),
    ("cmd_vel", "/robot1", "/robot1/cmd_vel"),
    ("cmd_vel", "robot1", "/robot1/cmd_vel"),
    ("cmd_vel", "/fleet/robot_1", "/fleet/robot_1/cmd_vel"),
    ("nav/cmd_vel", "/robot1", "/robot1/nav/cmd_vel"),
    ("/tf", "/robot1", "/tf"),
    ("_hidden/x9", "/", "/_hidden/x9"),
])
def test_names_resolve_like_rcl(name: str, namespace: str, full: str) -> None:
    assert resolve_topic_name(name, namespace) == full
    assert validate_full_topic_name(full) == full


@pytest.mark.parametrize(("name", "why"), [
    ("", r"expected a topic name such as 'cmd_vel', got ''"),
    ("/", r"expected a topic name such as 'cmd_vel', got '/'"),
    ("cmd_vel/", r"expected no trailing '/', got 'cmd_vel/'"),
    ("a//b", r"got 'a//b' \(it has \"//\"\)"),
    ("/9lives", r"got '/9lives' \(token '9lives' starts with a digit\)"),
    ("robot/2d_nav", r"token '2d_nav' starts with a digit"),
    ("cmd-vel", r"got 'cmd-vel' \(character '-'\)$"),
    ("cmd vel", r"\(character ' '\)"),
    ("~/odom", r"\(character '~'\) \(private and substituted names are not supported\)"),
    ("{node}/odom", r"\(character '\{'\) \(private"),
    ("ödom", r"\(character 'ö'\)"),
])
def test_bad_topic_names_are_config_errors_naming_the_key(name: str, why: str) -> None:
    with pytest.raises(ConfigError, match=r"^bridge\.topics\.cmd_vel: expected ") as info:
        resolve_topic_name(name, "/", "bridge.topics.cmd_vel")
    assert re.search(why, str(info.value))


def test_the_rules_are_spelled_out_in_the_message() -> None:
    with pytest.raises(ConfigError, match=r'^topic name: expected letters, digits and "_" in '
                                          r'tokens separated by single "/", no token starting '
                                          r"with a digit, got '9'"):
        validate_topic_name("9")


def test_a_topic_name_that_is_not_a_string_is_a_config_error() -> None:
    with pytest.raises(ConfigError, match=r"^topic name: expected a topic name .*got 5$"):
        validate_topic_name(5)  # type: ignore[arg-type]


@pytest.mark.parametrize(("namespace", "why"), [
    ("/robot1/", r"expected no trailing '/', got '/robot1/'"),
    ("//robot1", r"it has \"//\""),
    ("/1robot", r"token '1robot' starts with a digit"),
    ("/robot.1", r"character '\.'"),
    ("/" + "a" * 245, r"expected at most 245 characters, got 246"),
    (None, r"expected a namespace such as '/robot1', got None"),
])
def test_bad_namespaces_are_config_errors(namespace: str, why: str) -> None:
    with pytest.raises(ConfigError, match=r"^bridge\.namespace: expected ") as info:
        validate_namespace(namespace, "bridge.namespace")
    assert re.search(why, str(info.value))


def test_a_bad_namespace_of_a_relative_topic_is_named() -> None:
    with pytest.raises(ConfigError, match=r"^namespace of odom topic: expected"):
        resolve_topic_name("odom", "/9", "odom topic")


def test_fully_qualified_names_are_at_most_247_characters() -> None:
    assert len(resolve_topic_name("/" + "a" * 246)) == 247
    with pytest.raises(ConfigError, match=r"expected at most 247 characters fully qualified, "
                                          r"got 248"):
        resolve_topic_name("/" + "a" * 247)
    with pytest.raises(ConfigError, match=r"got 248"):
        resolve_topic_name("b" * 100, "/" + "a" * 146)


def test_a_fully_qualified_name_must_start_with_a_slash() -> None:
    with pytest.raises(ConfigError, match=r"^topic name: expected a fully qualified name such "
                                          r"as '/cmd_vel', got 'cmd_vel'$"):
        validate_full_topic_name("cmd_vel")


@pytest.mark.parametrize(("name", "why"), [
    ("", r"expected a node name such as 'wheelgate', got ''"),
    ("ns/node", r"expected a node name without '/', got 'ns/node'"),
    ("2node", r"token '2node' starts with a digit"),
    ("node-1", r"character '-'"),
    ("n" * 256, r"expected at most 255 characters, got 256"),
])
def test_bad_node_names_are_config_errors(name: str, why: str) -> None:
    with pytest.raises(ConfigError, match=r"^node name: expected ") as info:
        validate_node_name(name)
    assert re.search(why, str(info.value))
    assert validate_node_name("wheelgate_bridge") == "wheelgate_bridge"
