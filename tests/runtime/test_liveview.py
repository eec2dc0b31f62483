"""The live view (:mod:`gateway.runtime.liveview`): its MCAP recording (read back with the
``mcap`` package; protobuf by its wire format, https://protobuf.dev/programming-guides/encoding/),
its WebSocket server (RFC 6455 and the Foxglove protocol, https://github.com/foxglove/ws-protocol
docs/spec.md; loopback, port 0), bad data, SDK failures, start-up errors."""

from __future__ import annotations

import base64
import hashlib
import itertools
import json
import math
import os
import socket
import struct
import sys
import threading
import time
from typing import TYPE_CHECKING, Any

import pytest

from gateway.core.bridge_settings import FoxgloveSettings
from gateway.core.events import StatusEvent
from gateway.core.kinematics.odometry import OdometryState, Pose
from gateway.core.status import LastError
from gateway.core.types import ErrorCode, GatewayState, Twist
from gateway.runtime.liveview import INSTALL_HINT, LiveView, LiveViewError
from gateway.runtime.mailbox import Snapshot, SteerSample, WheelSample

if TYPE_CHECKING:
    from collections.abc import Callable, Iterator
    from pathlib import Path

EXTRA = "pip install 'wheelgate[foxglove]'"
pytest.importorskip("foxglove", reason=f"foxglove-sdk not installed: {EXTRA}")
make_reader = pytest.importorskip("mcap.reader", reason=f"mcap not installed: {EXTRA}").make_reader

WHEELS = ("left", "right")
STEERS = ("front steering",)
T0 = 1_700_000_000_123_456_789
WAIT_S = 5.0   # generous: a condition that holds at all holds within milliseconds
PER_SNAPSHOT = ("/tf", "/odom/pose", "/odom", "/wheels", "/steering", "/state")


def wait_for(condition: Callable[[], bool], what: str) -> None:
    deadline = time.monotonic() + WAIT_S
    while not condition():
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.001)


def snap(k: int, theta: float = 0.0, x: float | None = None, **over: Any) -> Snapshot:
    x = 0.1 * k if x is None else x
    fields: dict[str, Any] = {
        "stamp_ns": T0 + k * 20_000_000,
        "odometry": OdometryState(Pose(x, -0.05 * k, theta), Twist(0.5, 0.01 * k, -0.2), 0.001,
                                  0.1 * k, 10.0 + 0.02 * k),
        "state": GatewayState.RUNNING, "reason": "",
        "wheels": (WheelSample("left", 2.0 + k, 1.5 + k, 0.3 * k),
                   WheelSample("right", -1.0, None, None)),
        "steering": (SteerSample("front steering", 0.25, 0.2 + 0.01 * k),),
    }
    fields.update(over)
    return Snapshot(**fields)


def post_each(view: LiveView, snapshots: list[Snapshot]) -> None:
    """Post each once the worker took the one before (the mailbox keeps the newest only)."""
    for count, s in enumerate(snapshots, start=view.stats().snapshots + 1):
        view.mailbox.post(snapshot=s)
        wait_for(taken(view, count), f"the worker to take snapshot {count}")


def taken(view: LiveView, count: int) -> Callable[[], bool]:
    return lambda: view.stats().snapshots >= count


@pytest.fixture
def recording(tmp_path: Path) -> Iterator[tuple[LiveView, Path]]:
    path = tmp_path / "view.mcap"
    view = LiveView(FoxgloveSettings(), "rover", WHEELS, STEERS, record_mcap=str(path), serve=False)
    view.start()
    yield view, path
    view.close()


def read(path: Path) -> list[tuple[str, Any, str, int, bytes]]:
    """``(topic, schema, message encoding, log time, data)`` in log-time order."""
    with path.open("rb") as f:
        return [(c.topic, s, c.message_encoding, m.log_time, m.data)
                for s, c, m in make_reader(f).iter_messages(log_time_order=True)]


def fields(data: bytes) -> dict[int, list[Any]]:
    """A protobuf message's fields by number: varints, doubles, bytes (strings, messages)."""
    out: dict[int, list[Any]] = {}
    i = 0
    while i < len(data):
        key, i = _varint(data, i)
        number, wire = key >> 3, key & 7
        value: Any
        if wire == 0:
            value, i = _varint(data, i)
        elif wire == 1:
            value, i = struct.unpack_from("<d", data, i)[0], i + 8
        elif wire == 2:
            n, i = _varint(data, i)
            value, i = data[i:i + n], i + n
        else:
            raise AssertionError(f"unexpected wire type {wire}")
        out.setdefault(number, []).append(value)
    return out


def _varint(data: bytes, i: int) -> tuple[int, int]:
    value = shift = 0
    while True:
        b, i = data[i], i + 1
        value, shift = value | (b & 0x7F) << shift, shift + 7
        if b < 0x80:
            return value, i


def doubles(data: bytes, n: int) -> list[float]:
    """Fields 1..n of a Vector3/Quaternion (proto3 leaves zeros out)."""
    return [fields(data).get(k, [0.0])[0] for k in range(1, n + 1)]


def stamp(data: bytes) -> int:
    f = fields(data)
    return int(f.get(1, [0])[0]) * 1_000_000_000 + int(f.get(2, [0])[0])


# ----------------------------------------------------------------- the recording


def test_every_channel_is_recorded_with_its_schema(recording: tuple[LiveView, Path]) -> None:
    view, path = recording
    post_each(view, [snap(0)])
    view.mailbox.post(errors=(LastError(ErrorCode.MOTOR_FAULT, "left: overcurrent"),))
    wait_for(lambda: view.stats().errors == 1, "the error")
    view.close()
    messages = read(path)
    got = {topic: (schema.name, schema.encoding, enc) for topic, schema, enc, _, _ in messages}
    assert got == {
        "/tf": ("foxglove.FrameTransforms", "protobuf", "protobuf"),
        "/odom/pose": ("foxglove.PoseInFrame", "protobuf", "protobuf"),
        "/errors": ("foxglove.Log", "protobuf", "protobuf"),
        "/odom": ("wheelgate.Odometry", "jsonschema", "json"),
        "/wheels": ("wheelgate.Wheels", "jsonschema", "json"),
        "/steering": ("wheelgate.Steering", "jsonschema", "json"),
        "/state": ("wheelgate.State", "jsonschema", "json"),
    }
    # The Foxglove app reads a type as one name (it rejects ["number", "null"]).
    schemas = {t: json.loads(s.data) for t, s, enc, _, _ in messages if enc == "json"}

    def leaves(schema: dict[str, Any]) -> Iterator[Any]:
        for prop in schema["properties"].values():
            yield from leaves(prop) if prop["type"] == "object" else [prop["type"]]

    assert all(isinstance(t, str) for s in schemas.values() for t in leaves(s))
    assert set(schemas["/wheels"]["properties"]) == set(WHEELS)
    assert set(schemas["/steering"]["properties"]) == set(STEERS)


def test_values_round_trip_once_per_snapshot(recording: tuple[LiveView, Path]) -> None:
    view, path = recording
    thetas = [0.0, 0.4, -2.5, math.pi / 2, 3.0]
    snaps = [snap(k, theta) for k, theta in enumerate(thetas)]
    post_each(view, snaps)
    view.close()
    messages = read(path)
    for topic in PER_SNAPSHOT:
        stamps = [t for top, _, _, t, _ in messages if top == topic]
        assert stamps == [s.stamp_ns for s in snaps], topic
    by_topic = {t: [d for top, _, _, _, d in messages if top == t] for t in PER_SNAPSHOT}
    for s, theta, tf, pose, odom, wheels, steering, state in zip(
            snaps, thetas, by_topic["/tf"], by_topic["/odom/pose"], by_topic["/odom"],
            by_topic["/wheels"], by_topic["/steering"], by_topic["/state"], strict=True):
        p = s.odometry.pose
        q = [0.0, 0.0, math.sin(theta / 2), math.cos(theta / 2)]
        tr, in_frame = fields(fields(tf)[1][0]), fields(pose)
        pose_of = fields(in_frame[3][0])
        assert stamp(tr[1][0]) == stamp(in_frame[1][0]) == s.stamp_ns
        assert (tr[2][0], tr[3][0], in_frame[2][0]) == (b"odom", b"base_link", b"odom")
        for xyz, rotation in ((tr[4][0], tr[5][0]), (pose_of[1][0], pose_of[2][0])):
            assert doubles(xyz, 3) == pytest.approx([p.x_m, p.y_m, 0.0])
            assert doubles(rotation, 4) == pytest.approx(q)
        o = json.loads(odom)
        assert o["pose"] == {"x_m": p.x_m, "y_m": p.y_m, "theta_rad": theta}
        assert o["twist"] == {"vx_m_s": 0.5, "vy_m_s": s.odometry.twist.vy_m_s, "wz_rad_s": -0.2}
        assert (o["slip_m_s"], o["distance_m"]) == (0.001, s.odometry.distance_m)
        assert json.loads(wheels) == {
            "left": {"commanded_rad_s": s.wheels[0].commanded_rad_s,
                     "measured_rad_s": s.wheels[0].measured_rad_s,
                     "position_rad": s.wheels[0].position_rad},
            "right": {"commanded_rad_s": -1.0, "measured_rad_s": None, "position_rad": None},
        }
        assert json.loads(steering) == {"front steering": {
            "commanded_rad": 0.25, "measured_rad": s.steering[0].measured_rad}}
        assert json.loads(state) == {"state": "running", "code": 2, "reason": ""}


def test_errors_in_order_and_a_state_without_a_snapshot(recording: tuple[LiveView, Path]) -> None:
    view, path = recording
    sent = [LastError(ErrorCode(1 + k % 9), f"error number {k}") for k in range(12)]
    for k in range(0, len(sent), 3):
        view.mailbox.post(errors=tuple(sent[k:k + 3]))
    view.mailbox.post(status=StatusEvent(GatewayState.ESTOP, "button"))
    wait_for(lambda: view.stats().errors == len(sent), "every error")
    view.close()
    messages = read(path)
    logs = [fields(d) for t, _, _, _, d in messages if t == "/errors"]
    assert [f[3][0].decode() for f in logs] == [
        f"{e.code.name.lower()}: {e.message}" for e in sent]
    assert {f[2][0] for f in logs} == {4}   # foxglove.LogLevel.Error
    assert {f[4][0] for f in logs} == {b"rover"}
    states = [json.loads(d) for t, _, _, _, d in messages if t == "/state"]
    assert states == [{"state": "estop", "code": 4, "reason": "button"}]


# ----------------------------------------------------------------- bad data, failures


def test_bad_data_is_null_and_the_worker_goes_on(recording: tuple[LiveView, Path],
                                                  caplog: pytest.LogCaptureFixture) -> None:
    view, path = recording
    nan = float("nan")
    bad = [
        snap(0, x=nan),                                               # pose not finite
        snap(1, wheels=(WheelSample("left", math.inf, nan, None),)),  # speeds not finite
        snap(2, stamp_ns=-1),                                         # not a time
        snap(3, odometry=None),                                       # not an odometry at all
    ]
    post_each(view, [*bad, snap(4)])
    assert view._thread is not None and view._thread.is_alive()
    view.close()
    messages = read(path)
    tf = [t for top, _, _, t, _ in messages if top == "/tf"]   # the clock's stamp sorts last
    assert tf[:2] == [snap(1).stamp_ns, snap(4).stamp_ns] and tf[2] > T0 + 10**9
    at = {(top, t): json.loads(d) for top, _, _, t, d in messages if top in ("/wheels", "/odom")}
    assert at["/wheels", snap(1).stamp_ns] == {"left": dict.fromkeys(
        ("commanded_rad_s", "measured_rad_s", "position_rad"))}
    assert at["/odom", snap(0).stamp_ns]["pose"]["x_m"] is None
    stats = view.stats()
    assert (stats.snapshots, stats.bad_data) == (5, 3)
    assert stats.failures >= 2   # /tf and /odom of the snapshot without an odometry
    assert "'NoneType' object has no attribute" in caplog.text


def test_a_failing_channel_is_logged_once_and_the_others_go_on(
        recording: tuple[LiveView, Path], caplog: pytest.LogCaptureFixture) -> None:
    view, path = recording

    class Broken:
        def log(self, *args: object, **kwargs: object) -> None:
            raise RuntimeError("the SDK said no")

    view._channels._wheels = Broken()
    post_each(view, [snap(k) for k in range(3)])
    view.close()
    topics = [t for t, _, _, _, _ in read(path)]
    assert "/wheels" not in topics
    assert topics.count("/odom") == topics.count("/tf") == 3
    failures = [r.getMessage() for r in caplog.records if "/wheels" in r.getMessage()]
    assert len(failures) == 1 and "the SDK said no" in failures[0]
    assert view.stats().failures == 3


# ----------------------------------------------------------------- life cycle, start-up errors


def test_close_publishes_what_is_pending_and_ends_the_worker(tmp_path: Path) -> None:
    view = LiveView(FoxgloveSettings(port=0), "rover", WHEELS, record_mcap=str(tmp_path / "a.mcap"))
    slow = view._channels.wheels

    def wheels(*args: Any) -> None:
        time.sleep(0.2)
        slow(*args)

    view._channels.per_snapshot[3] = ("/wheels", wheels)
    view.start()
    view.mailbox.post(snapshot=snap(0))
    view.close()   # waits for the worker, which is still publishing
    view.close()
    assert view.stats().snapshots == 1
    assert not any(t.name == "wheelgate-liveview" for t in threading.enumerate())
    # The file was finished: the reader seeks its summary first.
    assert [t for t, _, _, _, _ in read(tmp_path / "a.mcap")].count("/wheels") == 1


def test_start_up_errors_name_what_is_wrong(tmp_path: Path,
                                           monkeypatch: pytest.MonkeyPatch) -> None:
    old = tmp_path / "old.mcap"
    old.write_bytes(b"an earlier recording")
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        with pytest.raises(LiveViewError, match=f"cannot serve .* on 127.0.0.1:{port}"):
            LiveView(FoxgloveSettings(port=port, mcap=str(old)), "rover", WHEELS)
    assert old.read_bytes() == b"an earlier recording"   # the server fails first
    with pytest.raises(LiveViewError, match="expected a file in an existing directory"):
        LiveView(FoxgloveSettings(mcap=str(tmp_path / "no" / "a.mcap")), "rover", WHEELS,
                 serve=False)
    with pytest.raises(LiveViewError, match="nothing to do"):
        LiveView(FoxgloveSettings(), "rover", WHEELS, serve=False)
    monkeypatch.setitem(sys.modules, "foxglove", None)
    with pytest.raises(LiveViewError, match="foxglove-sdk package is not installed") as err:
        LiveView(FoxgloveSettings(port=0), "rover", WHEELS)
    assert INSTALL_HINT in str(err.value)


# ----------------------------------------------------------------- the WebSocket server


class WsClient:
    """Just enough of RFC 6455: the handshake, the server's frames, masked text frames."""

    def __init__(self, port: int) -> None:
        self.sock = socket.create_connection(("127.0.0.1", port), timeout=WAIT_S)
        key = base64.b64encode(os.urandom(16)).decode()
        self.sock.sendall(
            f"GET / HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\n"
            f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n"
            "Sec-WebSocket-Protocol: foxglove.sdk.v1\r\n\r\n".encode())
        self.buf = b""
        while b"\r\n\r\n" not in self.buf:
            self._recv()
        head, self.buf = self.buf.split(b"\r\n\r\n", 1)
        accept = base64.b64encode(hashlib.sha1(
            (key + "258EAFA5-E914-47DA-95CA-C5AB0DC85B11").encode()).digest())
        assert head.startswith(b"HTTP/1.1 101"), head
        assert accept in head and b"foxglove.sdk.v1" in head, head

    def _recv(self) -> None:
        chunk = self.sock.recv(65536)
        assert chunk, "the server closed the connection"
        self.buf += chunk

    def frame(self) -> tuple[int, bytes]:
        """The next data frame, (opcode, payload), taken whole (a timeout loses nothing)."""
        while True:
            b, i = self.buf, 2
            n = b[1] & 0x7F if len(b) >= 2 else 0
            if n >= 126:
                i += 2 if n == 126 else 8
                n = int.from_bytes(b[2:i], "big") if len(b) >= i else 0
            if len(b) < 2 or len(b) < i + n:
                self._recv()
                continue
            self.buf = b[i + n:]
            if b[0] & 0x0F in (1, 2):   # text, binary (control frames skipped)
                return b[0] & 0x0F, b[i:i + n]

    def send_json(self, message: object) -> None:
        data = json.dumps(message).encode()
        assert len(data) < 126
        mask = os.urandom(4)
        self.sock.sendall(bytes([0x81, 0x80 | len(data)]) + mask
                          + bytes(b ^ mask[i % 4] for i, b in enumerate(data)))


def test_server_advertises_the_channels_and_sends_a_posted_snapshot() -> None:
    with LiveView(FoxgloveSettings(port=0), "rover", WHEELS, STEERS) as view:
        assert view.url.startswith("ws://127.0.0.1:") and not view.url.endswith(":0")
        client = WsClient(int(view.url.rsplit(":", 1)[1]))
        try:
            channels: dict[str, dict[str, Any]] = {}
            while len(channels) < 8:
                opcode, data = client.frame()
                message = json.loads(data) if opcode == 1 else {}
                if message.get("op") == "advertise":
                    channels.update({c["topic"]: c for c in message["channels"]})
            assert set(channels) == {*PER_SNAPSHOT, "/errors", "/diagnostics"}
            assert channels["/tf"]["schemaName"] == "foxglove.FrameTransforms"
            assert channels["/diagnostics"]["schemaEncoding"] == "ros2msg"  # (CDR messages)
            assert channels["/odom"]["encoding"] == "json"
            client.send_json({"op": "subscribe",
                              "subscriptions": [{"id": 7, "channelId": channels["/odom"]["id"]}]})
            client.sock.settimeout(0.05)
            deadline = time.monotonic() + WAIT_S
            for k in itertools.count():   # the subscription takes effect a little later
                view.mailbox.post(snapshot=snap(k))
                try:
                    opcode, data = client.frame()
                except TimeoutError:
                    assert time.monotonic() < deadline, "no message after the subscription"
                    continue
                if opcode == 2:
                    break
        finally:
            client.sock.close()
    op, sub, log_time = struct.unpack_from("<BIQ", data)
    assert (op, sub) == (1, 7)
    assert T0 <= log_time <= snap(k).stamp_ns
    assert json.loads(data[13:])["pose"]["x_m"] == pytest.approx(
        (log_time - T0) / 20_000_000 * 0.1)
    assert not any(t.name == "wheelgate-liveview" for t in threading.enumerate())
