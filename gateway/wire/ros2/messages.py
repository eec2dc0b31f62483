"""The ROS 2 messages the bridge speaks, as frozen dataclasses, and the stamp helpers.

Each class mirrors one message of the public repositories ros2/common_interfaces
(``geometry_msgs``, ``nav_msgs``, ``sensor_msgs``, ``std_msgs``, ``std_srvs``), ros2/geometry2
(``tf2_msgs``) and ros2/rcl_interfaces (``builtin_interfaces``), field for field and in the
same order, except
:class:`Twist3D`, which flattens ``geometry_msgs/msg/Twist``'s two vectors, and
:class:`Odometry`, which flattens the ``PoseWithCovariance`` and ``TwistWithCovariance``.
Units are the ROS ones (REP 103): metres, radians, seconds.  Values are not validated here:
a decoder returns what came (NaN included), an encoder checks what it writes.
"""

from __future__ import annotations

from dataclasses import dataclass

#: Nanoseconds in a second.
NS_PER_S = 1_000_000_000
#: Entries of a 6x6 covariance matrix, row-major.
COVARIANCE_SIZE = 36
#: A covariance matrix of zeros (ROS: "unknown" when the first entry is -1, zeros: no data).
ZERO_COVARIANCE: tuple[float, ...] = (0.0,) * COVARIANCE_SIZE


@dataclass(frozen=True, slots=True)
class Time:
    """``builtin_interfaces/msg/Time``: seconds and nanoseconds since the Unix epoch.

    ROS keeps ``nanosec`` in ``[0, 1e9)`` and lets ``sec`` carry the sign: -1.7 s is
    ``Time(-2, 300_000_000)``.

    :param sec: whole seconds, an ``int32``.
    :param nanosec: nanoseconds to add, a ``uint32``.
    """

    sec: int = 0
    nanosec: int = 0


def ns_to_stamp(ns: int) -> Time:
    """The :class:`Time` of ``ns`` nanoseconds since the Unix epoch (floor division).

    No range check: :func:`~gateway.wire.ros2.cdr.encode_odometry` and the other encoders
    refuse a ``sec`` outside ``int32`` (after 2038-01-19).

    >>> ns_to_stamp(-1_700_000_000)
    Time(sec=-2, nanosec=300000000)
    """
    sec, nanosec = divmod(ns, NS_PER_S)
    return Time(sec, nanosec)


def stamp_to_ns(stamp: Time) -> int:
    """Nanoseconds since the Unix epoch of ``stamp`` (the inverse of :func:`ns_to_stamp`).

    >>> stamp_to_ns(Time(1, 5))
    1000000005
    """
    return stamp.sec * NS_PER_S + stamp.nanosec


@dataclass(frozen=True, slots=True)
class Header:
    """``std_msgs/msg/Header``.

    :param stamp: when the data was taken.
    :param frame_id: the frame the data is expressed in.
    """

    stamp: Time = Time()
    frame_id: str = ""


@dataclass(frozen=True, slots=True)
class Vector3:
    """``geometry_msgs/msg/Vector3`` (and ``Point``, which has the same layout)."""

    x: float = 0.0
    y: float = 0.0
    z: float = 0.0


@dataclass(frozen=True, slots=True)
class Quaternion:
    """``geometry_msgs/msg/Quaternion`` (identity by default, as in the ``.msg``)."""

    x: float = 0.0
    y: float = 0.0
    z: float = 0.0
    w: float = 1.0


@dataclass(frozen=True, slots=True)
class Twist3D:
    """``geometry_msgs/msg/Twist``, flattened: linear (m/s) then angular (rad/s) velocity."""

    linear_x: float = 0.0
    linear_y: float = 0.0
    linear_z: float = 0.0
    angular_x: float = 0.0
    angular_y: float = 0.0
    angular_z: float = 0.0


@dataclass(frozen=True, slots=True)
class TwistStamped:
    """``geometry_msgs/msg/TwistStamped``."""

    header: Header = Header()
    twist: Twist3D = Twist3D()


@dataclass(frozen=True, slots=True)
class Odometry:
    """``nav_msgs/msg/Odometry``, with its pose and twist parts flattened.

    :param header: stamp, and the frame of the pose (usually ``odom``).
    :param child_frame_id: the frame of the twist (usually ``base_link``).
    :param position: ``pose.pose.position``, m.
    :param orientation: ``pose.pose.orientation``.
    :param pose_covariance: ``pose.covariance``, 36 entries, row-major (x, y, z, rx, ry, rz).
    :param twist: ``twist.twist``, in ``child_frame_id``.
    :param twist_covariance: ``twist.covariance``, 36 entries.
    """

    header: Header = Header()
    child_frame_id: str = ""
    position: Vector3 = Vector3()
    orientation: Quaternion = Quaternion()
    pose_covariance: tuple[float, ...] = ZERO_COVARIANCE
    twist: Twist3D = Twist3D()
    twist_covariance: tuple[float, ...] = ZERO_COVARIANCE


@dataclass(frozen=True, slots=True)
class TransformStamped:
    """``geometry_msgs/msg/TransformStamped``: the pose of ``child_frame_id`` in
    ``header.frame_id``.

    :param header: stamp and parent frame.
    :param child_frame_id: the child frame.
    :param translation: ``transform.translation``, m.
    :param rotation: ``transform.rotation``.
    """

    header: Header = Header()
    child_frame_id: str = ""
    translation: Vector3 = Vector3()
    rotation: Quaternion = Quaternion()


@dataclass(frozen=True, slots=True)
class TFMessage:
    """``tf2_msgs/msg/TFMessage``: what ``/tf`` and ``/tf_static`` carry."""

    transforms: tuple[TransformStamped, ...] = ()


@dataclass(frozen=True, slots=True)
class JointState:
    """``sensor_msgs/msg/JointState``: joints by name, each array empty or one value per name.

    :param header: stamp (the frame is unused).
    :param name: the joints' names (a URDF's joint names, for ``robot_state_publisher``).
    :param position: rad for a revolute or continuous joint.
    :param velocity: rad/s.
    :param effort: N m.
    """

    header: Header = Header()
    name: tuple[str, ...] = ()
    position: tuple[float, ...] = ()
    velocity: tuple[float, ...] = ()
    effort: tuple[float, ...] = ()


@dataclass(frozen=True, slots=True)
class TriggerResponse:
    """``std_srvs/srv/Trigger``'s response (its request has no field).

    :param success: whether the service did what it is for.
    :param message: what happened, for a person.
    """

    success: bool = False
    message: str = ""
