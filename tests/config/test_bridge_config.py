"""The ``bridge:`` and ``foxglove:`` blocks: defaults that listen nowhere, precise errors, the
warnings, and ``check`` without Zenoh or the Foxglove SDK imported."""

from __future__ import annotations

import math
import subprocess
import sys
from typing import TYPE_CHECKING

import pytest
import yaml

from gateway.config import parse_config
from gateway.core.bridge_settings import (
    AttachmentFormat,
    BridgeSettings,
    DeadmanAction,
    ZenohMode,
)
from gateway.core.errors import ConfigError
from tests.conftest import REPO

if TYPE_CHECKING:
    from pathlib import Path

    from gateway.core.settings import GatewayConfig

DEFAULT = yaml.safe_load((REPO / "gateway" / "data" / "default.yaml").read_text())


def parse(**blocks: object) -> tuple[GatewayConfig, tuple[str, ...]]:
    cfg = parse_config({**DEFAULT, **blocks}, "robot.yaml")
    return cfg, cfg.warnings


def bridge(**blocks: object) -> BridgeSettings:
    b = parse(**blocks)[0].bridge
    assert b is not None
    return b


def test_without_the_blocks_there_is_no_bridge_and_no_view() -> None:
    cfg = parse_config(DEFAULT, "robot.yaml")
    assert cfg.bridge is None and cfg.foxglove is None


def test_an_empty_bridge_block_listens_nowhere_and_scouts_nothing() -> None:
    b = bridge(bridge={})
    warnings = parse(bridge={})[1]
    assert b.zenoh.mode is ZenohMode.PEER
    assert b.zenoh.listen == () and b.zenoh.connect == ()
    assert b.zenoh.multicast_scouting is False
    assert b.namespace == "demo_mecanum" and b.ros_namespace == ""
    assert b.ros2 is None and b.deadman is DeadmanAction.STOP
    assert not [w for w in warnings if "bridge" in w]


def test_the_issue_example_reads_as_written() -> None:
    b = bridge(bridge={
        "zenoh": {"mode": "peer", "listen": ["tcp/127.0.0.1:7447"], "connect": [],
                  "multicast_scouting": False},
        "namespace": "robot1",
        "ros2": {"domain_id": 0, "cmd_vel": "cmd_vel", "odom": "odom"},
    })
    assert b.ros2 is not None
    assert b.zenoh.listen == ("tcp/127.0.0.1:7447",)
    assert b.namespace == "robot1" and b.ros_namespace == "robot1"
    assert b.ros2.cmd_vel == "cmd_vel" and b.ros2.odom_frame == "odom"
    assert b.ros2.base_frame == "base_link" and b.ros2.tf is True
    assert b.ros2.attachment is AttachmentFormat.POSITIONAL


def test_the_attachment_of_jazzys_first_rmw_zenoh_releases() -> None:
    b = bridge(bridge={"ros2": {"attachment": "labelled"}})
    assert b.ros2 is not None and b.ros2.attachment is AttachmentFormat.LABELLED


@pytest.mark.parametrize(("block", "message"), [
    ({"zenoh": {"listen": ["7447"]}},
     "bridge.zenoh.listen[0]: expected an endpoint '<protocol>/<address>' such as "
     "'tcp/127.0.0.1:7447', got '7447'"),
    ({"zenoh": {"listen": "tcp/127.0.0.1:7447"}},
     "bridge.zenoh.listen: expected list, got 'tcp/127.0.0.1:7447'"),
    ({"zenoh": {"mode": "router"}}, "bridge.zenoh.mode: expected one of 'peer', 'client'"),
    ({"zenoh": {"lease_s": 0}}, "bridge.zenoh.lease_s: expected at least 0.1, got 0"),
    ({"zenoh": {"listne": []}}, "bridge.zenoh.listne: unknown key"),
    ({"namespace": "robot 1"}, "bridge.namespace: expected a name of tokens"),
    ({"namespace": "/robot1"}, "bridge.namespace: expected a name of tokens"),
    ({"namespace": "1robot"}, "bridge.namespace: expected a name of tokens"),
    ({"ros2": {"cmd_vel": "cmd vel"}},
     "bridge.ros2.cmd_vel: expected letters, digits and \"_\" in tokens separated by single "
     "\"/\", no token starting with a digit, got 'cmd vel' (character ' ')"),
    ({"ros2": {"cmd_vel": "cmd_vel/"}}, "bridge.ros2.cmd_vel: expected no trailing '/'"),
    ({"ros2": {"node_name": "a/b"}},
     "bridge.ros2.node_name: expected a node name without '/', got 'a/b'"),
    ({"ros2": {"odom_frame": "/odom"}}, "bridge.ros2.odom_frame: expected a name of tokens"),
    ({"ros2": {"base_frame": "odom"}},
     "bridge.ros2.base_frame: expected a frame other than odom_frame, got 'odom' for both"),
    ({"ros2": {"domain_id": 300}}, "bridge.ros2.domain_id: expected at most 232, got 300"),
    ({"ros2": {"attachment": "labeled"}},
     "bridge.ros2.attachment: expected one of 'positional', 'labelled', got 'labeled'"),
    ({"deadman": "halt"}, "bridge.deadman: expected one of 'stop', 'estop', got 'halt'"),
    ({"zenoh": {"listen": ["tcp/127.0.0.1"]}},
     "bridge.zenoh.listen[0]: expected 'tcp/<host>:<port>' (port 0 to 65535; an IPv6 address "
     "in brackets, e.g. 'tcp/[::1]:7447'), got 'tcp/127.0.0.1'"),
    ({"zenoh": {"connect": ["udp/10.0.0.2:99999"]}},
     "bridge.zenoh.connect[0]: expected 'udp/<host>:<port>'"),
    ({"zenoh": {"connect": ["tcp/::1:7447"]}}, "bridge.zenoh.connect[0]: expected 'tcp/<host>"),
    ({"zenoh": {"listen": ["tcp/a\x00b:7447"]}},
     "bridge.zenoh.listen[0]: expected an endpoint '<protocol>/<address>'"),
    ({"ros2": {"odom": "cmd_vel"}},
     "bridge.ros2.odom: expected a topic other than cmd_vel's, got 'cmd_vel', which is "
     "'/cmd_vel' as cmd_vel is"),
    ({"namespace": "r1", "ros2": {"odom": "/r1/cmd_vel"}},
     "bridge.ros2.odom: expected a topic other than cmd_vel's"),
    ({"ros2": {"joint_states": "odom"}},
     "bridge.ros2.joint_states: expected a topic other than odom's, got 'odom', which is "
     "'/odom' as odom is"),
    ({"ros2": {"joint_states": "joint states"}}, "bridge.ros2.joint_states: expected letters"),
    ({"ros2": {"joint_states": "/diagnostics", "diagnostics": "/diagnostics"}},
     "bridge.ros2.diagnostics: expected a topic other than joint_states's, got '/diagnostics', "
     "which is '/diagnostics' as joint_states is"),
    ({"ros2": {"diagnostics": "diag nostics"}}, "bridge.ros2.diagnostics: expected letters"),
    ({"ros2": {"pose_covariance_diagonal": [0.001] * 5}},
     "bridge.ros2.pose_covariance_diagonal: expected 6 variances (x, y, z, rotation about x, "
     "y, z: finite numbers >= 0, the diagonal of a covariance), got [0.001, 0.001, 0.001, "
     "0.001, 0.001]"),
    ({"ros2": {"twist_covariance_diagonal": [0.001, 0.001, -1, 0, 0, 0]}},
     "bridge.ros2.twist_covariance_diagonal: expected 6 variances"),
    ({"ros2": {"twist_covariance_diagonal": [0.001, 0.001, math.nan, 0, 0, 0]}},
     "bridge.ros2.twist_covariance_diagonal: expected 6 variances"),
    ({"ros2": {"pose_covariance_diagonal": [0, 0, 0, 0, 0, True]}},
     "bridge.ros2.pose_covariance_diagonal: expected 6 variances"),
    ({"ros2": {"pose_covariance_diagonal": "0.001"}},
     "bridge.ros2.pose_covariance_diagonal: expected list, got '0.001'"),
    ({"ros2": {"joints": ["front_left"]}},
     "bridge.ros2.joints: expected dict, got ['front_left']"),
    ({"ros2": {"joints": {"front_left": "front left joint"}}},
     "bridge.ros2.joints.front_left: expected a joint name of 1 to 100 printable characters "
     "without spaces, got 'front left joint'"),
    ({"ros2": {"joints": {"front_left": "j", "rear_left": "j"}}},
     "bridge.ros2.joints.front_left: expected a joint name of its own, got 'j', which another "
     "wheel or actuator has too"),
    ({"ros2": {"joints": {"front_lft": "j"}}},
     "bridge.ros2.joints.front_lft: expected a wheel or steering actuator of the robot "
     "(front_left, front_right, rear_left, rear_right), got 'front_lft'"),
    ({"ros2": {"joints": {"front_left": "rear_left"}}},
     "bridge.ros2.joints.front_left: expected a joint name no other wheel or actuator keeps "
     "as its own, got 'rear_left'"),
    ({"ros": {}}, "bridge.ros: unknown key; did you mean 'ros2'? (known bridge keys: deadman, "
     "namespace, ros2, zenoh)"),
    ("yes", "bridge: expected a mapping, got 'yes'"),
])
def test_a_bad_bridge_block_names_the_key(block: object, message: str) -> None:
    with pytest.raises(ConfigError) as err:
        parse(bridge=block)
    assert str(err.value).startswith("robot.yaml: "), err.value
    assert message in str(err.value), err.value


def test_endpoints_zenoh_takes_are_accepted() -> None:
    z = bridge(bridge={"zenoh": {"listen": ["tcp/[::1]:7447", "tcp/robot.local:0"],
                                 "connect": ["tcp/192.168.1.10:7447#iface=eth0",
                                             "unixsock-stream//run/zenoh.sock"]}}).zenoh
    assert z.listen == ("tcp/[::1]:7447", "tcp/robot.local:0")
    assert z.connect[1] == "unixsock-stream//run/zenoh.sock"


@pytest.mark.parametrize("name", ["robot/", "/robot1", "a//b", "robot 1"])
def test_a_robot_name_that_cannot_name_the_keys_is_refused_without_a_namespace(
        name: str) -> None:
    """The robot's name names the native keys when no namespace is given: a name Zenoh would
    refuse (an empty chunk) is refused when the file is read, naming the key and the fix --
    not a traceback when the daemon declares its keys."""
    with pytest.raises(ConfigError) as err:
        parse(name=name, bridge={})
    text = str(err.value)
    assert text.startswith("robot.yaml: name: expected a name of tokens"), text
    assert f"got {name!r}" in text and "set bridge.namespace" in text
    assert bridge(name=name, bridge={"namespace": "robot1"}).namespace == "robot1"


def test_an_absolute_topic_is_accepted() -> None:
    ros2 = bridge(bridge={"ros2": {"cmd_vel": "/teleop/cmd_vel"}}).ros2
    assert ros2 is not None and ros2.cmd_vel == "/teleop/cmd_vel"


def test_listening_everywhere_and_multicast_are_warned_about() -> None:
    everywhere = ["tcp/0.0.0.0:7447", "tcp/[::]:7448", "tcp/[0:0:0:0:0:0:0:0]:7449",
                  "udp/[::0]:7450", "tcp/0:7452", "tcp/000.000.000.000:7453",
                  "tcp/[::ffff:0.0.0.0]:7454"]
    _, warnings = parse(bridge={"zenoh": {"listen": [*everywhere, "tcp/127.0.0.1:7451"],
                                          "multicast_scouting": True}})
    text = "\n".join(warnings)
    for endpoint in everywhere:
        assert f"{endpoint} listens on every network interface" in text
    assert "7451" not in text
    assert "multicast_scouting: on" in text


def test_the_foxglove_block() -> None:
    fox = parse(foxglove={})[0].foxglove
    assert fox is not None
    assert (fox.host, fox.port, fox.mcap) == ("127.0.0.1", 8765, "")
    with pytest.raises(ConfigError, match=r"robot.yaml: foxglove.port: expected at most 65535"):
        parse(foxglove={"port": 70000})
    with pytest.raises(ConfigError, match=r"robot.yaml: foxglove.hots: unknown key"):
        parse(foxglove={"hots": "x"})


def test_check_validates_the_blocks_without_importing_zenoh_or_foxglove(tmp_path: Path) -> None:
    path = tmp_path / "robot.yaml"
    path.write_text(yaml.safe_dump({**DEFAULT, "bridge": {"ros2": {}}, "foxglove": {}}))
    code = (
        "import sys\n"
        "from gateway.cli import main\n"
        f"try:\n    main(['check', '-c', {str(path)!r}])\n"
        "except SystemExit as e:\n    assert e.code in (0, None), e.code\n"
        "bad = sorted(m for m in sys.modules if m.split('.')[0] in ('zenoh', 'foxglove', 'mcap'))\n"
        "assert not bad, bad\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=60, check=False)
    assert done.returncode == 0, done.stdout + done.stderr
    assert "ok" in done.stdout


def test_joint_states_are_off_unless_a_topic_is_given_and_joints_rename_wheels() -> None:
    ros2 = bridge(bridge={"ros2": {}}).ros2
    assert ros2 is not None and ros2.joint_states == "" and ros2.joints == ()
    assert ros2.services is False  # (the services too, unless asked for)
    ros2 = bridge(bridge={"ros2": {"services": True}}).ros2
    assert ros2 is not None and ros2.services is True and ros2.diagnostics == ""
    ros2 = bridge(bridge={"ros2": {"diagnostics": "/diagnostics"}}).ros2
    assert ros2 is not None and ros2.diagnostics == "/diagnostics"


def test_the_odometrys_variances_are_zero_unless_given() -> None:
    ros2 = bridge(bridge={"ros2": {}}).ros2
    assert ros2 is not None and ros2.pose_covariance_diagonal == (0.0,) * 6
    assert ros2.twist_covariance_diagonal == (0.0,) * 6
    ros2 = bridge(bridge={"ros2": {"pose_covariance_diagonal": [0.001, 0.001, 1e6, 1e6, 1e6, 0.03],
                                   "twist_covariance_diagonal": [1, 2, 3, 4, 5, 6]}}).ros2
    assert ros2 is not None and ros2.pose_covariance_diagonal == (0.001, 0.001, 1e6, 1e6, 1e6,
                                                                  0.03)
    assert ros2.twist_covariance_diagonal == (1.0, 2.0, 3.0, 4.0, 5.0, 6.0)
    ros2 = bridge(bridge={"ros2": {"joint_states": "joint_states", "joints": {
        "front_left": "fl_wheel_joint", "rear_left": "front_left"}}}).ros2
    assert ros2 is not None and ros2.joint_states == "joint_states"
    assert ros2.joints == (("front_left", "fl_wheel_joint"), ("rear_left", "front_left"))
