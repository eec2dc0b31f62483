"""The live view's channels: their topics, schemas and messages.

:mod:`gateway.runtime.liveview` serves and records these channels through :class:`Channels`;
``wheelgate odom FILE.mcap`` (:mod:`gateway.apps.replay.mcap_source`) reads a recording back by
the same names.  This module never imports the Foxglove SDK (:class:`Channels` is handed the
module), so the replay needs only the ``mcap`` package; the rest is pure (no clock, no I/O).

========================  ===============================  ==========  ============================
topic                     schema                           encoding    fields
========================  ===============================  ==========  ============================
``/tf``                   ``foxglove.FrameTransforms``     protobuf    ``odom`` -> ``base_link``:
                                                                       translation (x, y, 0),
                                                                       rotation about z (theta)
``/odom/pose``            ``foxglove.PoseInFrame``         protobuf    the pose in frame ``odom``
``/odom``                 ``wheelgate.Odometry``           json        ``pose`` {x_m, y_m,
                                                                       theta_rad}, ``twist``
                                                                       {vx_m_s, vy_m_s, wz_rad_s}
                                                                       (body frame), slip_m_s,
                                                                       distance_m, timestamp_s
``/wheels``               ``wheelgate.Wheels``             json        ``{<wheel>: {commanded_rad_s,
                                                                       measured_rad_s,
                                                                       position_rad}}``
``/steering``             ``wheelgate.Steering``           json        ``{<actuator>:
                                                                       {commanded_rad,
                                                                       measured_rad}}``
``/state``                ``wheelgate.State``              json        state, code, reason
``/errors``               ``foxglove.Log``                 protobuf    level, ``<code>: <message>``,
                                                                       name (the robot)
``/diagnostics``          ``diagnostic_msgs/msg/``         cdr         the gateway, the CAN bus,
                          ``DiagnosticArray`` (ros2msg)                each motor: level, message,
                                                                       hardware id, values
========================  ===============================  ==========  ============================

Every number that is not finite, and every value not measured yet, is ``null`` (JSON has no
NaN, RFC 8259 section 6; a ``null`` is not plotted); the schemas still say ``number``, the one
type name the Foxglove app reads.  The wheels and actuators are keys, not array items, so the
Plot panel takes a path such as ``/wheels.front_left.measured_rad_s``.  ``/odom``'s
``timestamp_s`` is the odometry's own (its last wheel feedback); every message's log time is the
snapshot's ``stamp_ns``.  ``/errors`` holds every error at level Error, and a Warning when some
were dropped.  ``/steering`` exists only for robots with steering actuators.  ``/diagnostics``
is ROS 2's own message (:mod:`gateway.runtime.diagnostics`; once a second and at a change of
state), CDR-encoded under its complete ``ros2msg`` definition, so the app's Diagnostics panels
(which take ``diagnostic_msgs/msg/DiagnosticArray`` by that name) show it, as they would a ROS
robot's.

Well-known schemas: https://docs.foxglove.dev/docs/sdk/schemas (``/frame-transforms``,
``/pose-in-frame``, ``/log``); JSON channels (message encoding ``json``, schema encoding
``jsonschema``): https://docs.foxglove.dev/docs/getting-started/custom/custom-schema-encodings.
"""

from __future__ import annotations

import enum
import json
import math
from typing import TYPE_CHECKING, Any

from gateway.wire.ros2 import DIAGNOSTIC_ARRAY, encode_diagnostic_array
from gateway.wire.ros2.typehash import complete_definition

if TYPE_CHECKING:
    from collections.abc import Callable, Sequence
    from types import ModuleType

    from gateway.core.kinematics.odometry import OdometryState, Pose
    from gateway.runtime.mailbox import Snapshot, SteerSample, WheelSample
    from gateway.wire.ros2 import DiagnosticArray

#: A pose in the plane, every number finite: x (m), y (m), theta (rad).
Planar = tuple[float, float, float]

__all__ = [
    "BASE_FRAME",
    "DIAGNOSTICS_TOPIC",
    "ERRORS_TOPIC",
    "ODOM_FRAME",
    "ODOM_SCHEMA",
    "ODOM_TOPIC",
    "POSE_TOPIC",
    "STATE_SCHEMA",
    "STATE_TOPIC",
    "STEERING_TOPIC",
    "TF_TOPIC",
    "WHEELS_TOPIC",
    "Channels",
    "Planar",
    "encode_json",
    "log_time_ns",
    "num",
    "odom_message",
    "planar",
    "state_message",
    "steering_message",
    "steering_schema",
    "wheels_message",
    "wheels_schema",
    "yaw_quaternion",
]

TF_TOPIC = "/tf"
POSE_TOPIC = "/odom/pose"
ODOM_TOPIC = "/odom"
WHEELS_TOPIC = "/wheels"
STEERING_TOPIC = "/steering"
STATE_TOPIC = "/state"
ERRORS_TOPIC = "/errors"
DIAGNOSTICS_TOPIC = "/diagnostics"
#: The odometry's frame id (the transform's parent) and the robot's (its child), as ROS's.
ODOM_FRAME = "odom"
BASE_FRAME = "base_link"

#: The largest log time an MCAP record holds (a uint64 of ns).
_U64_MAX = 2**64 - 1

#: A number, or ``null`` (not finite, not measured yet).  The schema says ``number`` only: the
#: Foxglove app reads ``type`` as one name and rejects a list such as ``["number", "null"]``
#: (its ``parseJsonSchema``, https://github.com/foxglove/studio, packages/mcap-support).
_NUMBER: dict[str, Any] = {"type": "number", "description": "null when not finite or not known"}


def _object(title: str, properties: dict[str, Any], description: str) -> dict[str, Any]:
    schema: dict[str, Any] = {"type": "object", "properties": properties,
                              "description": description}
    if title:
        schema = {"title": title, **schema}
    return schema


def _numbers(*names: str) -> dict[str, Any]:
    return dict.fromkeys(names, _NUMBER)


#: ``/odom``: the odometry (SI units, named in the field; the twist in the body frame).
ODOM_SCHEMA = _object("wheelgate.Odometry", {
    "pose": _object("", _numbers("x_m", "y_m", "theta_rad"), "pose in frame odom"),
    "twist": _object("", _numbers("vx_m_s", "vy_m_s", "wz_rad_s"), "body twist"),
    **_numbers("slip_m_s", "distance_m", "timestamp_s"),
}, "wheel odometry of wheelgate")

#: ``/state``: the gateway's state (its lower-case name and number) and why.
STATE_SCHEMA = _object("wheelgate.State", {
    "state": {"type": "string"},
    "code": {"type": "integer"},
    "reason": {"type": "string"},
}, "the gateway's state; reason: why it is in fault or estop")


def wheels_schema(names: Sequence[str]) -> dict[str, Any]:
    """``/wheels``: one object per driven wheel (rad/s at the wheel; angle unwrapped, rad)."""
    wheel = _object("", _numbers("commanded_rad_s", "measured_rad_s", "position_rad"),
                    "a driven wheel")
    return _object("wheelgate.Wheels", dict.fromkeys(names, wheel),
                   "the driven wheels: commanded and measured speed, measured angle")


def steering_schema(names: Sequence[str]) -> dict[str, Any]:
    """``/steering``: one object per steering actuator (rad)."""
    actuator = _object("", _numbers("commanded_rad", "measured_rad"), "a steering actuator")
    return _object("wheelgate.Steering", dict.fromkeys(names, actuator),
                   "the steering actuators: commanded and measured angle")


def num(value: object) -> float | None:
    """``value`` as a float when it is a finite real number, else ``None`` (JSON ``null``).

    >>> num(1), num(float("nan")), num(None), num("2")
    (1.0, None, None, None)
    """
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        out = float(value)
        if math.isfinite(out):
            return out
    return None


def log_time_ns(stamp_ns: object) -> int | None:
    """``stamp_ns`` when it can be a log time (an int in [0, 2**64)), else ``None``."""
    if isinstance(stamp_ns, int) and not isinstance(stamp_ns, bool) and 0 <= stamp_ns <= _U64_MAX:
        return stamp_ns
    return None


def planar(pose: Pose) -> Planar | None:
    """``(x, y, theta)`` of ``pose``, or ``None`` when one of them is not a finite number."""
    x, y, theta = num(pose.x_m), num(pose.y_m), num(pose.theta_rad)
    if x is None or y is None or theta is None:
        return None
    return x, y, theta


def yaw_quaternion(theta_rad: float) -> tuple[float, float, float, float]:
    """The rotation by ``theta_rad`` about z, as ``(x, y, z, w)``.

    >>> tuple(round(c, 6) for c in yaw_quaternion(math.pi / 2))
    (0.0, 0.0, 0.707107, 0.707107)
    """
    half = 0.5 * theta_rad
    return 0.0, 0.0, math.sin(half), math.cos(half)


def odom_message(state: OdometryState) -> dict[str, Any]:
    """The ``/odom`` message of an odometry state."""
    p, t = state.pose, state.twist
    return {
        "pose": {"x_m": num(p.x_m), "y_m": num(p.y_m), "theta_rad": num(p.theta_rad)},
        "twist": {"vx_m_s": num(t.vx_m_s), "vy_m_s": num(t.vy_m_s), "wz_rad_s": num(t.wz_rad_s)},
        "slip_m_s": num(state.slip_m_s),
        "distance_m": num(state.distance_m),
        "timestamp_s": num(state.timestamp_s),
    }


def wheels_message(wheels: Sequence[WheelSample]) -> dict[str, Any]:
    """The ``/wheels`` message: every wheel by name."""
    return {
        str(w.name): {
            "commanded_rad_s": num(w.commanded_rad_s),
            "measured_rad_s": num(w.measured_rad_s),
            "position_rad": num(w.position_rad),
        }
        for w in wheels
    }


def steering_message(steering: Sequence[SteerSample]) -> dict[str, Any]:
    """The ``/steering`` message: every actuator by name."""
    return {
        str(s.name): {"commanded_rad": num(s.commanded_rad), "measured_rad": num(s.measured_rad)}
        for s in steering
    }


def state_message(state: object, reason: object) -> dict[str, Any]:
    """The ``/state`` message: ``{"state": "running", "code": 2, "reason": ""}``."""
    if isinstance(state, enum.Enum):
        name = state.name.lower() if state.name else str(state.value)
        code = state.value if isinstance(state.value, int) else None
    else:
        name, code = str(state), None
    return {"state": name, "code": code, "reason": "" if reason is None else str(reason)}


def encode_json(message: dict[str, Any]) -> bytes:
    """A message as compact UTF-8 JSON (strict: a NaN that slipped through raises
    :class:`ValueError` instead of writing what no JSON parser reads)."""
    return json.dumps(message, allow_nan=False, separators=(",", ":")).encode()


class Channels:
    """The SDK's channels of one live view, and how a snapshot goes on them.

    :param fg: the ``foxglove`` module (imported by the caller).
    :param context: the SDK context the channels belong to (one per view: two views never
        share a channel, and a sink sees only its own view's).
    :param robot_name: the ``name`` of the ``/errors`` log messages.
    :param wheel_names: the driven wheels (``/wheels``' schema).
    :param steer_names: the steering actuators (no ``/steering`` when there are none).
    """

    def __init__(self, fg: ModuleType, context: Any, robot_name: str,
                 wheel_names: Sequence[str], steer_names: Sequence[str]) -> None:
        self._m = fg.messages
        self.robot_name = robot_name
        make = fg.channels
        self._tf = make.FrameTransformsChannel(TF_TOPIC, context=context)
        self._pose = make.PoseInFrameChannel(POSE_TOPIC, context=context)
        self._errors = make.LogChannel(ERRORS_TOPIC, context=context)
        self._odom = fg.Channel(ODOM_TOPIC, schema=ODOM_SCHEMA, context=context)
        self._wheels = fg.Channel(WHEELS_TOPIC, schema=wheels_schema(wheel_names),
                                  context=context)
        self._state = fg.Channel(STATE_TOPIC, schema=STATE_SCHEMA, context=context)
        self._steering = (fg.Channel(STEERING_TOPIC, schema=steering_schema(steer_names),
                                     context=context) if steer_names else None)
        self._diagnostics = fg.Channel(
            DIAGNOSTICS_TOPIC, message_encoding="cdr", context=context,
            schema=fg.Schema(name=DIAGNOSTIC_ARRAY.ros_name, encoding="ros2msg",
                             data=complete_definition(DIAGNOSTIC_ARRAY.ros_name).encode()))
        #: ``(topic, publish)`` for every channel a snapshot goes on, in order; ``publish``
        #: takes the snapshot, its log time (ns) and its pose (``None``: not finite).
        self.per_snapshot: list[tuple[str, Callable[[Snapshot, int, Planar | None], None]]] = [
            (TF_TOPIC, self.tf), (POSE_TOPIC, self.pose), (ODOM_TOPIC, self.odom),
            (WHEELS_TOPIC, self.wheels),
            *([(STEERING_TOPIC, self.steering)] if steer_names else []),
            (STATE_TOPIC, self.snapshot_state),
        ]

    def _timestamp(self, t: int) -> Any:
        return self._m.Timestamp(t // 1_000_000_000, t % 1_000_000_000)

    def _transform(self, xyt: Planar) -> tuple[Any, Any]:
        m = self._m
        qx, qy, qz, qw = yaw_quaternion(xyt[2])
        return m.Vector3(x=xyt[0], y=xyt[1], z=0.0), m.Quaternion(x=qx, y=qy, z=qz, w=qw)

    def tf(self, snap: Snapshot, t: int, xyt: Planar | None) -> None:
        """``/tf``: ``odom`` -> ``base_link`` (nothing for a pose that is not finite)."""
        if xyt is None:
            return
        m = self._m
        translation, rotation = self._transform(xyt)
        self._tf.log(m.FrameTransforms(transforms=[m.FrameTransform(
            timestamp=self._timestamp(t), parent_frame_id=ODOM_FRAME, child_frame_id=BASE_FRAME,
            translation=translation, rotation=rotation)]), log_time=t)

    def pose(self, snap: Snapshot, t: int, xyt: Planar | None) -> None:
        """``/odom/pose``: the pose in ``odom`` (nothing for a pose that is not finite)."""
        if xyt is None:
            return
        m = self._m
        position, orientation = self._transform(xyt)
        self._pose.log(m.PoseInFrame(timestamp=self._timestamp(t), frame_id=ODOM_FRAME,
                                     pose=m.Pose(position=position, orientation=orientation)),
                       log_time=t)

    def odom(self, snap: Snapshot, t: int, xyt: Planar | None) -> None:
        """``/odom``."""
        self._odom.log(encode_json(odom_message(snap.odometry)), log_time=t)

    def wheels(self, snap: Snapshot, t: int, xyt: Planar | None) -> None:
        """``/wheels``."""
        self._wheels.log(encode_json(wheels_message(snap.wheels)), log_time=t)

    def steering(self, snap: Snapshot, t: int, xyt: Planar | None) -> None:
        """``/steering`` (only made for robots with steering actuators)."""
        if self._steering is not None:
            self._steering.log(encode_json(steering_message(snap.steering)), log_time=t)

    def snapshot_state(self, snap: Snapshot, t: int, xyt: Planar | None) -> None:
        """``/state`` from a snapshot."""
        self.state(snap.state, snap.reason, t)

    def state(self, state: object, reason: object, t: int) -> None:
        """``/state``."""
        self._state.log(encode_json(state_message(state, reason)), log_time=t)

    def log(self, error: bool, text: str, t: int) -> None:
        """``/errors``: a ``foxglove.Log`` at level Error (or Warning), named for the robot."""
        m = self._m
        self._errors.log(m.Log(timestamp=self._timestamp(t), message=text,
                               level=m.LogLevel.Error if error else m.LogLevel.Warning,
                               name=self.robot_name), log_time=t)

    def diagnostics(self, report: DiagnosticArray, t: int) -> None:
        """``/diagnostics``: the report as ROS 2 serializes it (CDR)."""
        self._diagnostics.log(encode_diagnostic_array(report), log_time=t)
