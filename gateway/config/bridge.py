"""The ``bridge:`` and ``foxglove:`` blocks of a configuration, checked without importing Zenoh
or the Foxglove SDK (``wheelgate check`` works on a core install).

::

    bridge:
      zenoh: {mode: peer, listen: ["tcp/127.0.0.1:7447"], connect: [], multicast_scouting: false}
      namespace: robot1
      ros2: {domain_id: 0, cmd_vel: cmd_vel, odom: odom}
      deadman: stop
    foxglove: {host: 127.0.0.1, port: 8765}

A Zenoh endpoint is ``<protocol>/<address>`` (Zenoh's locator syntax,
https://zenoh.io/docs/manual/configuration/); a listen endpoint on every interface
(``0.0.0.0``, ``[::]``) is accepted, as it was asked for, with a warning.
"""

from __future__ import annotations

import ipaddress
import math
import re
import socket
from types import MappingProxyType
from typing import TYPE_CHECKING

from gateway.core.bridge_settings import (
    AttachmentFormat,
    BridgeSettings,
    DeadmanAction,
    FoxgloveSettings,
    Ros2Settings,
    ZenohMode,
    ZenohSettings,
)
from gateway.core.choice import choice
from gateway.core.errors import ConfigError
from gateway.core.options import OptionSpec, validate_block

if TYPE_CHECKING:
    from collections.abc import Mapping, Sequence

__all__ = ["BRIDGE_KEYS", "FOXGLOVE_KEYS", "check_joints", "parse_bridge", "parse_foxglove"]

#: The longest joint name (characters).
MAX_JOINT_NAME = 100

_MODES = tuple(m.value for m in ZenohMode)
_ACTIONS = tuple(a.value for a in DeadmanAction)
_LAYOUTS = tuple(f.value for f in AttachmentFormat)

BRIDGE_KEYS: Mapping[str, OptionSpec] = MappingProxyType({
    "zenoh": OptionSpec(dict, {}, help="the Zenoh session: mode, listen, connect, ..."),
    "namespace": OptionSpec(str, "", help="wheelgate/<namespace>/... and the ROS 2 namespace"),
    "ros2": OptionSpec(dict, {}, help="ROS 2 topics over rmw_zenoh (omit for native keys only)"),
    "deadman": OptionSpec(str, "stop", choices=_ACTIONS,
                          help="what a lost commander does: stop or estop"),
})
ZENOH_KEYS: Mapping[str, OptionSpec] = MappingProxyType({
    "mode": OptionSpec(str, "peer", choices=_MODES),
    "listen": OptionSpec(list, [], help="endpoints to listen on, e.g. tcp/127.0.0.1:7447"),
    "connect": OptionSpec(list, [], help="endpoints to connect to (a router or a peer)"),
    "multicast_scouting": OptionSpec(bool, False),
    "lease_s": OptionSpec(float, 10.0, minimum=0.1, maximum=3600.0,
                          help="the gateway's lease: seconds its peers keep a silent gateway "
                               "and its tokens alive (a frozen commander is dropped after its "
                               "own lease)"),
})
_VARIANCES_HELP = ("the odometry's variances of x, y, z, rotation about x, y, z (diff_drive_"
                   "controller's key; zeros: not estimated)")
ROS2_KEYS: Mapping[str, OptionSpec] = MappingProxyType({
    "domain_id": OptionSpec(int, 0, minimum=0, maximum=232, help="ROS_DOMAIN_ID"),
    "cmd_vel": OptionSpec(str, "cmd_vel"),
    "odom": OptionSpec(str, "odom"),
    "tf": OptionSpec(bool, True, help="publish odom -> base_link on /tf"),
    "odom_frame": OptionSpec(str, "odom"),
    "base_frame": OptionSpec(str, "base_link"),
    "node_name": OptionSpec(str, "wheelgate"),
    "attachment": OptionSpec(str, "positional", choices=_LAYOUTS,
                             help="labelled for the rmw_zenoh 0.2.0 to 0.2.3 of Jazzy"),
    "joint_states": OptionSpec(str, "", help="topic of the wheels' and steering actuators' "
                                             "sensor_msgs/msg/JointState ('': none)"),
    "joints": OptionSpec(dict, {}, help="joint name per wheel or steering actuator (default: "
                                        "its own name), as the robot's URDF names them"),
    "services": OptionSpec(bool, False, help="std_srvs/srv/Trigger services ~/estop, "
                                             "~/enable, ~/disable of the gateway's node"),
    "pose_covariance_diagonal": OptionSpec(list, [0.0] * 6, help=_VARIANCES_HELP),
    "twist_covariance_diagonal": OptionSpec(list, [0.0] * 6, help=_VARIANCES_HELP),
    "diagnostics": OptionSpec(str, "", help="topic of the gateway's, bus's and motors' "
                                            "diagnostic_msgs/msg/DiagnosticArray, once a "
                                            "second ('': none; ROS's tools read /diagnostics)"),
})
FOXGLOVE_KEYS: Mapping[str, OptionSpec] = MappingProxyType({
    "host": OptionSpec(str, "127.0.0.1", help="address of the WebSocket server"),
    "port": OptionSpec(int, 8765, minimum=0, maximum=65535, help="0: any free port"),
    "mcap": OptionSpec(str, "", help="also record the channels to this MCAP file"),
})

#: A Zenoh locator: protocol, slash, address (host:port, a path for unix sockets), then
#: optionally Zenoh's ``?metadata`` and ``#config`` parts.
_ENDPOINT = re.compile(r"^(tcp|udp|tls|quic|ws|unixsock-stream|unixpipe)/([^?#\s\x00-\x1f\x7f]+)"
                       r"[^\s\x00-\x1f\x7f]*$")
#: The protocols whose address is ``host:port``.
_IP = frozenset({"tcp", "udp", "tls", "quic", "ws"})
#: ``host:port``, the host an IPv4 address, a name or a bracketed IPv6 address.
_HOST_PORT = re.compile(r"^(\[[0-9A-Fa-f:.]+\]|[^:\[\]]+):(\d{1,5})$")
#: One token of a name: ROS 2 naming rules (alphanumerics and underscores, no leading digit).
_TOKEN = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")


def _endpoints(value: object, where: str) -> tuple[str, ...]:
    if not isinstance(value, list):
        raise ConfigError(f"{where}: expected a list of endpoints, got {value!r}")
    for i, item in enumerate(value):
        m = _ENDPOINT.match(item) if isinstance(item, str) else None
        if m is None:
            raise ConfigError(
                f"{where}[{i}]: expected an endpoint '<protocol>/<address>' such as "
                f"'tcp/127.0.0.1:7447', got {item!r}"
            )
        if m.group(1) in _IP:
            hp = _HOST_PORT.match(m.group(2))
            if hp is None or int(hp.group(2)) > 65535:
                raise ConfigError(
                    f"{where}[{i}]: expected '{m.group(1)}/<host>:<port>' (port 0 to 65535; "
                    f"an IPv6 address in brackets, e.g. '{m.group(1)}/[::1]:7447'), got "
                    f"{item!r}"
                )
    return tuple(value)


def _everywhere(endpoint: str) -> bool:
    """Whether an endpoint listens on every interface: ``0.0.0.0`` or ``[::]`` in any spelling
    the resolver takes (``0``, ``000.000.000.000``, ``[0:0::0]``, ``[::ffff:0.0.0.0]``)."""
    m = _ENDPOINT.match(endpoint)
    hp = _HOST_PORT.match(m.group(2)) if m is not None else None
    if hp is None:
        return False
    host = hp.group(1).strip("[]")
    try:
        address = ipaddress.ip_address(host)
    except ValueError:  # a name, or an IPv4 spelling only inet_aton takes ("0", "0.0")
        try:
            return socket.inet_aton(host) == bytes(4)
        except (OSError, ValueError):  # (ValueError: a NUL in the name)
            return False
    mapped = getattr(address, "ipv4_mapped", None)
    return address.is_unspecified or (mapped is not None and mapped.is_unspecified)


def _variances(value: object, where: str) -> tuple[float, ...]:
    """Six variances (a covariance matrix's diagonal): finite numbers, none negative."""
    if (not isinstance(value, list) or len(value) != 6 or not all(
            isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
            and v >= 0.0 for v in value)):
        raise ConfigError(f"{where}: expected 6 variances (x, y, z, rotation about x, y, z: "
                          f"finite numbers >= 0, the diagonal of a covariance), got {value!r}")
    return tuple(float(v) for v in value)


def check_name(value: str, where: str) -> str:
    """A name of tokens of letters, digits and underscores (not starting with a digit)
    separated by ``/``, without a leading ``/``: a namespace as wheelgate's keys take it, a
    frame id as tf2 wants it.

    :raises ConfigError: naming ``where``, the rule and what came.
    """
    if not value or value[:1] == "/" or not all(_TOKEN.match(t) for t in value.split("/")):
        raise ConfigError(
            f"{where}: expected a name of tokens of letters, digits and underscores, not "
            f"starting with a digit, separated by '/', no leading '/', got {value!r}"
        )
    return value


def _joints(raw: object, where: str) -> tuple[tuple[str, str], ...]:
    """The ``joints:`` mapping: wheel or actuator name -> joint name (printable, no spaces,
    each used once)."""
    if not isinstance(raw, dict):  # (validate_block checked it)
        raise ConfigError(f"{where}: expected dict, got {raw!r}")
    pairs = []
    for name, joint in raw.items():
        if (not isinstance(joint, str) or not 0 < len(joint) <= MAX_JOINT_NAME
                or not joint.isprintable() or any(c.isspace() for c in joint)):
            raise ConfigError(f"{where}.{name}: expected a joint name of 1 to "
                              f"{MAX_JOINT_NAME} printable characters without spaces, got "
                              f"{joint!r}")
        pairs.append((str(name), joint))
    joints = [j for _, j in pairs]
    for name, joint in pairs:
        if joints.count(joint) > 1:
            raise ConfigError(f"{where}.{name}: expected a joint name of its own, got "
                              f"{joint!r}, which another wheel or actuator has too")
    return tuple(pairs)


def check_joints(bridge: BridgeSettings, names: Sequence[str], source: str) -> None:
    """The ``joints:`` of ``bridge.ros2`` name the robot's wheels and steering actuators
    (``names``), and no joint name is another one's own name.

    :raises ConfigError: naming the key, what was expected and what came.
    """
    ros2 = bridge.ros2
    if ros2 is None:
        return
    where = f"{source}: bridge.ros2.joints"
    renamed = dict(ros2.joints)
    for name, joint in ros2.joints:
        if name not in names:
            raise ConfigError(f"{where}.{name}: expected a wheel or steering actuator of the "
                              f"robot ({', '.join(names)}), got {name!r}")
        if joint in names and joint != name and joint not in renamed:
            raise ConfigError(f"{where}.{name}: expected a joint name no other wheel or "
                              f"actuator keeps as its own, got {joint!r}")


def parse_bridge(raw: object, source: str, robot: str) -> tuple[BridgeSettings, list[str]]:
    """The ``bridge:`` block and its warnings.

    :param robot: the robot's name: the native keys' namespace when none is given.
    :raises ConfigError: naming the key, what was expected and what came.
    """
    where = f"{source}: bridge"
    v = validate_block(raw, BRIDGE_KEYS, where, "bridge keys")
    z = validate_block(v["zenoh"], ZENOH_KEYS, f"{where}.zenoh", "zenoh keys")
    zenoh = ZenohSettings(
        mode=choice(ZenohMode, z["mode"], f"{where}.zenoh.mode"),
        listen=_endpoints(z["listen"], f"{where}.zenoh.listen"),
        connect=_endpoints(z["connect"], f"{where}.zenoh.connect"),
        multicast_scouting=bool(z["multicast_scouting"]),
        lease_s=float(z["lease_s"]),  # type: ignore[arg-type]
    )
    warnings = [
        f"{where}.zenoh.listen: {e} listens on every network interface: anyone on those "
        f"networks can drive the robot; expected a loopback or one interface's address"
        for e in zenoh.listen if _everywhere(e)
    ]
    if zenoh.multicast_scouting:
        warnings.append(f"{where}.zenoh.multicast_scouting: on: the robot announces itself to "
                        f"every host of its networks")
    namespace = str(v["namespace"])
    if namespace:
        check_name(namespace, f"{where}.namespace")
    else:
        try:
            check_name(robot, f"{source}: name")
        except ConfigError as err:
            raise ConfigError(f"{err}: with a bridge: block and no bridge.namespace, the "
                              f"robot's name names its keys (wheelgate/<name>/...); set "
                              f"bridge.namespace") from None
    native = namespace or robot
    ros2 = None
    if "ros2" in (raw if isinstance(raw, dict) else {}):
        r = validate_block(v["ros2"], ROS2_KEYS, f"{where}.ros2", "ros2 keys")
        # ROS's naming rules, from the bridge's wire layer: loaded only for a ros2: block.
        from gateway.wire.ros2.names import (  # noqa: PLC0415
            resolve_topic_name,
            validate_namespace,
            validate_node_name,
        )

        if namespace:
            validate_namespace(namespace, f"{where}.namespace")
        keys = ("cmd_vel", "odom", *(k for k in ("joint_states", "diagnostics") if r[k]))
        taken: dict[str, str] = {}  # topic (relative to the namespace, or absolute) -> key
        for key in keys:
            topic = resolve_topic_name(str(r[key]), namespace or "/", f"{where}.ros2.{key}")
            if topic in taken:
                raise ConfigError(f"{where}.ros2.{key}: expected a topic other than "
                                  f"{taken[topic]}'s, got {r[key]!r}, which is {topic!r} as "
                                  f"{taken[topic]} is")
            taken[topic] = key
        r["joints"] = _joints(r["joints"], f"{where}.ros2.joints")
        for key in ("pose_covariance_diagonal", "twist_covariance_diagonal"):
            r[key] = _variances(r[key], f"{where}.ros2.{key}")
        validate_node_name(str(r["node_name"]), f"{where}.ros2.node_name")
        for key in ("odom_frame", "base_frame"):
            check_name(str(r[key]), f"{where}.ros2.{key}")
        if r["odom_frame"] == r["base_frame"]:
            raise ConfigError(f"{where}.ros2.base_frame: expected a frame other than "
                              f"odom_frame, got {r['base_frame']!r} for both")
        r["attachment"] = choice(AttachmentFormat, r["attachment"], f"{where}.ros2.attachment")
        ros2 = Ros2Settings(**r)  # type: ignore[arg-type]
    deadman = choice(DeadmanAction, v["deadman"], f"{where}.deadman")
    return BridgeSettings(zenoh, native, ros2, deadman, namespace), warnings


def parse_foxglove(raw: object, source: str) -> FoxgloveSettings:
    """The ``foxglove:`` block.

    :raises ConfigError: naming the key, what was expected and what came.
    """
    v = validate_block(raw, FOXGLOVE_KEYS, f"{source}: foxglove", "foxglove keys")
    return FoxgloveSettings(str(v["host"]), int(v["port"]), str(v["mcap"]))  # type: ignore[call-overload]
