"""The ROS 2 CDR codecs against an independent encoder, pycdr2 (from cyclonedds-python).

The messages are declared here with pycdr2's IDL types, field for field as the ``.msg`` files
declare them; pycdr2 serializes them as XCDR1 little endian with the encapsulation header.
Our encoder must produce the same bytes, and our decoder must read pycdr2's bytes, for
fixed examples and for any message hypothesis draws.
"""

from __future__ import annotations

import types
from dataclasses import dataclass
from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st

pytest.importorskip("pycdr2", reason="pycdr2 (pip install pycdr2) is the independent CDR "
                                     "encoder these tests compare with")

from pycdr2 import IdlStruct
from pycdr2 import types as pycdr2_types
from pycdr2._support import Endianness

from gateway.wire.ros2 import (
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

# ----------------------------------------------------------------------------- IDL, by pycdr2


def idl_struct(typename: str, **fields: Any) -> Any:
    """A pycdr2 struct class named ``typename`` with ``fields`` (name: pycdr2 type), in order.

    Built at run time so that its annotations are objects, not the strings that
    ``from __future__ import annotations`` would leave for pycdr2 to resolve.
    """
    def body(namespace: dict[str, Any]) -> None:
        namespace["__annotations__"] = dict(fields)

    cls = types.new_class(typename.rsplit("::", 1)[-1], (IdlStruct,), {"typename": typename},
                          body)
    return dataclass(cls)


T: Any = pycdr2_types
CTime = idl_struct("builtin_interfaces::msg::dds_::Time_", sec=T.int32, nanosec=T.uint32)
CHeader = idl_struct("std_msgs::msg::dds_::Header_", stamp=CTime, frame_id=str)
CVector3 = idl_struct("geometry_msgs::msg::dds_::Vector3_",
                      x=T.float64, y=T.float64, z=T.float64)
CQuaternion = idl_struct("geometry_msgs::msg::dds_::Quaternion_",
                         x=T.float64, y=T.float64, z=T.float64, w=T.float64)
CTwist = idl_struct("geometry_msgs::msg::dds_::Twist_", linear=CVector3, angular=CVector3)
CTwistStamped = idl_struct("geometry_msgs::msg::dds_::TwistStamped_",
                           header=CHeader, twist=CTwist)
CPose = idl_struct("geometry_msgs::msg::dds_::Pose_", position=CVector3, orientation=CQuaternion)
CPoseWithCovariance = idl_struct("geometry_msgs::msg::dds_::PoseWithCovariance_",
                                 pose=CPose, covariance=T.array[T.float64, 36])
CTwistWithCovariance = idl_struct("geometry_msgs::msg::dds_::TwistWithCovariance_",
                                  twist=CTwist, covariance=T.array[T.float64, 36])
COdometry = idl_struct("nav_msgs::msg::dds_::Odometry_", header=CHeader, child_frame_id=str,
                       pose=CPoseWithCovariance, twist=CTwistWithCovariance)
CTransform = idl_struct("geometry_msgs::msg::dds_::Transform_",
                        translation=CVector3, rotation=CQuaternion)
CTransformStamped = idl_struct("geometry_msgs::msg::dds_::TransformStamped_",
                               header=CHeader, child_frame_id=str, transform=CTransform)
CTFMessage = idl_struct("tf2_msgs::msg::dds_::TFMessage_",
                        transforms=T.sequence[CTransformStamped])
CTriggerRequest = idl_struct("std_srvs::srv::dds_::Trigger_Request_",
                             structure_needs_at_least_one_member=T.uint8)
CTriggerResponse = idl_struct("std_srvs::srv::dds_::Trigger_Response_", success=bool,
                              message=str)
CJointState = idl_struct("sensor_msgs::msg::dds_::JointState_", header=CHeader,
                         name=T.sequence[str], position=T.sequence[T.float64],
                         velocity=T.sequence[T.float64], effort=T.sequence[T.float64])


# ----------------------------------------------------------------------------- conversions


def c_header(h: Header) -> Any:
    return CHeader(CTime(h.stamp.sec, h.stamp.nanosec), h.frame_id)


def c_twist(t: Twist3D) -> Any:
    return CTwist(CVector3(t.linear_x, t.linear_y, t.linear_z),
                  CVector3(t.angular_x, t.angular_y, t.angular_z))


def c_quaternion(q: Quaternion) -> Any:
    return CQuaternion(q.x, q.y, q.z, q.w)


def c_odometry(m: Odometry) -> Any:
    p = m.position
    return COdometry(
        c_header(m.header), m.child_frame_id,
        CPoseWithCovariance(CPose(CVector3(p.x, p.y, p.z), c_quaternion(m.orientation)),
                            list(m.pose_covariance)),
        CTwistWithCovariance(c_twist(m.twist), list(m.twist_covariance)),
    )


def c_tf(m: TFMessage) -> Any:
    return CTFMessage([
        CTransformStamped(
            c_header(t.header), t.child_frame_id,
            CTransform(CVector3(t.translation.x, t.translation.y, t.translation.z),
                       c_quaternion(t.rotation)))
        for t in m.transforms
    ])


def c_joints(m: JointState) -> Any:
    return CJointState(c_header(m.header), list(m.name), list(m.position), list(m.velocity),
                       list(m.effort))


def cdr(struct: Any) -> bytes:
    """pycdr2's XCDR1 little-endian payload of ``struct``."""
    return bytes(struct.serialize(endianness=Endianness.Little, use_version_2=False))


# ----------------------------------------------------------------------------- strategies

FLOATS = st.floats(allow_nan=False, width=64)
NAMES = st.text(st.characters(exclude_categories=["Cs"], exclude_characters="\0"),
                max_size=20)
TIMES = st.builds(Time, st.integers(-(2**31), 2**31 - 1), st.integers(0, 10**9 - 1))
HEADERS = st.builds(Header, TIMES, NAMES)
TWISTS = st.builds(Twist3D, FLOATS, FLOATS, FLOATS, FLOATS, FLOATS, FLOATS)
VECTORS = st.builds(Vector3, FLOATS, FLOATS, FLOATS)
QUATERNIONS = st.builds(Quaternion, FLOATS, FLOATS, FLOATS, FLOATS)
COVARIANCES = st.lists(FLOATS, min_size=36, max_size=36).map(tuple)
ODOMETRIES = st.builds(Odometry, HEADERS, NAMES, VECTORS, QUATERNIONS, COVARIANCES, TWISTS,
                       COVARIANCES)
JOINT_STATES = st.integers(0, 5).flatmap(lambda n: st.builds(
    JointState, HEADERS, st.lists(NAMES, min_size=n, max_size=n).map(tuple),
    *(st.one_of(st.just(()), st.lists(FLOATS, min_size=n, max_size=n).map(tuple))
      for _ in range(3))))
TF_MESSAGES = st.builds(TFMessage, st.lists(
    st.builds(TransformStamped, HEADERS, NAMES, VECTORS, QUATERNIONS), max_size=4).map(tuple))


# ----------------------------------------------------------------------------- tests

ODOM = Odometry(Header(Time(1_700_000_000, 5), "odom"), "base_link", Vector3(1.0, 2.0, 0.0),
                Quaternion(0.0, 0.0, 0.6, 0.8), tuple(i / 8 for i in range(36)),
                Twist3D(0.5, 0.0, 0.0, 0.0, 0.0, -0.25), (0.01,) * 36)


def test_twist_matches_pycdr2() -> None:
    twist = Twist3D(1.0, -2.0, 3.5, 0.0, -0.0, 1e-300)
    expected = cdr(c_twist(twist))
    assert expected[:4] == b"\x00\x01\x00\x00"
    assert len(expected) == 52
    assert encode_twist(twist) == expected
    assert decode_twist(expected) == twist


@pytest.mark.parametrize("frame", ["", "b", "base_link", "odom_frame_", "ünïcödé"])
def test_twist_stamped_matches_pycdr2_for_every_padding(frame: str) -> None:
    message = TwistStamped(Header(Time(-5, 999_999_999), frame), Twist3D(0.1, 0.2))
    expected = cdr(CTwistStamped(c_header(message.header), c_twist(message.twist)))
    assert encode_twist_stamped(message) == expected
    assert decode_twist_stamped(expected) == message


@pytest.mark.parametrize("child", ["", "base", "base_link"])
def test_odometry_matches_pycdr2(child: str) -> None:
    message = Odometry(ODOM.header, child, ODOM.position, ODOM.orientation,
                       ODOM.pose_covariance, ODOM.twist, ODOM.twist_covariance)
    expected = cdr(c_odometry(message))
    assert encode_odometry(message) == expected
    assert decode_odometry(expected) == message


def test_tf_message_matches_pycdr2() -> None:
    message = TFMessage((
        TransformStamped(Header(Time(1, 2), "odom"), "base_link", Vector3(1.0, 2.0, 0.0),
                         Quaternion(0.0, 0.0, 0.0, 1.0)),
        TransformStamped(Header(Time(3, 4), "base_link"), "laser", Vector3(0.1),
                         Quaternion(0.0, 0.0, 1.0, 0.0)),
    ))
    expected = cdr(c_tf(message))
    assert encode_tf_message(message) == expected
    assert decode_tf_message(expected) == message
    assert encode_tf_message(TFMessage()) == cdr(CTFMessage([]))


@given(TWISTS)
def test_any_twist_matches_pycdr2(twist: Twist3D) -> None:
    expected = cdr(c_twist(twist))
    assert encode_twist(twist) == expected
    assert decode_twist(expected) == twist


@given(st.builds(TwistStamped, HEADERS, TWISTS))
def test_any_twist_stamped_matches_pycdr2(message: TwistStamped) -> None:
    expected = cdr(CTwistStamped(c_header(message.header), c_twist(message.twist)))
    assert encode_twist_stamped(message) == expected
    assert decode_twist_stamped(expected) == message


@given(ODOMETRIES)
def test_any_odometry_matches_pycdr2(message: Odometry) -> None:
    expected = cdr(c_odometry(message))
    assert encode_odometry(message) == expected
    assert decode_odometry(expected) == message


@given(TF_MESSAGES)
def test_any_tf_message_matches_pycdr2(message: TFMessage) -> None:
    expected = cdr(c_tf(message))
    assert encode_tf_message(message) == expected
    assert decode_tf_message(expected) == message


@pytest.mark.parametrize("names", [(), ("a",), ("front_left", "rear"), ("ünï", "b", "cd")])
def test_joint_state_matches_pycdr2_for_every_padding(names: tuple[str, ...]) -> None:
    n = len(names)
    message = JointState(Header(Time(1_700_000_000, 7), ""), names,
                         tuple(1.5 * k for k in range(n)), tuple(-0.25 * k for k in range(n)))
    expected = cdr(c_joints(message))
    assert encode_joint_state(message) == expected
    assert decode_joint_state(expected) == message


@given(JOINT_STATES)
def test_any_joint_state_matches_pycdr2(message: JointState) -> None:
    expected = cdr(c_joints(message))
    assert encode_joint_state(message) == expected
    assert decode_joint_state(expected) == message


@pytest.mark.parametrize(("success", "message"), [(True, ""), (False, "x"), (True, "state: estop"),
                                                  (False, "ünï")])
def test_trigger_matches_pycdr2(success: bool, message: str) -> None:
    assert encode_trigger_request() == cdr(CTriggerRequest(0))
    decode_trigger_request(cdr(CTriggerRequest(7)))  # (the placeholder means nothing)
    expected = cdr(CTriggerResponse(success, message))
    response = TriggerResponse(success, message)
    assert encode_trigger_response(response) == expected
    assert decode_trigger_response(expected) == response
