"""Hand-written XCDR1 little-endian codecs of the messages the bridge exchanges.

====================================  =========================================================
message                               body layout (offsets from the end of the 4-byte header)
====================================  =========================================================
``geometry_msgs/msg/Twist``           6 x f64: linear xyz, angular xyz (48 bytes; 52 in all)
``geometry_msgs/msg/TwistStamped``    header (i32 sec, u32 nanosec, string frame_id), pad to
                                      8, 6 x f64
``nav_msgs/msg/Odometry``             header, string child_frame_id, pad to 8, 7 x f64 pose
                                      (position xyz, orientation xyzw), 36 x f64 covariance,
                                      6 x f64 twist, 36 x f64 covariance
``tf2_msgs/msg/TFMessage``            u32 count, then per transform: header, string
                                      child_frame_id, pad to 8, 7 x f64 (translation xyz,
                                      rotation xyzw)
``sensor_msgs/msg/JointState``        header, u32 count and the strings of name, then each of
                                      position, velocity, effort: u32 count, pad to 8 (when
                                      not empty), count x f64
``std_srvs/srv/Trigger`` request      u8 ``structure_needs_at_least_one_member`` (an empty
                                      struct's placeholder; 5 bytes in all)
``std_srvs/srv/Trigger`` response     bool success (u8), pad to 4, string message
====================================  =========================================================

Field order comes from the ``.msg`` files (ros2/common_interfaces, ros2/geometry2), the
layout rules from :mod:`gateway.wire.ros2.cdr_stream`.  ``tests/wire/test_ros2_cdr*.py`` check
every codec byte for byte against pycdr2 (eclipse-cyclonedds/cyclonedds-python), an
independent implementation.

Decoders raise :class:`~gateway.core.errors.DecodeError` and nothing else for any input;
they return non-finite numbers as they came (the caller validates).  Encoders raise
:class:`~gateway.core.errors.EncodeError` for what cannot go on the wire (a ``sec`` outside
``int32``, ``nanosec`` outside ``[0, 1e9)``, a non-number, a covariance of other than 36
entries, a string with a NUL).  Pure: no I/O, no clock.
"""

from __future__ import annotations

import struct

from gateway.core.errors import DecodeError, EncodeError
from gateway.wire.ros2.cdr_stream import (
    HEADER_SIZE,
    CdrReader,
    CdrWriter,
    Payload,
    as_bytes,
    check_header,
)
from gateway.wire.ros2.messages import (
    COVARIANCE_SIZE,
    NS_PER_S,
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
)

TWIST = "geometry_msgs/msg/Twist"
TWIST_STAMPED = "geometry_msgs/msg/TwistStamped"
ODOMETRY = "nav_msgs/msg/Odometry"
TF_MESSAGE = "tf2_msgs/msg/TFMessage"
JOINT_STATE = "sensor_msgs/msg/JointState"
TRIGGER_REQUEST = "std_srvs/srv/Trigger_Request"
TRIGGER_RESPONSE = "std_srvs/srv/Trigger_Response"

_SIX = struct.Struct("<6d")
_POSE = struct.Struct("<7d")
_COVARIANCE = struct.Struct(f"<{COVARIANCE_SIZE}d")
_TWIST_MESSAGE = struct.Struct("<4s6d")
#: Size of a whole ``geometry_msgs/msg/Twist`` payload, header included.
TWIST_SIZE = _TWIST_MESSAGE.size
#: The fewest body bytes one ``TransformStamped`` takes (empty frame names, no padding).
_MIN_TRANSFORM_BYTES = 4 + 4 + 4 + 1 + 4 + 1 + _POSE.size


# ----------------------------------------------------------------------------- shared parts


def write_header(w: CdrWriter, header: object, field: str) -> None:
    """A ``std_msgs/msg/Header`` (stamp, frame id) at ``field``."""
    if not isinstance(header, Header) or not isinstance(header.stamp, Time):
        raise EncodeError(f"{w.type_name}: expected a Header for {field}, got {header!r}")
    w.int32(header.stamp.sec, f"{field}.stamp.sec")
    w.uint32(header.stamp.nanosec, f"{field}.stamp.nanosec", NS_PER_S - 1)
    w.string(header.frame_id, f"{field}.frame_id")


def read_header(r: CdrReader, field: str) -> Header:
    """The ``std_msgs/msg/Header`` at ``field``."""
    sec = r.int32(f"{field}.stamp.sec")
    nanosec = r.uint32(f"{field}.stamp.nanosec")
    return Header(Time(sec, nanosec), r.string(f"{field}.frame_id"))


def _twist_values(type_name: str, twist: object, field: str) -> tuple[object, ...]:
    if not isinstance(twist, Twist3D):
        raise EncodeError(f"{type_name}: expected a Twist3D for {field}, got {twist!r}")
    return (twist.linear_x, twist.linear_y, twist.linear_z,
            twist.angular_x, twist.angular_y, twist.angular_z)


def _pose_values(type_name: str, position: object, orientation: object,
                 field: str) -> tuple[object, ...]:
    if not isinstance(position, Vector3) or not isinstance(orientation, Quaternion):
        raise EncodeError(
            f"{type_name}: expected a Vector3 and a Quaternion for {field}, "
            f"got {position!r} and {orientation!r}"
        )
    return (position.x, position.y, position.z,
            orientation.x, orientation.y, orientation.z, orientation.w)


def _covariance(type_name: str, values: object, field: str) -> tuple[object, ...]:
    if isinstance(values, (str, bytes)) or not hasattr(values, "__iter__"):
        raise EncodeError(
            f"{type_name}: expected {COVARIANCE_SIZE} numbers for {field}, got {values!r}"
        )
    return tuple(values)


def _read_pose(r: CdrReader, field: str) -> tuple[Vector3, Quaternion]:
    x, y, z, qx, qy, qz, qw = r.float64s(_POSE, field)
    return Vector3(x, y, z), Quaternion(qx, qy, qz, qw)


# ----------------------------------------------------------------------------- Twist


def encode_twist(twist: Twist3D) -> bytes:
    """The 52-byte ``geometry_msgs/msg/Twist`` payload of ``twist``.

    >>> encode_twist(Twist3D(linear_x=1.0)).hex()[:24]
    '00010000000000000000f03f'
    """
    w = CdrWriter(TWIST)
    w.float64s(_SIX, _twist_values(TWIST, twist, "twist"), "twist")
    return w.payload()


def decode_twist(payload: Payload) -> Twist3D:
    """The :class:`Twist3D` in a ``geometry_msgs/msg/Twist`` payload.

    :raises DecodeError: not exactly 52 bytes, or not little-endian CDR.
    """
    data = as_bytes(TWIST, payload)
    if len(data) != TWIST_SIZE:
        raise DecodeError(f"{TWIST}: expected {TWIST_SIZE} bytes, got {len(data)}")
    check_header(TWIST, data)
    return Twist3D(*_SIX.unpack_from(data, HEADER_SIZE))


# ----------------------------------------------------------------------------- TwistStamped


def encode_twist_stamped(message: TwistStamped) -> bytes:
    """The ``geometry_msgs/msg/TwistStamped`` payload of ``message``."""
    if not isinstance(message, TwistStamped):
        raise EncodeError(f"{TWIST_STAMPED}: expected a TwistStamped, got {message!r}")
    w = CdrWriter(TWIST_STAMPED)
    write_header(w, message.header, "header")
    w.float64s(_SIX, _twist_values(TWIST_STAMPED, message.twist, "twist"), "twist")
    return w.payload()


def decode_twist_stamped(payload: Payload) -> TwistStamped:
    """The :class:`TwistStamped` in a ``geometry_msgs/msg/TwistStamped`` payload."""
    r = CdrReader(TWIST_STAMPED, payload)
    header = read_header(r, "header")
    twist = Twist3D(*r.float64s(_SIX, "twist"))
    r.finish()
    return TwistStamped(header, twist)


# ----------------------------------------------------------------------------- Odometry


def encode_odometry(message: Odometry) -> bytes:
    """The ``nav_msgs/msg/Odometry`` payload of ``message``."""
    if not isinstance(message, Odometry):
        raise EncodeError(f"{ODOMETRY}: expected an Odometry, got {message!r}")
    w = CdrWriter(ODOMETRY)
    write_header(w, message.header, "header")
    w.string(message.child_frame_id, "child_frame_id")
    w.float64s(_POSE, _pose_values(ODOMETRY, message.position, message.orientation,
                                   "pose.pose"), "pose.pose")
    w.float64s(_COVARIANCE, _covariance(ODOMETRY, message.pose_covariance, "pose.covariance"),
               "pose.covariance")
    w.float64s(_SIX, _twist_values(ODOMETRY, message.twist, "twist.twist"), "twist.twist")
    w.float64s(_COVARIANCE,
               _covariance(ODOMETRY, message.twist_covariance, "twist.covariance"),
               "twist.covariance")
    return w.payload()


def decode_odometry(payload: Payload) -> Odometry:
    """The :class:`Odometry` in a ``nav_msgs/msg/Odometry`` payload."""
    r = CdrReader(ODOMETRY, payload)
    header = read_header(r, "header")
    child = r.string("child_frame_id")
    position, orientation = _read_pose(r, "pose.pose")
    pose_covariance = r.float64s(_COVARIANCE, "pose.covariance")
    twist = Twist3D(*r.float64s(_SIX, "twist.twist"))
    twist_covariance = r.float64s(_COVARIANCE, "twist.covariance")
    r.finish()
    return Odometry(header, child, position, orientation, pose_covariance, twist,
                    twist_covariance)


# ----------------------------------------------------------------------------- TFMessage


def encode_tf_message(message: TFMessage) -> bytes:
    """The ``tf2_msgs/msg/TFMessage`` payload of ``message``."""
    if not isinstance(message, TFMessage):
        raise EncodeError(f"{TF_MESSAGE}: expected a TFMessage, got {message!r}")
    w = CdrWriter(TF_MESSAGE)
    transforms = tuple(message.transforms)
    w.sequence_length(len(transforms), "transforms")
    for index, transform in enumerate(transforms):
        field = f"transforms[{index}]"
        if not isinstance(transform, TransformStamped):
            raise EncodeError(
                f"{TF_MESSAGE}: expected a TransformStamped for {field}, got {transform!r}"
            )
        write_header(w, transform.header, f"{field}.header")
        w.string(transform.child_frame_id, f"{field}.child_frame_id")
        w.float64s(_POSE, _pose_values(TF_MESSAGE, transform.translation, transform.rotation,
                                       f"{field}.transform"), f"{field}.transform")
    return w.payload()


def decode_tf_message(payload: Payload) -> TFMessage:
    """The :class:`TFMessage` in a ``tf2_msgs/msg/TFMessage`` payload."""
    r = CdrReader(TF_MESSAGE, payload)
    count = r.sequence_length("transforms", _MIN_TRANSFORM_BYTES)
    transforms = []
    for index in range(count):
        field = f"transforms[{index}]"
        header = read_header(r, f"{field}.header")
        child = r.string(f"{field}.child_frame_id")
        translation, rotation = _read_pose(r, f"{field}.transform")
        transforms.append(TransformStamped(header, child, translation, rotation))
    r.finish()
    return TFMessage(tuple(transforms))



# ----------------------------------------------------------------------------- JointState


def _read_float64_sequence(r: CdrReader, field: str) -> tuple[float, ...]:
    count = r.sequence_length(field, 8)
    return r.float64s(struct.Struct(f"<{count}d"), field) if count else ()


def encode_joint_state(message: JointState) -> bytes:
    """The ``sensor_msgs/msg/JointState`` payload of ``message``; each of position, velocity
    and effort is empty or has one value per name."""
    if not isinstance(message, JointState):
        raise EncodeError(f"{JOINT_STATE}: expected a JointState, got {message!r}")
    names = message.name
    if not isinstance(names, (tuple, list)):
        raise EncodeError(f"{JOINT_STATE}: expected a sequence of str for name, got "
                          f"{names!r}")
    w = CdrWriter(JOINT_STATE)
    write_header(w, message.header, "header")
    w.sequence_length(len(names), "name")
    for index, name in enumerate(names):
        w.string(name, f"name[{index}]")
    for field in ("position", "velocity", "effort"):
        values = getattr(message, field)
        if not isinstance(values, (tuple, list)) or len(values) not in (0, len(names)):
            raise EncodeError(f"{JOINT_STATE}: expected none or {len(names)} numbers for "
                              f"{field} (one per name), got {values!r}")
        w.sequence_length(len(values), field)
        if values:  # (an empty sequence is its count alone: nothing to align)
            w.float64s(struct.Struct(f"<{len(values)}d"), values, field)
    return w.payload()


def decode_joint_state(payload: Payload) -> JointState:
    """The :class:`JointState` in a ``sensor_msgs/msg/JointState`` payload."""
    r = CdrReader(JOINT_STATE, payload)
    header = read_header(r, "header")
    count = r.sequence_length("name", 5)  # (a string: its length and its NUL at least)
    names = tuple(r.string(f"name[{index}]") for index in range(count))
    position = _read_float64_sequence(r, "position")
    velocity = _read_float64_sequence(r, "velocity")
    effort = _read_float64_sequence(r, "effort")
    r.finish()
    return JointState(header, names, position, velocity, effort)


# ----------------------------------------------------------------------------- std_srvs Trigger


def encode_trigger_request() -> bytes:
    """A ``std_srvs/srv/Trigger`` request (its placeholder byte 0)."""
    w = CdrWriter(TRIGGER_REQUEST)
    w.octet(0, "structure_needs_at_least_one_member")
    return w.payload()


def decode_trigger_request(payload: Payload) -> None:
    """Check a ``std_srvs/srv/Trigger`` request (any placeholder value: it means nothing)."""
    r = CdrReader(TRIGGER_REQUEST, payload)
    r.octet("structure_needs_at_least_one_member")
    r.finish()


def encode_trigger_response(message: TriggerResponse) -> bytes:
    """The ``std_srvs/srv/Trigger`` response payload of ``message``."""
    if not isinstance(message, TriggerResponse) or not isinstance(message.success, bool):
        raise EncodeError(f"{TRIGGER_RESPONSE}: expected a TriggerResponse with a bool "
                          f"success, got {message!r}")
    w = CdrWriter(TRIGGER_RESPONSE)
    w.octet(message.success, "success")
    w.string(message.message, "message")
    return w.payload()


def decode_trigger_response(payload: Payload) -> TriggerResponse:
    """The :class:`TriggerResponse` in a ``std_srvs/srv/Trigger`` response payload."""
    r = CdrReader(TRIGGER_RESPONSE, payload)
    success = r.octet("success")
    if success > 1:
        raise DecodeError(f"{TRIGGER_RESPONSE}: expected 0 or 1 for success, got {success}")
    message = r.string("message")
    r.finish()
    return TriggerResponse(bool(success), message)
