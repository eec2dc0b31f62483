"""The ROS 2 message types the bridge uses, as data: names, DDS names, type hashes, definitions.

A type hash (RIHS01, REP 2011) identifies a message definition; rmw_zenoh puts it in every data
key and liveliness token, so a subscriber only meets publishers of the identical definition.
The seven hashes below are the published ones (Jazzy and later; the definitions have not
changed since; ``diagnostic_msgs/msg/DiagnosticArray``'s as the public repository
copper-project/copper-rs lists Jazzy's, ``components/payloads/cu_ros2_payloads/all_rihs.md``);
:func:`gateway.wire.ros2.typehash.compute_type_hash` recomputes each of them from
:data:`MESSAGE_DEFINITIONS`, and ``tests/wire/test_ros2_types.py`` checks that they agree.

:data:`MESSAGE_DEFINITIONS` holds the ``.msg`` text of every type involved (comments and
constants dropped): from the public repositories ros2/common_interfaces (``diagnostic_msgs``,
``geometry_msgs``, ``nav_msgs``, ``sensor_msgs``, ``std_msgs``, ``std_srvs``), ros2/geometry2
(``tf2_msgs/msg/TFMessage.msg``) and ros2/rcl_interfaces (``builtin_interfaces/msg/Time.msg``).
"""

from __future__ import annotations

from dataclasses import dataclass
from types import MappingProxyType
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from collections.abc import Mapping

#: Prefix of a RIHS01 type hash string (REP 2011).
RIHS01_PREFIX = "RIHS01_"


def dds_type_name(ros_name: str) -> str:
    """The DDS name of a ROS type (rmw_zenoh keys use it): ``pkg/msg/N`` -> ``pkg::msg::dds_::N_``.

    >>> dds_type_name("geometry_msgs/msg/Twist")
    'geometry_msgs::msg::dds_::Twist_'
    """
    package, kind, name = ros_name.split("/")
    return f"{package}::{kind}::dds_::{name}_"


@dataclass(frozen=True, slots=True)
class RosType:
    """One ROS 2 message type.

    :param ros_name: the full ROS name, ``geometry_msgs/msg/Twist``.
    :param type_hash: its RIHS01 hash string, ``RIHS01_`` and 64 hex digits.
    """

    ros_name: str
    type_hash: str

    @property
    def dds_name(self) -> str:
        """The DDS type name, ``geometry_msgs::msg::dds_::Twist_``."""
        return dds_type_name(self.ros_name)


TWIST = RosType(
    "geometry_msgs/msg/Twist",
    "RIHS01_9c45bf16fe0983d80e3cfe750d6835843d265a9a6c46bd2e609fcddde6fb8d2a",
)
TWIST_STAMPED = RosType(
    "geometry_msgs/msg/TwistStamped",
    "RIHS01_5f0fcd4f81d5d06ad9b4c4c63e3ea51b82d6ae4d0558f1d475229b1121db6f64",
)
ODOMETRY = RosType(
    "nav_msgs/msg/Odometry",
    "RIHS01_3cc97dc7fb7502f8714462c526d369e35b603cfc34d946e3f2eda2766dfec6e0",
)
TF_MESSAGE = RosType(
    "tf2_msgs/msg/TFMessage",
    "RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087",
)
JOINT_STATE = RosType(
    "sensor_msgs/msg/JointState",
    "RIHS01_a13ee3a330e346c9d87b5aa18d24e11690752bd33a0350f11c5882bc9179260e",
)
#: A service: its hash is the service type's, its DDS name the service's
#: (``std_srvs::srv::dds_::Trigger_``: rmw_zenoh strips the response type's ``Response_``).
TRIGGER = RosType(
    "std_srvs/srv/Trigger",
    "RIHS01_eeff2cd6fa5ad9d27cdf4dec64818317839b62f212a91e6b5304b634b2062c5f",
)
DIAGNOSTIC_ARRAY = RosType(
    "diagnostic_msgs/msg/DiagnosticArray",
    "RIHS01_5a8a36efb05fb25070fa0fb3810290c0e6cd4862b54a8fb975a1ee8dc55a333e",
)
#: The seven types, by ROS name.
ROS_TYPES: Mapping[str, RosType] = MappingProxyType(
    {t.ros_name: t for t in (TWIST, TWIST_STAMPED, ODOMETRY, TF_MESSAGE, JOINT_STATE, TRIGGER,
                             DIAGNOSTIC_ARRAY)}
)

#: ``.msg`` text of the seven types and of every type they reference, by ROS name.
MESSAGE_DEFINITIONS: Mapping[str, str] = MappingProxyType({
    "builtin_interfaces/msg/Time": "int32 sec\nuint32 nanosec\n",
    "std_msgs/msg/Header": "builtin_interfaces/Time stamp\nstring frame_id\n",
    "geometry_msgs/msg/Vector3": "float64 x\nfloat64 y\nfloat64 z\n",
    "geometry_msgs/msg/Point": "float64 x\nfloat64 y\nfloat64 z\n",
    "geometry_msgs/msg/Quaternion": "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n",
    "geometry_msgs/msg/Pose": "Point position\nQuaternion orientation\n",
    "geometry_msgs/msg/PoseWithCovariance": "Pose pose\nfloat64[36] covariance\n",
    "geometry_msgs/msg/Twist": "Vector3 linear\nVector3 angular\n",
    "geometry_msgs/msg/TwistStamped": "std_msgs/Header header\nTwist twist\n",
    "geometry_msgs/msg/TwistWithCovariance": "Twist twist\nfloat64[36] covariance\n",
    "geometry_msgs/msg/Transform": "Vector3 translation\nQuaternion rotation\n",
    "geometry_msgs/msg/TransformStamped":
        "std_msgs/Header header\nstring child_frame_id\nTransform transform\n",
    "nav_msgs/msg/Odometry": (
        "std_msgs/Header header\nstring child_frame_id\n"
        "geometry_msgs/PoseWithCovariance pose\ngeometry_msgs/TwistWithCovariance twist\n"
    ),
    "tf2_msgs/msg/TFMessage": "geometry_msgs/TransformStamped[] transforms\n",
    "sensor_msgs/msg/JointState": (
        "std_msgs/Header header\nstring[] name\nfloat64[] position\nfloat64[] velocity\n"
        "float64[] effort\n"
    ),
    # A service as rosidl describes it (rosidl_generator_type_description ``add_srv``): its
    # request, response and introspection event; an empty struct (Trigger's request) gets
    # rosidl's placeholder member, as std_msgs/msg/Empty's generated description shows.
    "service_msgs/msg/ServiceEventInfo": (
        "uint8 event_type\nbuiltin_interfaces/Time stamp\nchar[16] client_gid\n"
        "int64 sequence_number\n"
    ),
    "std_srvs/srv/Trigger_Request": "uint8 structure_needs_at_least_one_member\n",
    "std_srvs/srv/Trigger_Response": "bool success\nstring message\n",
    "std_srvs/srv/Trigger_Event": (
        "service_msgs/ServiceEventInfo info\nstd_srvs/srv/Trigger_Request[<=1] request\n"
        "std_srvs/srv/Trigger_Response[<=1] response\n"
    ),
    "std_srvs/srv/Trigger": (
        "std_srvs/srv/Trigger_Request request_message\n"
        "std_srvs/srv/Trigger_Response response_message\n"
        "std_srvs/srv/Trigger_Event event_message\n"
    ),
    "diagnostic_msgs/msg/KeyValue": "string key\nstring value\n",
    "diagnostic_msgs/msg/DiagnosticStatus": (
        "byte level\nstring name\nstring message\nstring hardware_id\nKeyValue[] values\n"
    ),
    "diagnostic_msgs/msg/DiagnosticArray": "std_msgs/Header header\nDiagnosticStatus[] status\n",
})
