"""The ROS 2 joint states of a snapshot (``gateway.runtime.bridge.ros2.joint_state``): every
wheel and steering actuator heard so far, under its joint name, encoded as rmw_zenoh carries
it."""

from __future__ import annotations

import math

from gateway.core.kinematics.odometry import OdometryState, Pose
from gateway.core.types import GatewayState, Twist
from gateway.runtime.bridge.ros2 import joint_state
from gateway.runtime.mailbox import Snapshot, SteerSample, WheelSample
from gateway.wire.ros2 import Time, decode_joint_state, encode_joint_state


def snapshot(wheels: tuple[WheelSample, ...], steering: tuple[SteerSample, ...] = ()) -> Snapshot:
    state = OdometryState(Pose(), Twist(), 0.0, 0.0, 0.0)
    return Snapshot(1_700_000_000_250_000_000, state, GatewayState.RUNNING, "", wheels, steering)


def test_wheels_and_steering_under_their_joint_names() -> None:
    snap = snapshot(
        (WheelSample("rear_left", 1.0, 2.0, 10.5), WheelSample("rear_right", 1.0, None, None),
         WheelSample("front", 1.0, 2.5, -3.0)),
        (SteerSample("front steering", 0.1, 0.12), SteerSample("other", 0.0, None)))
    js = joint_state(snap, {"rear_left": "rear_left_wheel_joint",
                            "front steering": "front_steer_joint"})
    assert js.header.stamp == Time(1_700_000_000, 250_000_000)
    assert js.name == ("rear_left_wheel_joint", "front", "front_steer_joint")  # unheard: out
    assert js.position == (10.5, -3.0, 0.12)
    assert js.velocity[:2] == (2.0, 2.5) and math.isnan(js.velocity[2])  # not measured
    assert js.effort == ()
    back = decode_joint_state(encode_joint_state(js))
    assert back.name == js.name and back.position == js.position


def test_nothing_heard_yet_is_an_empty_message() -> None:
    js = joint_state(snapshot((WheelSample("rear_left", 0.0, None, None),)), {})
    assert (js.name, js.position, js.velocity) == ((), (), ())
    assert decode_joint_state(encode_joint_state(js)).name == ()
