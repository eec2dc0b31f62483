"""The RIHS01 type hashes, recomputed from the ``.msg`` definitions (REP 2011, ros2/rosidl).

The definitions below are the upstream ``.msg`` files as published (comments and default values
kept, which the rule must ignore), written here independently of the module's copies.  Every
recomputed hash must equal the published constant, and two more published hashes (from
rmw_zenoh's ``docs/design.md`` and the ``builtin_interfaces`` package) check the rule on types
the module does not carry.
"""

from __future__ import annotations

import json

import pytest

from gateway.core.errors import DecodeError
from gateway.wire.ros2 import (
    MESSAGE_DEFINITIONS,
    ODOMETRY,
    ROS_TYPES,
    TF_MESSAGE,
    TWIST,
    TWIST_STAMPED,
    RosType,
    compute_type_hash,
    dds_type_name,
)
from gateway.wire.ros2.typehash import FieldDescription, canonical_json, parse_msg

#: The upstream ``.msg`` files, comments and defaults included.
UPSTREAM = {
    "builtin_interfaces/msg/Time": """
# This message communicates ROS Time defined here:
# https://design.ros2.org/articles/clock_and_time.html

# The seconds component, valid over all int32 values.
int32 sec

# The nanoseconds component, valid in the range [0, 1e9), to be added to the seconds component.
uint32 nanosec
""",
    "std_msgs/msg/Header": """
# Standard metadata for higher-level stamped data types.
# Two-integer timestamp that is expressed as seconds and nanoseconds.
builtin_interfaces/Time stamp

# Transform frame with which this data is associated.
string frame_id
""",
    "geometry_msgs/msg/Vector3": "# This represents a vector in free space.\n"
                                 "float64 x\nfloat64 y\nfloat64 z\n",
    "geometry_msgs/msg/Point": "# This contains the position of a point in free space\n"
                               "float64 x\nfloat64 y\nfloat64 z\n",
    "geometry_msgs/msg/Quaternion": "# This represents an orientation in free space in "
                                    "quaternion form.\n\nfloat64 x 0\nfloat64 y 0\n"
                                    "float64 z 0\nfloat64 w 1\n",
    "geometry_msgs/msg/Pose": "# A representation of pose in free space.\n"
                              "Point position\nQuaternion orientation\n",
    "geometry_msgs/msg/PoseWithCovariance": "Pose pose\n\n# Row-major representation of the "
                                            "6x6 covariance matrix\nfloat64[36] covariance\n",
    "geometry_msgs/msg/Twist": "# This expresses velocity in free space broken into its "
                               "linear and angular parts.\n\nVector3  linear\nVector3  angular\n",
    "geometry_msgs/msg/TwistStamped": "# A twist with reference coordinate frame and "
                                      "timestamp\n\nstd_msgs/Header header\nTwist twist\n",
    "geometry_msgs/msg/TwistWithCovariance": "Twist twist\n\nfloat64[36] covariance\n",
    "geometry_msgs/msg/Transform": "Vector3 translation\nQuaternion rotation\n",
    "geometry_msgs/msg/TransformStamped": "std_msgs/Header header\n\n# The frame id of the "
                                          "child frame to which this transform points.\n"
                                          "string child_frame_id\n\nTransform transform\n",
    "nav_msgs/msg/Odometry": """
# This represents an estimate of a position and velocity in free space.
# Includes the frame id of the pose parent.
std_msgs/Header header

# Frame id the pose points to. The twist is in this coordinate frame.
string child_frame_id

# Estimated pose that is typically relative to a fixed world frame.
geometry_msgs/PoseWithCovariance pose

# Estimated linear and angular velocity relative to child_frame_id.
geometry_msgs/TwistWithCovariance twist
""",
    "tf2_msgs/msg/TFMessage": "geometry_msgs/TransformStamped[] transforms\n",
    "sensor_msgs/msg/JointState": "std_msgs/Header header\n\nstring[] name\n\nfloat64[] "
                                  "position\nfloat64[] velocity\nfloat64[] effort\n",
    # service_msgs/msg/ServiceEventInfo.msg with its constants, and std_srvs/srv/Trigger.srv
    # as rosidl splits it (the empty request gets rosidl's placeholder member).
    "service_msgs/msg/ServiceEventInfo": (
        "uint8 REQUEST_SENT = 0\nuint8 REQUEST_RECEIVED = 1\nuint8 RESPONSE_SENT = 2\n"
        "uint8 RESPONSE_RECEIVED = 3\n\n# The type of event this message represents\n"
        "uint8 event_type\n\nbuiltin_interfaces/Time stamp\n\nchar[16] client_gid\n\n"
        "int64 sequence_number\n"),
    "std_srvs/srv/Trigger_Request": "uint8 structure_needs_at_least_one_member\n",
    # diagnostic_msgs' three messages, constants included (``byte``: its own type id).
    "diagnostic_msgs/msg/KeyValue": "# What to label this value when viewing.\nstring key\n"
                                    "# A value to track over time.\nstring value\n",
    "diagnostic_msgs/msg/DiagnosticStatus": (
        "# This message holds the status of an individual component of the robot.\n\n"
        "# Possible levels of operations.\nbyte OK=0\nbyte WARN=1\nbyte ERROR=2\n"
        "byte STALE=3\n\n# Level of operation enumerated above.\nbyte level\n"
        "# A description of the test/component reporting.\nstring name\n"
        "# A description of the status.\nstring message\n"
        "# A hardware unique string.\nstring hardware_id\n"
        "# An array of values associated with the status.\nKeyValue[] values\n"),
    "diagnostic_msgs/msg/DiagnosticArray": (
        "# This message is used to send diagnostic information about the state of the robot."
        "\nstd_msgs/Header header # for timestamp\n"
        "DiagnosticStatus[] status # an array of components being reported on\n"),
    "std_srvs/srv/Trigger_Response": "bool success   # indicate successful run of triggered "
                                     "service\nstring message # informational, e.g. for error "
                                     "messages\n",
    "std_srvs/srv/Trigger_Event": (
        "service_msgs/ServiceEventInfo info\nstd_srvs/srv/Trigger_Request[<=1] request\n"
        "std_srvs/srv/Trigger_Response[<=1] response\n"),
    "std_srvs/srv/Trigger": (
        "std_srvs/srv/Trigger_Request request_message\n"
        "std_srvs/srv/Trigger_Response response_message\n"
        "std_srvs/srv/Trigger_Event event_message\n"),
}

PUBLISHED = {
    "geometry_msgs/msg/Twist":
        "RIHS01_9c45bf16fe0983d80e3cfe750d6835843d265a9a6c46bd2e609fcddde6fb8d2a",
    "nav_msgs/msg/Odometry":
        "RIHS01_3cc97dc7fb7502f8714462c526d369e35b603cfc34d946e3f2eda2766dfec6e0",
    "geometry_msgs/msg/TwistStamped":
        "RIHS01_5f0fcd4f81d5d06ad9b4c4c63e3ea51b82d6ae4d0558f1d475229b1121db6f64",
    "tf2_msgs/msg/TFMessage":
        "RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087",
    # (``ros2 topic info /joint_states --verbose`` prints it)
    "sensor_msgs/msg/JointState":
        "RIHS01_a13ee3a330e346c9d87b5aa18d24e11690752bd33a0350f11c5882bc9179260e",
    # (a service's hash is the service type's: the key of its queryable carries it)
    "std_srvs/srv/Trigger":
        "RIHS01_eeff2cd6fa5ad9d27cdf4dec64818317839b62f212a91e6b5304b634b2062c5f",
    # (Jazzy's, as copper-project/copper-rs lists them: components/payloads/cu_ros2_payloads/
    # all_rihs.md; its DiagnosticStatus and KeyValue are checked below)
    "diagnostic_msgs/msg/DiagnosticArray":
        "RIHS01_5a8a36efb05fb25070fa0fb3810290c0e6cd4862b54a8fb975a1ee8dc55a333e",
}


def test_every_type_of_the_module_is_checked_here() -> None:
    assert set(ROS_TYPES) == set(PUBLISHED)


@pytest.mark.parametrize("name", sorted(PUBLISHED))
def test_the_published_hashes_are_recomputed_from_upstream_definitions(name: str) -> None:
    assert compute_type_hash(name, UPSTREAM) == PUBLISHED[name]


@pytest.mark.parametrize("name", sorted(PUBLISHED))
def test_the_module_constants_are_the_published_hashes_and_its_definitions_agree(
        name: str) -> None:
    assert ROS_TYPES[name].type_hash == PUBLISHED[name]
    assert compute_type_hash(name) == PUBLISHED[name]
    assert canonical_json(name, UPSTREAM) == canonical_json(name, MESSAGE_DEFINITIONS)


def test_other_published_hashes_are_recomputed() -> None:
    """``std_msgs/msg/String`` from rmw_zenoh's design.md, ``Time`` from builtin_interfaces."""
    assert compute_type_hash("std_msgs/msg/String", {"std_msgs/msg/String": "string data\n"}) \
        == "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"
    assert compute_type_hash("builtin_interfaces/msg/Time", UPSTREAM) \
        == "RIHS01_b106235e25a4c5ed35098aa0a61a3ee9c9b18d197f398b0e4206cea9acf9c197"
    # A service's parts have hashes of their own (Trigger's empty request with rosidl's
    # placeholder member; std_srvs/srv/SetBool's whole service).
    assert compute_type_hash("std_srvs/srv/Trigger_Request", UPSTREAM) \
        == "RIHS01_d010825374ce8918e72bfd826c82603e60f45419e932ea976f807b74a863a199"
    set_bool = {**UPSTREAM, **{
        f"std_srvs/srv/SetBool{part}": text.replace("Trigger", "SetBool")
        for part, text in (("_Request", "bool data\n"),
                           ("_Response", UPSTREAM["std_srvs/srv/Trigger_Response"]),
                           ("_Event", UPSTREAM["std_srvs/srv/Trigger_Event"]),
                           ("", UPSTREAM["std_srvs/srv/Trigger"]))}}
    assert compute_type_hash("std_srvs/srv/SetBool", set_bool) \
        == "RIHS01_abe9e4bb6b41b40e6789712c00ec8871923e089af3f667a79992a428cff2da0a"
    # DiagnosticArray's parts, and a ``byte`` that is not a ``uint8`` (example_interfaces'
    # Byte, ``byte data``), as the same list has them.
    assert compute_type_hash("diagnostic_msgs/msg/DiagnosticStatus", UPSTREAM) \
        == "RIHS01_b0e3e692ea2d54a8af2f4ef1930e81556a2db55216b771f8a7d2724ed47bf0e4"
    assert compute_type_hash("diagnostic_msgs/msg/KeyValue", UPSTREAM) \
        == "RIHS01_d68081eaa540288c5440753baecef0c4e16e81a5f78ad68902ded5100413bb42"
    assert compute_type_hash("example_interfaces/msg/Byte", {
        "example_interfaces/msg/Byte": "byte data\n"}) \
        == "RIHS01_f014e0424be54b8ba7c35490aea4198be92df1de4e88f4e19a2fbbce2e020bb9"


def test_the_hashed_text_is_exactly_rosidls_json() -> None:
    text = canonical_json("builtin_interfaces/msg/Time")
    assert text == (
        '{"type_description": {"type_name": "builtin_interfaces/msg/Time", "fields": ['
        '{"name": "sec", "type": {"type_id": 6, "capacity": 0, "string_capacity": 0, '
        '"nested_type_name": ""}}, '
        '{"name": "nanosec", "type": {"type_id": 7, "capacity": 0, "string_capacity": 0, '
        '"nested_type_name": ""}}]}, "referenced_type_descriptions": []}'
    )


def test_referenced_types_are_complete_and_sorted_by_name() -> None:
    description = json.loads(canonical_json("nav_msgs/msg/Odometry"))
    names = [t["type_name"] for t in description["referenced_type_descriptions"]]
    assert names == sorted(names) == [
        "builtin_interfaces/msg/Time", "geometry_msgs/msg/Point", "geometry_msgs/msg/Pose",
        "geometry_msgs/msg/PoseWithCovariance", "geometry_msgs/msg/Quaternion",
        "geometry_msgs/msg/Twist", "geometry_msgs/msg/TwistWithCovariance",
        "geometry_msgs/msg/Vector3", "std_msgs/msg/Header",
    ]


def test_a_changed_definition_changes_the_hash() -> None:
    changed = dict(UPSTREAM, **{"geometry_msgs/msg/Vector3": "float64 x\nfloat64 y\n"})
    assert compute_type_hash("geometry_msgs/msg/Twist", changed) != PUBLISHED[
        "geometry_msgs/msg/Twist"]


def test_parse_msg_covers_arrays_sequences_bounds_and_constants() -> None:
    fields = parse_msg("pkg/msg/T", """
        int32 LIMIT=5            # a constant
        string NAME = "x"
        uint8[4] fixed
        string<=8[<=3] names "a=b"
        char c
        byte b
        Other[] others
        other_pkg/Thing thing
        float32[<=10] samples
    """)
    assert fields == (
        FieldDescription("fixed", 3 + 48, 4),
        FieldDescription("names", 21 + 96, 3, 8),
        FieldDescription("c", 3),
        FieldDescription("b", 16),
        FieldDescription("others", 1 + 144, 0, 0, "pkg/msg/Other"),
        FieldDescription("thing", 1, 0, 0, "other_pkg/msg/Thing"),
        FieldDescription("samples", 10 + 96, 10),
    )


@pytest.mark.parametrize(("text", "error"), [
    ("float64", r"^a/msg/B line 1: expected '<type> <field name>', got 'float64'$"),
    ("float64 X", r"^a/msg/B line 1: expected '<type> <field name>', got 'float64' 'X'$"),
    ("int32<=3 x", r"^a/msg/B line 1: expected a bound on a string, got 'int32<=3'$"),
    ("int32[<=] x", r"expected a sequence bound, got 'int32\[<=\]'$"),
    ("9bad x", r"expected '<type> <field name>'"),
])
def test_parse_msg_refuses_malformed_lines(text: str, error: str) -> None:
    with pytest.raises(DecodeError, match=error):
        parse_msg("a/msg/B", text)


def test_a_missing_referenced_definition_is_named() -> None:
    with pytest.raises(DecodeError, match=r"^geometry_msgs/msg/Twist: expected a definition "
                                          r"of geometry_msgs/msg/Vector3, got none among"):
        compute_type_hash("geometry_msgs/msg/Twist", {"geometry_msgs/msg/Twist": "Vector3 a\n"})


@pytest.mark.parametrize(("ros_type", "dds"), [
    (TWIST, "geometry_msgs::msg::dds_::Twist_"),
    (TWIST_STAMPED, "geometry_msgs::msg::dds_::TwistStamped_"),
    (ODOMETRY, "nav_msgs::msg::dds_::Odometry_"),
    (TF_MESSAGE, "tf2_msgs::msg::dds_::TFMessage_"),
])
def test_dds_type_names(ros_type: RosType, dds: str) -> None:
    assert ros_type.dds_name == dds
    assert dds_type_name(ros_type.ros_name) == dds
