"""A peer of the Zenoh bridge, for the bridge's process tests and ``bench_bridge.py``: a
commander that holds a liveliness token and publishes twists until it is killed; and the
loopback session the observers use.

Run as ``python tools/bridge_peer.py commander --connect tcp/127.0.0.1:7447 --ns robot1
--name teleop1 --vx 0.3 [--lease 1.0]``: prints ``ready`` once its token is declared and its
first twist sent, then publishes one every 50 ms for ever.  A real commander does the same:
hold ``wheelgate/<ns>/commander/<name>`` while it commands, and attach its name to each twist.
``python tools/bridge_peer.py observe --connect ... --ns robot1`` subscribes to the gateway's
odometry, status and errors until its stdin closes, then prints how many of each came.
``python tools/bridge_peer.py ros-node --connect ... [--cmd-vel /robot1/cmd_vel] [--stamped]``
is a ROS 2 node on rmw_zenoh as the wire shows it (no ROS installed): see :func:`ros_node`;
``ros-call --connect ... --service /robot1/wheelgate/estop`` calls a ``std_srvs/srv/Trigger``
service as a ROS client does (:func:`ros_call`).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import socket
import subprocess
import sys
import threading
import time
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from gateway.core.settings import GatewayConfig


def free_port() -> int:
    """A TCP port free on the loopback now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port: int = s.getsockname()[1]
        return port


def session(connect: str, lease_s: float = 10.0) -> Any:
    """A peer session that connects to ``connect``, listens nowhere and does not scout."""
    import zenoh  # noqa: PLC0415 - only where Zenoh is installed

    config = zenoh.Config()
    for key, value in {"mode": "peer", "listen/endpoints": [], "connect/endpoints": [connect],
                       "scouting/multicast/enabled": False,
                       "transport/link/tx/lease": round(lease_s * 1000)}.items():
        config.insert_json5(key, json.dumps(value))
    return zenoh.open(config)


def commander(args: argparse.Namespace) -> None:
    s = session(args.connect, args.lease)
    root = f"wheelgate/{args.ns}"
    token = s.liveliness().declare_token(f"{root}/commander/{args.name}")
    pub = s.declare_publisher(f"{root}/cmd/twist")
    line = json.dumps({"op": "twist", "vx": args.vx})
    pub.put(line, attachment=args.name.encode())
    sys.stdout.write("ready\n")
    sys.stdout.flush()
    while True:
        time.sleep(0.05)
        pub.put(line, attachment=args.name.encode())
    del token  # unreachable: the process is killed


def ros_node(args: argparse.Namespace) -> None:
    """A ROS 2 node as rmw_zenoh puts it on the wire (:mod:`gateway.wire.ros2`): its tokens, a
    ``Twist`` (or ``TwistStamped``) publisher on ``--cmd-vel`` sending every 50 ms, and
    subscriptions to ``--odom``, ``/tf``, with ``--joints`` that topic's joint states and with
    ``--diagnostics`` that topic's diagnostics (on the exact key, the type's hash in it, as a
    Jazzy subscriber); prints ``ready``, then one JSON line per message received."""
    from gateway.wire import ros2  # noqa: PLC0415 - the bridge's own wire layer

    s = session(args.connect, args.lease)
    zid = str(s.zid())
    kind = ros2.TWIST_STAMPED if args.stamped else ros2.TWIST
    token = ros2.entity_token(ros2.EntityKind.PUBLISHER, args.domain, zid, 0, 1, "/", "teleop",
                              args.cmd_vel, kind, ros2.QosProfile())
    keep = [s.liveliness().declare_token(ros2.node_token(args.domain, zid, 0, "/", "teleop")),
            s.liveliness().declare_token(token)]
    gid = ros2.gid_of(token)
    key = ros2.topic_key(args.domain, args.cmd_vel, kind)
    if args.humble:
        key = key.rsplit("/", 1)[0] + "/" + ros2.HUMBLE_TYPE_HASH
    pub = s.declare_publisher(key)

    # The subscriptions' callbacks run on Zenoh's threads and may fire (the gateway publishes
    # all the time) before this thread has printed ``ready``: they print nothing until it has,
    # and one line at a time, so that ``ready`` is always the first line.
    out = threading.Lock()
    started = False

    def show(what: str, data: dict[str, object]) -> None:
        if args.quiet:
            return
        with out:
            if started:
                sys.stdout.write(json.dumps({"topic": what, **data}) + "\n")
                sys.stdout.flush()

    def on_odom(sample: Any) -> None:
        o = ros2.decode_odometry(sample.payload.to_bytes())
        a = ros2.decode_attachment(sample.attachment.to_bytes())
        show("odom", {"frame": o.header.frame_id, "child": o.child_frame_id,
                      "vx": o.twist.linear_x, "wz": o.twist.angular_z, "x": o.position.x,
                      "seq": a.sequence_number, "layout": a.layout.value,
                      "pose_variances": o.pose_covariance[::7],
                      "twist_variances": o.twist_covariance[::7],
                      "off_diagonal": any(v for i, v in enumerate(
                          (*o.pose_covariance, *o.twist_covariance)) if i % 36 % 7)})

    def on_tf(sample: Any) -> None:
        t = ros2.decode_tf_message(sample.payload.to_bytes()).transforms[0]
        show("tf", {"frame": t.header.frame_id, "child": t.child_frame_id,
                    "x": t.translation.x, "qz": t.rotation.z, "qw": t.rotation.w})

    def on_joints(sample: Any) -> None:
        j = ros2.decode_joint_state(sample.payload.to_bytes())
        show("joints", {"names": list(j.name), "position": list(j.position),
                        "velocity": [None if math.isnan(v) else v for v in j.velocity]})

    def on_diagnostics(sample: Any) -> None:
        d = ros2.decode_diagnostic_array(sample.payload.to_bytes())
        show("diagnostics", {"key": str(sample.key_expr), "statuses": [
            {"level": int(x.level), "name": x.name, "message": x.message,
             "hardware_id": x.hardware_id, "values": {v.key: v.value for v in x.values}}
            for x in d.status]})

    if args.joints:
        keep.append(s.declare_subscriber(ros2.topic_subscription_key(
            args.domain, args.joints, ros2.JOINT_STATE), on_joints))
    if args.diagnostics:
        keep.append(s.declare_subscriber(ros2.topic_key(
            args.domain, args.diagnostics, ros2.DIAGNOSTIC_ARRAY), on_diagnostics))
    keep += [s.declare_subscriber(ros2.topic_subscription_key(args.domain, args.odom,
                                                              ros2.ODOMETRY), on_odom),
             s.declare_subscriber(ros2.topic_subscription_key(args.domain, "/tf",
                                                              ros2.TF_MESSAGE), on_tf)]
    twist = ros2.Twist3D(args.vx, 0.0, 0.0, 0.0, 0.0, args.wz)
    layout = ros2.AttachmentFormat.LABELLED if args.labelled else ros2.AttachmentFormat.POSITIONAL
    seq = 0
    with out:
        sys.stdout.write("ready\n")
        sys.stdout.flush()
        started = True
    while True:
        seq += 1
        now = time.time_ns()
        payload = ros2.encode_twist_stamped(ros2.TwistStamped(
            ros2.Header(ros2.ns_to_stamp(now), "base_link"), twist)) if args.stamped \
            else ros2.encode_twist(twist)
        pub.put(payload, attachment=ros2.encode_attachment(seq, now, gid, layout))
        time.sleep(0.05)


def ros_call(args: argparse.Namespace) -> None:
    """A ROS 2 client's call of a ``std_srvs/srv/Trigger`` service as rmw_zenoh puts it on the
    wire (a query on the service's key, the request's sequence number, time and the client's
    GID in the attachment); prints one JSON line per reply: the response, and whether the
    reply's attachment carries the request's sequence number and GID back."""
    from gateway.wire import ros2  # noqa: PLC0415 - the bridge's own wire layer

    s = session(args.connect, args.lease)
    zid = str(s.zid())
    token = ros2.entity_token(ros2.EntityKind.CLIENT, args.domain, zid, 0, 1, "/", "caller",
                              args.service, ros2.TRIGGER, ros2.QosProfile())
    keep = s.liveliness().declare_token(token)
    gid, seq = ros2.gid_of(token), 41
    payload = b"\x00\x01\x00" if args.bad_request else ros2.encode_trigger_request()
    replies = s.get(ros2.topic_key(args.domain, args.service, ros2.TRIGGER), payload=payload,
                    attachment=ros2.encode_attachment(seq, time.time_ns(), gid),
                    timeout=10.0)
    for reply in replies:
        if reply.ok is None:
            sys.stdout.write(json.dumps({"error": str(reply.err)}) + "\n")
            continue
        response = ros2.decode_trigger_response(reply.ok.payload.to_bytes())
        attachment = ros2.decode_attachment(reply.ok.attachment.to_bytes())
        sys.stdout.write(json.dumps({
            "success": response.success, "message": response.message,
            "seq": attachment.sequence_number == seq, "gid": attachment.gid == gid}) + "\n")
    sys.stdout.flush()
    keep.undeclare()
    s.close()


def observe(args: argparse.Namespace) -> None:
    """Subscribe to the gateway's news until stdin closes; print how many samples came."""
    s = session(args.connect, args.lease)
    root = f"wheelgate/{args.ns}"
    counts = dict.fromkeys(("odom", "status", "error"), 0)

    def count(sample: Any) -> None:
        counts[str(sample.key_expr).rsplit("/", 1)[-1]] += 1

    subs = [s.declare_subscriber(f"{root}/{key}", count) for key in counts]
    sys.stdout.write("ready\n")
    sys.stdout.flush()
    sys.stdin.read()
    for sub in subs:
        sub.undeclare()
    sys.stdout.write(json.dumps(counts) + "\n")
    s.close()


def with_bridge(cfg: GatewayConfig) -> tuple[GatewayConfig, subprocess.Popen[str]]:
    """The configuration with a loopback bridge, and the observer process subscribed to it."""
    from gateway.core.bridge_settings import (  # noqa: PLC0415 - only with --bridge
        BridgeSettings,
        Ros2Settings,
        ZenohSettings,
    )

    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    cfg = dataclasses.replace(cfg, bridge=BridgeSettings(
        ZenohSettings(listen=(endpoint,)), "bench", Ros2Settings()))
    observer = subprocess.Popen(
        [sys.executable, __file__, "observe",
         "--connect", endpoint, "--ns", "bench"],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    return cfg, observer


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    sub = parser.add_subparsers(dest="role", required=True)
    c = sub.add_parser("commander")
    c.add_argument("--connect", required=True)
    c.add_argument("--ns", required=True)
    c.add_argument("--name", required=True)
    c.add_argument("--vx", type=float, default=0.3)
    c.add_argument("--lease", type=float, default=10.0)
    r = sub.add_parser("ros-node")
    r.add_argument("--connect", required=True)
    r.add_argument("--domain", type=int, default=0)
    r.add_argument("--cmd-vel", default="/cmd_vel")
    r.add_argument("--odom", default="/odom")
    r.add_argument("--joints", default="", help="also read sensor_msgs/msg/JointState here")
    r.add_argument("--diagnostics", default="",
                   help="also read diagnostic_msgs/msg/DiagnosticArray here")
    r.add_argument("--vx", type=float, default=0.3)
    r.add_argument("--wz", type=float, default=0.0)
    r.add_argument("--stamped", action="store_true", help="TwistStamped instead of Twist")
    r.add_argument("--humble", action="store_true", help="Humble's TypeHashNotSupported key")
    r.add_argument("--labelled", action="store_true",
                   help="the labelled attachment of Jazzy's rmw_zenoh 0.2.0 to 0.2.3")
    r.add_argument("--quiet", action="store_true", help="print nothing after 'ready'")
    r.add_argument("--lease", type=float, default=10.0)
    k = sub.add_parser("ros-call")
    k.add_argument("--connect", required=True)
    k.add_argument("--domain", type=int, default=0)
    k.add_argument("--service", required=True, help="e.g. /robot1/wheelgate/estop")
    k.add_argument("--bad-request", action="store_true", help="a request cut short")
    k.add_argument("--lease", type=float, default=10.0)
    o = sub.add_parser("observe")
    o.add_argument("--connect", required=True)
    o.add_argument("--ns", required=True)
    o.add_argument("--lease", type=float, default=10.0)
    args = parser.parse_args(argv)
    {"commander": commander, "ros-node": ros_node, "ros-call": ros_call,
     "observe": observe}[args.role](args)


if __name__ == "__main__":
    main(sys.argv[1:])
