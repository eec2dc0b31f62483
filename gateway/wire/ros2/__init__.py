"""ROS 2 on the wire as rmw_zenoh carries it, without ROS: a pure layer, no I/O, no clock.

What a Zenoh bridge needs to exchange messages with ROS 2 nodes that run rmw_zenoh (the
public repository ros2/rmw_zenoh, Jazzy and later):

* :mod:`gateway.wire.ros2.cdr`: XCDR1 little-endian codecs of ``geometry_msgs/msg/Twist``,
  ``TwistStamped``, ``nav_msgs/msg/Odometry``, ``tf2_msgs/msg/TFMessage``,
  ``sensor_msgs/msg/JointState`` and the service ``std_srvs/srv/Trigger``
  (:mod:`~gateway.wire.ros2.cdr_stream` has the reader and writer,
  :mod:`~gateway.wire.ros2.messages` the dataclasses and the stamp helpers);
  :mod:`gateway.wire.ros2.diagnostics`: ``diagnostic_msgs/msg/DiagnosticArray`` and its codec;
* :mod:`gateway.wire.ros2.types`: the types' names, DDS names, RIHS01 hashes and ``.msg``
  definitions; :mod:`~gateway.wire.ros2.typehash` recomputes a hash (REP 2011);
* :mod:`gateway.wire.ros2.attachment`: the attachment every sample carries (sequence number,
  timestamp, publisher GID);
* :mod:`gateway.wire.ros2.names`: ROS name validation and resolution;
* :mod:`gateway.wire.ros2.keys`: data keys, liveliness tokens and entity GIDs
  (:mod:`~gateway.wire.ros2.qos` has the QoS chunk, :mod:`~gateway.wire.ros2.xxh3` the hash).

Decoders raise :class:`~gateway.core.errors.DecodeError` only, encoders
:class:`~gateway.core.errors.EncodeError`, name checks :class:`~gateway.core.errors.ConfigError`.
"""

from __future__ import annotations

from gateway.core.bridge_settings import AttachmentFormat
from gateway.wire.ros2.attachment import (
    ATTACHMENT_SIZE,
    GID_SIZE,
    Attachment,
    decode_attachment,
    encode_attachment,
)
from gateway.wire.ros2.cdr import (
    TWIST_SIZE,
    decode_joint_state,
    decode_odometry,
    decode_tf_message,
    decode_trigger_request,
    decode_trigger_response,
    decode_twist,
    decode_twist_stamped,
    encode_joint_state,
    encode_odometry,
    encode_tf_message,
    encode_trigger_request,
    encode_trigger_response,
    encode_twist,
    encode_twist_stamped,
)
from gateway.wire.ros2.diagnostics import (
    DiagnosticArray,
    DiagnosticLevel,
    DiagnosticStatus,
    KeyValue,
    decode_diagnostic_array,
    encode_diagnostic_array,
)
from gateway.wire.ros2.keys import (
    ADMIN_SPACE,
    HUMBLE_TYPE_HASH,
    EntityKind,
    LivelinessToken,
    entity_token,
    gid_of,
    node_token,
    parse_token,
    topic_key,
    topic_subscription_key,
)
from gateway.wire.ros2.messages import (
    COVARIANCE_SIZE,
    ZERO_COVARIANCE,
    Header,
    JointState,
    Odometry,
    Quaternion,
    TFMessage,
    Time,
    TransformStamped,
    TriggerResponse,
    Twist3D,
    TwistStamped,
    Vector3,
    ns_to_stamp,
    stamp_to_ns,
)
from gateway.wire.ros2.names import (
    resolve_topic_name,
    validate_full_topic_name,
    validate_namespace,
    validate_node_name,
    validate_topic_name,
)
from gateway.wire.ros2.qos import (
    DEFAULT_DEPTH,
    Durability,
    History,
    QosProfile,
    Reliability,
    parse_qos_chunk,
    qos_chunk,
)
from gateway.wire.ros2.typehash import compute_type_hash
from gateway.wire.ros2.types import (
    DIAGNOSTIC_ARRAY,
    JOINT_STATE,
    MESSAGE_DEFINITIONS,
    ODOMETRY,
    ROS_TYPES,
    TF_MESSAGE,
    TRIGGER,
    TWIST,
    TWIST_STAMPED,
    RosType,
    dds_type_name,
)

__all__ = [
    "ADMIN_SPACE",
    "ATTACHMENT_SIZE",
    "COVARIANCE_SIZE",
    "DEFAULT_DEPTH",
    "DIAGNOSTIC_ARRAY",
    "GID_SIZE",
    "HUMBLE_TYPE_HASH",
    "JOINT_STATE",
    "MESSAGE_DEFINITIONS",
    "ODOMETRY",
    "ROS_TYPES",
    "TF_MESSAGE",
    "TRIGGER",
    "TWIST",
    "TWIST_SIZE",
    "TWIST_STAMPED",
    "ZERO_COVARIANCE",
    "Attachment",
    "AttachmentFormat",
    "DiagnosticArray",
    "DiagnosticLevel",
    "DiagnosticStatus",
    "Durability",
    "EntityKind",
    "Header",
    "History",
    "JointState",
    "KeyValue",
    "LivelinessToken",
    "Odometry",
    "QosProfile",
    "Quaternion",
    "Reliability",
    "RosType",
    "TFMessage",
    "Time",
    "TransformStamped",
    "TriggerResponse",
    "Twist3D",
    "TwistStamped",
    "Vector3",
    "compute_type_hash",
    "dds_type_name",
    "decode_attachment",
    "decode_diagnostic_array",
    "decode_joint_state",
    "decode_odometry",
    "decode_tf_message",
    "decode_trigger_request",
    "decode_trigger_response",
    "decode_twist",
    "decode_twist_stamped",
    "encode_attachment",
    "encode_diagnostic_array",
    "encode_joint_state",
    "encode_odometry",
    "encode_tf_message",
    "encode_trigger_request",
    "encode_trigger_response",
    "encode_twist",
    "encode_twist_stamped",
    "entity_token",
    "gid_of",
    "node_token",
    "ns_to_stamp",
    "parse_qos_chunk",
    "parse_token",
    "qos_chunk",
    "resolve_topic_name",
    "stamp_to_ns",
    "topic_key",
    "topic_subscription_key",
    "validate_full_topic_name",
    "validate_namespace",
    "validate_node_name",
    "validate_topic_name",
]
