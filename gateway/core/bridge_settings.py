"""The ``bridge:`` and ``foxglove:`` blocks, validated: frozen dataclasses, no network code.

The configuration loader (:mod:`gateway.config.bridge`) fills these in without importing Zenoh or
the Foxglove SDK; the daemon starts :mod:`gateway.runtime.bridge` and
:mod:`gateway.runtime.liveview` from them.  Nothing listens on a network address that these do
not name: Zenoh's own defaults (listening on every interface, multicast scouting) are turned
off unless the block asks for them.
"""

from __future__ import annotations

from dataclasses import dataclass

from gateway.core.choice import Choice

__all__ = [
    "AttachmentFormat",
    "BridgeSettings",
    "DeadmanAction",
    "FoxgloveSettings",
    "Ros2Settings",
    "ZenohMode",
    "ZenohSettings",
]


class ZenohMode(Choice):
    """How the bridge's Zenoh session joins the network."""

    #: Talks to the peers it connects to or that connect to it.
    PEER = "peer"
    #: Talks through the router it connects to (e.g. ROS 2's ``rmw_zenohd``).
    CLIENT = "client"


class DeadmanAction(Choice):
    """What happens when the commander whose twist the robot follows disappears."""

    #: The target goes to zero within the deceleration limits.
    STOP = "stop"
    #: E-stop (latched; an explicit enable releases it).
    ESTOP = "estop"


class AttachmentFormat(Choice):
    """The two layouts of the attachment rmw_zenoh has put on every sample on Zenoh 1.x
    (:mod:`gateway.wire.ros2.attachment`); the ROS side drops samples in the other one."""

    #: 33 bytes, fields by position (rmw_zenoh >= 0.6.0 / Jazzy >= 0.2.4).
    POSITIONAL = "positional"
    #: 77 bytes, each field after its name (Jazzy 0.2.0 to 0.2.3).
    LABELLED = "labelled"


@dataclass(frozen=True, slots=True)
class ZenohSettings:
    """The Zenoh session (``bridge.zenoh``).

    :param mode: peer or client.
    :param listen: endpoints to listen on, e.g. ``("tcp/127.0.0.1:7447",)``; none by default.
    :param connect: endpoints to connect to (a router, or another peer).
    :param multicast_scouting: whether to find peers by UDP multicast (off by default).
    :param lease_s: the gateway's own lease: how long its peers keep a silent gateway (and its
        liveliness tokens) alive.  A frozen commander is dropped after *its* lease, which its
        own Zenoh configuration sets (Zenoh checks each peer against the lease that peer
        announced).
    """

    mode: ZenohMode = ZenohMode.PEER
    listen: tuple[str, ...] = ()
    connect: tuple[str, ...] = ()
    multicast_scouting: bool = False
    lease_s: float = 10.0


@dataclass(frozen=True, slots=True)
class Ros2Settings:
    """ROS 2 over rmw_zenoh (``bridge.ros2``).

    :param domain_id: ``ROS_DOMAIN_ID`` of the ROS 2 machines.
    :param cmd_vel: the topic twists come in on (``Twist`` or ``TwistStamped``).
    :param odom: the topic ``nav_msgs/msg/Odometry`` goes out on.
    :param tf: whether to publish the odom -> base_link transform on ``/tf``.
    :param odom_frame: the odometry's frame id.
    :param base_frame: the robot's frame id (``child_frame_id``).
    :param node_name: the ROS node name the bridge's endpoints belong to.
    :param attachment: the attachment layout the bridge's publishers write (what the ROS
        machines' rmw_zenoh reads: ``LABELLED`` for Jazzy's 0.2.0 to 0.2.3); incoming samples
        may carry either.
    :param joint_states: the topic ``sensor_msgs/msg/JointState`` of the wheels and steering
        actuators goes out on ('': none).
    :param joints: ``(wheel or actuator name, joint name)`` pairs: the joint names the joint
        states carry (a URDF's); a wheel or actuator not named here is its own joint name.
    :param services: whether the node offers ``std_srvs/srv/Trigger`` services ``~/estop``,
        ``~/enable`` and ``~/disable`` (the control socket's requests, from the bridge).
    :param pose_covariance_diagonal: the variances of the odometry's pose (x, y, z, rotation
        about x, y, z; m^2, rad^2), its covariance's diagonal (zeros: not estimated), as
        ros2_control's ``diff_drive_controller`` sets them; ``robot_localization`` needs them
        to weigh the wheels against an IMU.
    :param twist_covariance_diagonal: the same for the odometry's twist ((m/s)^2, (rad/s)^2).
    :param diagnostics: the topic ``diagnostic_msgs/msg/DiagnosticArray`` goes out on ('':
        none; ``/diagnostics`` is where ROS's diagnostic tools look).
    """

    domain_id: int = 0
    cmd_vel: str = "cmd_vel"
    odom: str = "odom"
    tf: bool = True
    odom_frame: str = "odom"
    base_frame: str = "base_link"
    node_name: str = "wheelgate"
    attachment: AttachmentFormat = AttachmentFormat.POSITIONAL
    joint_states: str = ""
    joints: tuple[tuple[str, str], ...] = ()
    services: bool = False
    pose_covariance_diagonal: tuple[float, ...] = (0.0,) * 6
    twist_covariance_diagonal: tuple[float, ...] = (0.0,) * 6
    diagnostics: str = ""


@dataclass(frozen=True, slots=True)
class BridgeSettings:
    """The ``bridge:`` block.

    :param zenoh: the session.
    :param namespace: the robot's namespace: ``wheelgate/<namespace>/...`` for the native
        keys (the robot's ``name`` when not given) and the ROS 2 namespace of its topics
        (none when not given).
    :param ros2: ROS 2 topics, or ``None`` for the native keys only.
    :param deadman: what a lost commander does to the robot.
    """

    zenoh: ZenohSettings
    namespace: str
    ros2: Ros2Settings | None = None
    deadman: DeadmanAction = DeadmanAction.STOP
    #: Whether ``namespace`` was given (it then namespaces the ROS 2 topics too).
    ros_namespace: str = ""


@dataclass(frozen=True, slots=True)
class FoxgloveSettings:
    """The ``foxglove:`` block: a live view for the Foxglove app.

    :param host: the address the WebSocket server listens on.
    :param port: its port (0: any free one, logged at start).
    :param mcap: a file the same channels are recorded to ('' for none).
    """

    host: str = "127.0.0.1"
    port: int = 8765
    mcap: str = ""
