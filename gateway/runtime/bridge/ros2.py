"""ROS 2 over rmw_zenoh, without ROS: ``cmd_vel`` in; ``odom`` and ``/tf`` out.

As the public repository ros2/rmw_zenoh (``docs/design.md``) describes its wire: data on the key
``<domain>/<topic>/<DDS type>/<type hash>`` in XCDR1 with an attachment (sequence number per
publisher, time, GID) on every sample, and the graph as liveliness tokens under ``@ros2_lv``
-- one for the node, one per publisher (``MP``) and subscription (``MS``) -- which is what
``ros2 topic list`` and ``ros2 node list`` show (:mod:`gateway.wire.ros2`).

* **In**: ``geometry_msgs/msg/Twist`` and ``TwistStamped`` on the ``cmd_vel`` topic (any type
  hash: Jazzy's and Humble's ``TypeHashNotSupported``); linear x, y and angular z become a
  twist request validated exactly as the control socket's (a twist with non-zero linear z or
  angular x, y is followed in the plane).  The publisher's GID in the attachment names the
  commander (``ros2:<gid>``); its ``MP`` token's disappearance is the deadman's trigger, GIDs
  being the XXH3 hash of the token key (:func:`gateway.wire.ros2.keys.gid_of`).
* **Out**: ``nav_msgs/msg/Odometry`` on ``odom`` (frame ``odom_frame``, child ``base_frame``,
  covariances the configured diagonals, zero by default: not estimated) and, with
  ``tf: true``, ``tf2_msgs/msg/TFMessage`` with the ``odom_frame`` -> ``base_frame``
  transform on ``/tf`` (Nav2 needs it there); with a ``joint_states`` topic,
  ``sensor_msgs/msg/JointState`` of every wheel (its unwrapped angle and measured speed) and
  steering actuator (its angle; speed NaN, not measured, as ros2_control's
  ``joint_state_broadcaster`` fills an interface it lacks), under the ``joints`` names, which
  ``robot_state_publisher`` turns into the wheels' transforms for RViz.  A motor not heard yet
  is left out (none of its values is known).
* **Diagnostics**, with a ``diagnostics`` topic (``/diagnostics``):
  ``diagnostic_msgs/msg/DiagnosticArray`` of the gateway, the CAN bus and every motor, once a
  second and at a change of state (:mod:`gateway.runtime.diagnostics`).
* **Services**, with ``services: true``: ``std_srvs/srv/Trigger`` on the node's ``~/estop``,
  ``~/enable`` and ``~/disable`` (``/robot1/wheelgate/estop``): each the control socket's
  request, through the bridge's inbox as the native ``rpc/<op>`` queries (the e-stop release
  rule included); the response's ``success`` is the reply's ``ok``, its ``message`` the state
  or the error.  As rmw_zenoh's service server (``rmw_zenoh_cpp/src/detail/rmw_service_data.cpp``)
  the reply carries the request's sequence number and the client's GID in its attachment.
"""

from __future__ import annotations

import functools
import json
import logging
import math
import time
from typing import TYPE_CHECKING, Any, cast

from gateway.core.errors import DecodeError, EncodeError
from gateway.runtime.bridge.inbox import NO_REPLY, Inbound, TwistSource
from gateway.runtime.bridge.native import parse_query
from gateway.runtime.bridge.session import import_zenoh
from gateway.runtime.diagnostics import diagnostic_array
from gateway.wire.ros2 import (
    DIAGNOSTIC_ARRAY,
    JOINT_STATE,
    ODOMETRY,
    TF_MESSAGE,
    TRIGGER,
    TWIST,
    TWIST_STAMPED,
    EntityKind,
    Header,
    JointState,
    Odometry,
    QosProfile,
    Quaternion,
    TFMessage,
    TransformStamped,
    TriggerResponse,
    Twist3D,
    Vector3,
    decode_attachment,
    decode_trigger_request,
    decode_twist,
    decode_twist_stamped,
    encode_attachment,
    encode_diagnostic_array,
    encode_joint_state,
    encode_odometry,
    encode_tf_message,
    encode_trigger_response,
    entity_token,
    gid_of,
    node_token,
    ns_to_stamp,
    parse_token,
    resolve_topic_name,
    topic_key,
    topic_subscription_key,
)
from gateway.wire.socket import Op, ProtocolError, Request, TwistRequest, parse_request

if TYPE_CHECKING:
    from collections.abc import Callable, Mapping

    from gateway.core.bridge_settings import AttachmentFormat, Ros2Settings
    from gateway.core.status import GatewayStatus
    from gateway.runtime.mailbox import Snapshot
    from gateway.wire.ros2 import RosType

log = logging.getLogger(__name__)

__all__ = ["SERVICE_OPS", "Ros2Side", "RosCall", "commander_name", "diagonal", "joint_state",
           "twist_request"]

#: The requests offered as ``std_srvs/srv/Trigger`` services of the node (``~/<op>``).
SERVICE_OPS: tuple[Op, ...] = (Op.ESTOP, Op.ENABLE, Op.DISABLE)

#: ``/tf`` publishers keep 100 (tf2_ros's ``DynamicBroadcasterQoS``); the others ROS's default.
TF_QOS = QosProfile(depth=100)
DEFAULT_QOS = QosProfile()


def commander_name(gid: bytes) -> str:
    """The deadman's name of the ROS publisher with this GID."""
    return f"ros2:{gid.hex()}"


def twist_request(twist: Twist3D, key: str) -> TwistRequest:
    """The socket's twist request for a ROS twist, validated as the socket validates it.

    :raises ProtocolError: a component that is not finite or beyond the socket's bound.
    """
    line = json.dumps({"op": "twist", "vx": twist.linear_x, "vy": twist.linear_y,
                       "wz": twist.angular_z})
    try:
        request = parse_request(line)
    except ProtocolError as err:
        raise ProtocolError(f"{key}: {err}") from None
    if not isinstance(request, TwistRequest):  # a twist line parses to a twist request
        raise ProtocolError(f"{key}: expected a twist, got {request!r}")
    return request


class _Publisher:
    """One ROS publisher: its Zenoh publisher, token, GID, sequence number and attachment
    layout."""

    def __init__(self, session: Any, key: str, token: str, layout: AttachmentFormat) -> None:
        self.zenoh = session.declare_publisher(key)
        self.token = session.liveliness().declare_token(token)
        self.gid = gid_of(token)
        self.seq = 0
        self.layout = layout

    def put(self, payload: bytes) -> None:
        self.seq += 1
        self.zenoh.put(payload, attachment=encode_attachment(self.seq, time.time_ns(), self.gid,
                                                             self.layout))


class RosCall:
    """A ROS service call waiting for the loop's reply (:meth:`response` is its payload and
    attachment; the bridge's ``_answer`` sends them).

    :param query: the Zenoh query.
    :param attachment: the request's attachment (sequence number, time, the client's GID).
    :param layout: the attachment layout the reply is written in.
    """

    def __init__(self, query: Any, attachment: bytes | None, layout: AttachmentFormat) -> None:
        self.query = query
        self.layout = layout
        self.seq, self.gid, self.bad = 0, bytes(16), ""
        if attachment is None:
            self.bad = "expected rmw_zenoh's attachment (sequence number, time, GID), got none"
        else:
            try:
                got = decode_attachment(attachment)
                self.seq, self.gid = got.sequence_number, got.gid
            except DecodeError as err:
                self.bad = str(err)

    def response(self, line: bytes) -> tuple[bytes, bytes]:
        """The ``Trigger`` response of the socket's reply ``line``, and the reply's
        attachment (the call's sequence number and the client's GID)."""
        reply = json.loads(line)
        ok = reply.get("ok") is True
        message = (f"state: {reply.get('state')}" if ok else
                   str((reply.get("error") or {}).get("message", reply)))
        return (encode_trigger_response(TriggerResponse(ok, message)),
                encode_attachment(self.seq, time.time_ns(), self.gid, self.layout))


class Ros2Side:
    """The ROS 2 endpoints of the bridge (see the module's doc).

    :param session: the bridge's Zenoh session.
    :param settings: the ``bridge.ros2`` block.
    :param namespace: the ROS namespace ('' for none).
    :param commander: a commander's token came (``True``) or went (Zenoh's threads call it).
    :param call: takes a service call and its request (or why it is refused).
    :param hardware: each motor's hardware id by its name, for the diagnostics.

    :attr:`twists` are the ``cmd_vel`` subscribers (one per type), for the loop to take from.
    """

    def __init__(self, session: Any, settings: Ros2Settings, namespace: str,
                 commander: Callable[[str, bool], object],
                 call: Callable[[RosCall, Request | ProtocolError], object] | None = None,
                 hardware: Mapping[str, str] | None = None) -> None:
        self.settings = settings
        self._hardware = dict(hardware or {})
        self._commander = commander
        self._call = call
        ns = "/" + namespace if namespace else "/"
        domain, zid, name = settings.domain_id, str(session.zid()), settings.node_name
        self.cmd_vel = resolve_topic_name(settings.cmd_vel, ns)
        ids = iter(range(1, 100))
        self._entities: list[Any] = [
            session.liveliness().declare_token(node_token(domain, zid, 0, ns, name))]
        #: The cmd_vel subscribers, newest sample only (see TwistSource).
        self.twists: list[TwistSource] = []
        ring = cast("Any", import_zenoh()).handlers.RingChannel
        for ros_type, decode in ((TWIST, _plain), (TWIST_STAMPED, _stamped)):
            self.twists.append(TwistSource(session.declare_subscriber(
                topic_subscription_key(domain, self.cmd_vel, ros_type), ring(1)),
                functools.partial(_ros_twist, decode)))
            self._entities.append(self.twists[-1].subscriber)
            self._entities.append(session.liveliness().declare_token(entity_token(
                EntityKind.SUBSCRIPTION, domain, zid, 0, next(ids), ns, name, self.cmd_vel,
                ros_type, QosProfile())))

        def publisher(topic: str, ros_type: RosType, qos: QosProfile = DEFAULT_QOS
                      ) -> _Publisher | None:
            """A publisher on ``topic`` (resolved in the namespace), none for ``""``."""
            if not topic:
                return None
            full = resolve_topic_name(topic, ns)
            return _Publisher(session, topic_key(domain, full, ros_type), entity_token(
                EntityKind.PUBLISHER, domain, zid, 0, next(ids), ns, name, full, ros_type, qos),
                settings.attachment)

        self.odom = cast("_Publisher", publisher(settings.odom, ODOMETRY))
        self.tf = publisher("/tf" if settings.tf else "", TF_MESSAGE, TF_QOS)
        self.joints = publisher(settings.joint_states, JOINT_STATE)
        self.diagnostics = publisher(settings.diagnostics, DIAGNOSTIC_ARRAY)
        self._joint_names = dict(settings.joints)
        self._covariances = (diagonal(settings.pose_covariance_diagonal),
                             diagonal(settings.twist_covariance_diagonal))
        #: The services' names (``/robot1/wheelgate/estop``), by op.
        self.services: dict[Op, str] = {}
        if settings.services and call is not None:
            for op in SERVICE_OPS:
                service = f"{ns.rstrip('/')}/{name}/{op.value}"
                self.services[op] = service
                self._entities.append(session.declare_queryable(
                    topic_key(domain, service, TRIGGER), functools.partial(self._on_call, op)))
                self._entities.append(session.liveliness().declare_token(entity_token(
                    EntityKind.SERVICE, domain, zid, 0, next(ids), ns, name, service, TRIGGER,
                    QosProfile())))
        self._types = {TWIST.dds_name, TWIST_STAMPED.dds_name}
        self._entities.append(session.liveliness().declare_subscriber(
            f"@ros2_lv/{domain}/**", self._on_token, history=True))

    # ----------------------------------------------------------------- in (Zenoh's threads)

    def _on_token(self, sample: Any) -> None:
        try:
            token = parse_token(str(sample.key_expr))
        except DecodeError:
            return  # another rmw's or a newer layout's token: not a commander of ours
        if (token.kind is EntityKind.PUBLISHER and token.topic == self.cmd_vel
                and token.type_name in self._types):
            self._commander(commander_name(token.gid), str(sample.kind).endswith("PUT"))

    def _on_call(self, op: Op, query: Any) -> None:
        key = str(query.key_expr)
        attachment, payload = query.attachment, query.payload
        call = RosCall(query, None if attachment is None else attachment.to_bytes(),
                       self.settings.attachment)
        request: Request | ProtocolError
        try:
            decode_trigger_request(b"" if payload is None else payload.to_bytes())
            if call.bad:
                raise ProtocolError(f"{key}: {call.bad}")
            request = parse_query(op, None, key)  # (no payload: the op's bare request)
        except DecodeError as err:
            request = ProtocolError(f"{key}: {err}")
        except ProtocolError as err:
            request = err
        if self._call is not None:
            self._call(call, request)

    # ----------------------------------------------------------------- out (the worker)

    def publish(self, snap: Snapshot) -> None:
        """Odometry (and the transform) of one snapshot."""
        s = self.settings
        odom = snap.odometry
        pose, twist = odom.pose, odom.twist
        header = Header(ns_to_stamp(snap.stamp_ns), s.odom_frame)
        half = 0.5 * pose.theta_rad
        rotation = Quaternion(0.0, 0.0, math.sin(half), math.cos(half))
        position = Vector3(pose.x_m, pose.y_m, 0.0)
        try:
            pose_cov, twist_cov = self._covariances
            self.odom.put(encode_odometry(Odometry(
                header, s.base_frame, position, rotation, pose_cov,
                Twist3D(twist.vx_m_s, twist.vy_m_s, 0.0, 0.0, 0.0, twist.wz_rad_s), twist_cov)))
            if self.tf is not None:
                self.tf.put(encode_tf_message(TFMessage((TransformStamped(
                    header, s.base_frame, position, rotation),))))
        except EncodeError as err:  # e.g. a stamp beyond int32 seconds (2038)
            log.warning("bridge: ROS 2 odometry not sent: %s", err)
        if self.joints is not None:
            try:
                self.joints.put(encode_joint_state(joint_state(snap, self._joint_names)))
            except EncodeError as err:
                log.warning("bridge: ROS 2 joint states not sent: %s", err)

    def publish_report(self, report: GatewayStatus) -> None:
        """The diagnostics of a status report (nothing without a ``diagnostics`` topic)."""
        if self.diagnostics is None:
            return
        try:
            self.diagnostics.put(encode_diagnostic_array(diagnostic_array(
                report, self.settings.node_name, self._hardware, time.time_ns())))
        except EncodeError as err:
            log.warning("bridge: ROS 2 diagnostics not sent: %s", err)

    def close(self) -> None:
        """Withdraw the tokens (the node leaves ``ros2 node list``)."""
        for publisher in (self.odom, self.tf, self.joints, self.diagnostics):
            if publisher is not None:
                publisher.token.undeclare()
        for entity in self._entities:
            entity.undeclare()


def diagonal(variances: tuple[float, ...]) -> tuple[float, ...]:
    """The 6x6 covariance, row-major, with ``variances`` on its diagonal."""
    return tuple(variances[i // 6] if i % 7 == 0 else 0.0 for i in range(36))


def joint_state(snap: Snapshot, names: Mapping[str, str]) -> JointState:
    """The ``sensor_msgs/msg/JointState`` of a snapshot: every wheel and steering actuator
    heard so far, under its joint name (``names``, else its own)."""
    joints: list[str] = []
    position: list[float] = []
    velocity: list[float] = []
    for wheel in snap.wheels:
        if wheel.position_rad is not None:
            joints.append(names.get(wheel.name, wheel.name))
            position.append(wheel.position_rad)
            speed = wheel.measured_rad_s
            velocity.append(math.nan if speed is None else speed)
    for actuator in snap.steering:
        if actuator.measured_rad is not None:
            joints.append(names.get(actuator.name, actuator.name))
            position.append(actuator.measured_rad)
            velocity.append(math.nan)
    return JointState(Header(ns_to_stamp(snap.stamp_ns), ""), tuple(joints), tuple(position),
                      tuple(velocity))


def _ros_twist(decode: Callable[[bytes], Twist3D], payload: bytes, attachment: bytes | None,
               key: str) -> Inbound:
    """A ``cmd_vel`` sample's twist request, its commander the publisher's GID.

    :raises ProtocolError: for a payload or attachment that does not decode, or a twist the
        socket would refuse, naming the key.
    """
    try:
        twist = decode(payload)
        commander = None if attachment is None else commander_name(
            decode_attachment(attachment).gid)
    except DecodeError as err:
        raise ProtocolError(f"{key}: {err}") from None
    return Inbound(NO_REPLY, twist_request(twist, key), commander)


def _plain(payload: bytes) -> Twist3D:
    return decode_twist(payload)


def _stamped(payload: bytes) -> Twist3D:
    return decode_twist_stamped(payload).twist
