"""Fuzzing of the gateway's own inputs: CAN twists, configuration files, the control socket.

* **CAN twist input** (``WG_Twist_Cmd`` on a running gateway with its simulators, on simulated
  time): random payloads, lengths, remote frames, reserved flag bits, extreme values.  Never
  raises; every malformed frame is counted (``bad_can_twists``) and answered with a
  ``WG_Error`` ``BAD_COMMAND``; every valid one is counted as a twist or a duplicate; and the
  wheels stay at zero unless a valid, feasible, non-zero twist without flags arrived.
* **Configuration**: random YAML-able documents, mutations of every shipped configuration
  (keys deleted, types changed, keys added, NaN / infinity / huge values), random bytes in a
  file, random bus overrides: ``parse_config`` / ``load_config`` raise ``ConfigError`` only.
* **Control socket**: structure-aware mutations of valid requests (huge numbers, NaN and
  infinity literals, deep nesting, unicode, duplicate and unknown keys, truncation) through
  ``parse_request``: a request or ``ProtocolError``, and the reply to either encodes; and end
  to end, a daemon on simulated time answers every garbage line with a ``bad_command`` error
  and changes nothing else (state, wheel speeds, odometry, counters but the parse errors).
"""

from __future__ import annotations

import contextlib
import dataclasses
import itertools
import json
import math
import os
import shutil
import struct
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pytest
import yaml
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from gateway.bus.can_bus import drain, send_frames
from gateway.config import load_config, parse_config
from gateway.core.errors import ConfigError, DecodeError
from gateway.core.types import ErrorCode, Frame, GatewayState, Twist
from gateway.wire.can import TwistFlags
from gateway.wire.socket import (
    MAX_TWIST_COMPONENT,
    ProtocolError,
    ResetOdometryRequest,
    TwistRequest,
    parse_request,
    reply_ok,
    reply_protocol_error,
)
from tests.conftest import CONFIG_DIR
from tests.e2e_helpers import Rig, SocketPilot, virtual_config

if TYPE_CHECKING:
    from collections.abc import Iterator

FUZZ = settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])
_channels = itertools.count()

#: ``WG_Twist_Cmd`` as ``config/wheelgate.dbc`` lays it out: vx, vy (mm/s), wz (mrad/s),
#: counter, flags.
TWIST_LAYOUT = struct.Struct("<hhhBB")
TWIST_FLAG_BITS = 0x07
I16 = st.integers(-(2**15), 2**15 - 1)
I16_EXTREMES = st.sampled_from([-(2**15), -(2**15) + 1, -1, 0, 1, 2**15 - 1])


@contextlib.contextmanager
def running(path: Path, socket_path: str | None = None) -> Iterator[Rig]:
    """A rig of ``path`` on its own virtual channel, enabled, RUNNING and stopped."""
    cfg = virtual_config(path, f"wg-fuzz-{next(_channels)}", rate_hz=100.0)
    with Rig(cfg, socket_path) as rig:
        rig.enable()
        rig.advance(0.05)
        assert rig.gw.state is GatewayState.RUNNING
        assert all(w == 0.0 for w in rig.gw.prev.wheel_rad_s)
        yield rig


@contextlib.contextmanager
def socket_dir() -> Iterator[str]:
    """A short socket path in a private directory (AF_UNIX paths are short)."""
    folder = tempfile.mkdtemp(prefix="wgfz", dir="/tmp")
    try:
        yield f"{folder}/s.sock"
    finally:
        shutil.rmtree(folder, ignore_errors=True)


# =============================================================================== CAN twists


@st.composite
def bad_twist_payloads(draw: st.DrawFn) -> tuple[bytes, bool, int]:
    """(data, remote, dlc) of a malformed ``WG_Twist_Cmd``."""
    kind = draw(st.sampled_from(["remote", "length", "flags"]))
    if kind == "remote":
        return b"", True, draw(st.integers(0, 8))
    if kind == "length":
        data = draw(st.binary(max_size=7))
        return data, False, len(data)
    head = draw(st.binary(min_size=7, max_size=7))
    flags = draw(st.integers(0, 255).filter(lambda f: f & ~TWIST_FLAG_BITS))
    return head + bytes([flags]), False, 8


@st.composite
def any_twist_payloads(draw: st.DrawFn) -> tuple[bytes, bool, int]:
    """(data, remote, dlc) of any ``WG_Twist_Cmd``: malformed, random, or well formed with
    extreme or small values, any counter, and flags mostly clear."""
    kind = draw(st.sampled_from(["bad", "random", "valid", "valid"]))
    if kind == "bad":
        return draw(bad_twist_payloads())
    if kind == "random":
        return draw(st.binary(min_size=8, max_size=8)), False, 8
    values = draw(st.lists(I16_EXTREMES | I16 | st.integers(-400, 400), min_size=3, max_size=3))
    if draw(st.booleans()):
        values[1] = 0  # no sideways speed: feasible for car-like and differential robots too
    flags = draw(st.sampled_from([0, 0, 0, 1, 2, 4, 3, 7]))
    data = TWIST_LAYOUT.pack(*values, draw(st.integers(0, 255)), flags)
    return data, False, 8


def twist_frame(rig: Rig, payload: tuple[bytes, bool, int]) -> Frame:
    data, remote, dlc = payload
    ids = rig.gw.wg.ids
    return Frame(ids.twist, data, ids.extended, remote, dlc)


def bad_command_errors(rig: Rig) -> int:
    """``WG_Error`` frames with code ``BAD_COMMAND`` the pilot has received since last asked."""
    count = 0
    for frame in drain(rig.pilot):
        with contextlib.suppress(DecodeError):
            report = rig.gw.wg.decode_error(frame)
            count += report is not None and report.code is ErrorCode.BAD_COMMAND
    return count


def assert_wheels_within_limits(rig: Rig) -> None:
    for w, m in zip(rig.gw.prev.wheel_rad_s, rig.config.motors, strict=True):
        assert math.isfinite(w)
        if m is not None:
            assert abs(w) <= m.max_wheel_rad_s * (1 + 1e-9)


@FUZZ
@given(payloads=st.lists(bad_twist_payloads(), min_size=1, max_size=12))
def test_malformed_can_twists_are_counted_answered_and_never_move(
    payloads: list[tuple[bytes, bool, int]],
) -> None:
    with running(CONFIG_DIR / "turtlebot3_burger.yaml") as rig:
        counts = dataclasses.replace(rig.gw.counts)
        bad_command_errors(rig)
        speeds: list[tuple[float, ...]] = []
        for payload in payloads:
            send_frames(rig.pilot, [twist_frame(rig, payload)])
            rig.advance(rig.period, lambda r: speeds.append(r.gw.prev.wheel_rad_s))
        rig.advance(0.05, lambda r: speeds.append(r.gw.prev.wheel_rad_s))
        assert rig.gw.counts.bad_can_twists == counts.bad_can_twists + len(payloads)
        assert rig.gw.counts.can_twists == counts.can_twists
        assert bad_command_errors(rig) == len(payloads)
        assert rig.gw.state is GatewayState.RUNNING
        assert all(w == 0.0 for s in speeds for w in s)


@pytest.mark.parametrize("robot", ["turtlebot3_burger.yaml", "ackermann.yaml"])
@FUZZ
@given(payloads=st.lists(any_twist_payloads(), min_size=1, max_size=12))
def test_the_robot_moves_only_on_a_valid_feasible_twist(
    robot: str, payloads: list[tuple[bytes, bool, int]]
) -> None:
    with running(CONFIG_DIR / robot) as rig:
        counts = dataclasses.replace(rig.gw.counts)
        bad_command_errors(rig)
        model, wg = rig.config.model, rig.gw.wg
        bad = valid = 0
        may_move = False
        speeds: list[tuple[float, ...]] = []
        for payload in payloads:
            frame = twist_frame(rig, payload)
            try:
                cmd = wg.decode_twist(frame)
            except DecodeError:
                bad += 1
            else:
                assert cmd is not None
                valid += 1
                may_move |= (
                    cmd.flags is TwistFlags.NONE
                    and cmd.twist != Twist()
                    and model.feasible(cmd.twist, rig.gw.prev.steer_rad)
                )
            send_frames(rig.pilot, [frame])
            rig.advance(rig.period, lambda r: speeds.append(r.gw.prev.wheel_rad_s))
            assert_wheels_within_limits(rig)
        rig.advance(0.05, lambda r: speeds.append(r.gw.prev.wheel_rad_s))
        now = rig.gw.counts
        assert now.bad_can_twists - counts.bad_can_twists == bad
        assert (now.can_twists - counts.can_twists
                + now.can_duplicates - counts.can_duplicates) == valid
        assert bad_command_errors(rig) == bad
        if not may_move:
            assert all(w == 0.0 for s in speeds for w in s), "moved without a feasible twist"


# =============================================================================== configuration

SHIPPED = sorted(CONFIG_DIR.glob("*.yaml"))
KEYS = sorted({
    "name", "drive", "geometry", "wheels", "motors", "motor_defaults", "limits", "kinematics",
    "bus", "gateway", "wheel_radius", "track", "wheelbase", "driver", "node_id", "gear_ratio",
    "max_rpm", "invert", "firmware", "extended_id", "pole_pairs", "esc", "dbc", "interface",
    "channel", "bitrate", "rate_hz", "can_ids", "twist", "type", "alpha", "l", "beta",
    "radius", "motor", "left", "right", "max_steer", "wheel_count", "wheel_distance",
})
DRIVES = ["differential", "skid_steer", "synchro", "tricycle", "ackermann", "omni", "mecanum",
          "swerve", "generic"]
scalars = (
    st.none()
    | st.booleans()
    | st.integers(-(10**30), 10**30)
    | st.sampled_from([0, 1, 2, 3, 63, 0x7FF, 2**31, 2**64, -1])
    | st.floats()
    | st.sampled_from([math.nan, math.inf, -math.inf, 1e308, -1e308, 5e-324, 1e-9, -0.0])
    | st.text(max_size=12)
    | st.sampled_from([*DRIVES, "odrive", "vesc", "dji", "cia402", "dbc", "0.6", "c620", ""])
)
yaml_docs = st.recursive(
    scalars,
    lambda children: st.lists(children, max_size=4)
    | st.dictionaries(st.sampled_from(KEYS) | st.text(max_size=6) | st.integers(), children,
                      max_size=6),
    max_leaves=25,
)


def parse_or_config_error(doc: object, source: str) -> None:
    try:
        cfg = parse_config(doc, source)
    except ConfigError as err:
        assert str(err)
    else:
        assert cfg.model.wheels


@FUZZ
@given(doc=yaml_docs | st.fixed_dictionaries(
    {"drive": st.sampled_from(DRIVES)},
    optional=dict.fromkeys(("geometry", "motors", "motor_defaults", "wheels", "limits", "bus",
                            "gateway", "kinematics", "name"), yaml_docs),
))
def test_random_documents_raise_only_config_error(doc: object) -> None:
    parse_or_config_error(doc, "fuzz.yaml")


def _paths(doc: object, prefix: tuple[Any, ...] = ()) -> Iterator[tuple[Any, ...]]:
    if prefix:
        yield prefix
    if isinstance(doc, dict):
        for k, v in doc.items():
            yield from _paths(v, (*prefix, k))
    elif isinstance(doc, list):
        for i, v in enumerate(doc):
            yield from _paths(v, (*prefix, i))


def _mutate(doc: Any, draw: st.DrawFn) -> None:
    """One mutation at a random place (a leaf, mostly): delete the key, replace the value
    (mostly by a scalar of another type), add a key, or wrap the value in a list."""
    paths = list(_paths(doc))
    leaves = [p for p in paths if not isinstance(_get(doc, p), (dict, list))]
    pool = leaves if leaves and draw(st.integers(0, 9)) < 7 else paths
    path = draw(st.randoms(use_true_random=False)).choice(pool)  # uniform, unlike sampled_from
    parent, key = _get(doc, path[:-1]), path[-1]
    op = draw(st.sampled_from(["delete", "replace", "replace", "replace", "add", "wrap"]))
    if op == "delete" and isinstance(parent, dict):
        del parent[key]
    elif op == "add" and isinstance(parent, dict):
        parent[draw(st.sampled_from(KEYS) | st.text(max_size=4))] = draw(yaml_docs)
    elif op == "wrap":
        parent[key] = [parent[key]]
    else:
        parent[key] = draw(st.one_of(scalars, scalars, yaml_docs))


def _get(doc: Any, path: tuple[Any, ...]) -> Any:
    for key in path:
        doc = doc[key]
    return doc


@st.composite
def mutated_configs(draw: st.DrawFn) -> tuple[Any, str]:
    path = draw(st.sampled_from(SHIPPED))
    doc = yaml.safe_load(path.read_text("utf-8"))
    for _ in range(draw(st.integers(1, 4))):
        _mutate(doc, draw)
    return doc, str(path)


@settings(FUZZ, max_examples=300)
@given(case=mutated_configs())
def test_mutated_shipped_configs_raise_only_config_error(case: tuple[Any, str]) -> None:
    doc, source = case
    parse_or_config_error(doc, source)


def test_every_shipped_config_loads() -> None:
    """The mutation test starts from valid files."""
    for path in SHIPPED:
        assert load_config(path).model.wheels


@contextlib.contextmanager
def _written(data: bytes) -> Iterator[str]:
    """A private file holding ``data``."""
    folder = tempfile.mkdtemp(prefix="wgfz")
    try:
        path = os.path.join(folder, "robot.yaml")
        Path(path).write_bytes(data)
        yield path
    finally:
        shutil.rmtree(folder, ignore_errors=True)


def load_or_config_error(data: bytes) -> None:
    with _written(data) as path:
        try:
            load_config(path)
        except ConfigError as err:
            assert str(err).startswith(path)


yaml_text = st.text(
    st.characters(codec="utf-8") | st.sampled_from(list(":-[]{},#&*!|>'\"%@ \n\t")),
    max_size=200,
)


@FUZZ
@given(text=yaml_text | st.builds(yaml.safe_dump, yaml_docs))
def test_load_config_on_random_text_raises_only_config_error(text: str) -> None:
    load_or_config_error(text.encode("utf-8"))


@FUZZ
@example(data=b"\xff\xfedrive: differential\n")
@given(data=st.binary(max_size=200))
def test_load_config_on_random_bytes_raises_only_config_error(data: bytes) -> None:
    load_or_config_error(data)


def test_load_config_on_deeply_nested_yaml_raises_config_error() -> None:
    load_or_config_error(b"drive: " + b"[" * 2000 + b"]" * 2000 + b"\n")


def test_a_huge_wheel_count_is_refused_as_such() -> None:
    doc = yaml.safe_load((CONFIG_DIR / "omni3.yaml").read_text("utf-8"))
    doc["geometry"]["wheel_count"] = 10**12  # refused before any wheel is built
    with pytest.raises(ConfigError) as err:
        parse_config(doc, str(CONFIG_DIR / "omni3.yaml"))
    assert "wheel_count" in str(err.value), str(err.value)


bus_values = scalars | st.text(max_size=30)


@FUZZ
@given(interface=bus_values, channel=bus_values, bitrate=bus_values, env=st.none() | st.text())
def test_bus_overrides_raise_only_config_error(
    interface: object, channel: object, bitrate: object, env: str | None
) -> None:
    old = os.environ.pop("GATEWAY_BITRATE", None)
    if env is not None and "\x00" not in env:
        os.environ["GATEWAY_BITRATE"] = env
    try:
        load_config(None, {"interface": interface, "channel": channel, "bitrate": bitrate})
    except ConfigError as err:
        assert str(err)
    finally:
        os.environ.pop("GATEWAY_BITRATE", None)
        if old is not None:
            os.environ["GATEWAY_BITRATE"] = old


# =============================================================================== control socket

VALID_REQUESTS: list[dict[str, object]] = [
    {"op": "twist", "vx": 0.1, "vy": 0.0, "wz": 0.2, "id": 7},
    {"op": "stop"},
    {"op": "estop", "id": "e"},
    {"op": "enable"},
    {"op": "disable", "id": -3},
    {"op": "status", "id": 1},
    {"op": "reset_odometry", "x": 1.0, "y": -2.0, "theta": 0.5},
    {"op": "subscribe", "topics": ["odometry", "status"], "id": "s"},
    {"op": "unsubscribe"},
]
#: JSON literals Python's json reads but no request accepts as a number.
RAW_LITERALS = ["NaN", "Infinity", "-Infinity", "1e400", "-1e999", "1" + "0" * 400,
                "-" + "9" * 4000, "1e-400", "123456789012345678901234567890", "true", "null",
                "0x10", "01", "1.", ".5", "+1", "--1", "1e", "\"\\ud83d\\ude00\""]


def unicode_text(surrogates: bool) -> st.SearchStrategy[str]:
    chars = st.characters(exclude_categories=()) if surrogates else st.characters(codec="utf-8")
    odd = ["twist", "\u00f6p", "\u03c4wist", "twist\u0000", "\u202etsiwt", "\U0001f680",
           "\uff54\uff57\uff49\uff53\uff54", "TWIST", " twist"]  # fullwidth "twist"
    return st.text(chars, max_size=12) | st.sampled_from(odd)


@st.composite
def json_fragments(draw: st.DrawFn, surrogates: bool) -> str:
    """A JSON value as text: awkward literals, deep nesting, unicode, or a random value."""
    kind = draw(st.sampled_from(["literal", "nest", "unicode", "value", "number"]))
    if kind == "literal":
        return draw(st.sampled_from(RAW_LITERALS))
    if kind == "nest":
        depth = draw(st.sampled_from([2, 50, 500, 1500]))
        opener, closer = draw(st.sampled_from([("[", "]"), ('{"a":', "}")]))
        return opener * depth + "0" + closer * depth
    if kind == "unicode":
        return json.dumps(draw(unicode_text(surrogates)), ensure_ascii=draw(st.booleans()))
    if kind == "number":
        return json.dumps(draw(st.floats(allow_nan=True) | st.integers(-(2**70), 2**70)))
    value = draw(st.recursive(st.none() | st.booleans() | st.integers() | st.floats()
                              | unicode_text(surrogates),
                              lambda c: st.lists(c, max_size=3)
                              | st.dictionaries(unicode_text(surrogates), c, max_size=3),
                              max_leaves=6))
    return json.dumps(value)


@st.composite
def mutated_requests(draw: st.DrawFn, surrogates: bool = False) -> str:
    """A valid request with 1..3 structural mutations, as JSON text (maybe then cut)."""
    base = draw(st.sampled_from(VALID_REQUESTS))
    items = [(k, json.dumps(v)) for k, v in base.items()]
    for _ in range(draw(st.integers(1, 3))):
        op = draw(st.sampled_from(["value", "value", "delete", "add", "duplicate", "rename"]))
        k = draw(st.integers(0, max(len(items) - 1, 0)))
        if op == "value" and items:
            items[k] = (items[k][0], draw(json_fragments(surrogates)))
        elif op == "delete" and items:
            del items[k]
        elif op == "duplicate" and items:
            items.insert(k, items[k])
        elif op == "rename" and items:
            items[k] = (draw(unicode_text(surrogates)), items[k][1])
        else:
            name = draw(st.sampled_from(["op", "id", "vx", "topics", "x", "extra"])
                        | unicode_text(surrogates))
            items.insert(k, (name, draw(json_fragments(surrogates))))
    text = "{" + ",".join(f"{json.dumps(k)}:{v}" for k, v in items) + "}"
    if draw(st.integers(0, 4)) == 0:
        text = text[: draw(st.integers(0, len(text)))]
    return text


def check_parse_and_reply(line: bytes) -> ProtocolError | None:
    """Parse ``line``; whatever comes out, the reply to it encodes as one JSON line."""
    try:
        request = parse_request(line)
    except ProtocolError as err:
        reply = reply_protocol_error(err)
        body = json.loads(reply.decode("utf-8"))
        assert reply.endswith(b"\n") and reply.count(b"\n") == 1
        assert body["ok"] is False and body["error"]["code"] == "bad_command"
        return err
    if isinstance(request, TwistRequest):
        tw = request.twist
        assert all(math.isfinite(v) and abs(v) <= MAX_TWIST_COMPONENT
                   for v in (tw.vx_m_s, tw.vy_m_s, tw.wz_rad_s))
    if isinstance(request, ResetOdometryRequest):
        pose = request.pose
        assert all(math.isfinite(v) for v in (pose.x_m, pose.y_m, pose.theta_rad))
    json.loads(reply_ok(request.id, {}).decode("utf-8"))
    return None


@settings(FUZZ, max_examples=400)
@given(text=mutated_requests(), as_bytes=st.booleans())
def test_mutated_requests_parse_or_fail_cleanly_and_every_reply_encodes(
    text: str, as_bytes: bool
) -> None:
    check_parse_and_reply(text.encode("utf-8") if as_bytes else text)  # type: ignore[arg-type]


@settings(FUZZ, max_examples=200)
@given(data=st.binary(max_size=300) | st.binary(min_size=4090, max_size=4200))
def test_random_bytes_fail_cleanly_and_every_reply_encodes(data: bytes) -> None:
    check_parse_and_reply(data)


@settings(FUZZ, report_multiple_bugs=False)
@example(text='{"op": "\\ud800"}')
@example(text='{"op": "estop", "id": "\\udc80"}')
@given(text=mutated_requests(surrogates=True))
def test_lone_surrogates_parse_or_fail_cleanly_and_every_reply_encodes(text: str) -> None:
    check_parse_and_reply(text.encode("utf-8"))


garbage_lines = (
    st.binary(min_size=1, max_size=300)
    | mutated_requests().map(lambda s: s.encode("utf-8"))
    | st.sampled_from([b"x" * 5000, b'{"op":"twist","vx":' + b"1" * 5000 + b"}"])
).map(lambda b: b.replace(b"\n", b" ")).filter(lambda b: bool(b.strip()))


def _invalid(line: bytes) -> bool:
    try:
        parse_request(line)
    except ProtocolError:
        return True
    return False


def _snapshot(rig: Rig) -> dict[str, object]:
    gw = rig.gw
    assert rig.daemon is not None
    server = rig.daemon.server.counters
    odom = gw.odometry.state
    return {
        "state": gw.state,
        "gateway": {k: v for k, v in {**dataclasses.asdict(gw.counts),
                                      **dataclasses.asdict(gw.edge.counts)}.items()
                    if k not in ("cycles", "frames_sent", "frames_received")},
        "supervisor": dataclasses.asdict(gw.supervisor.counts),
        "rejected": [dict(drv.rejected) for drv, _ in gw.drives.groups],
        "server": {k: v for k, v in dataclasses.asdict(server).items()
                   if k not in ("malformed", "too_long")},
        "parse_errors": server.malformed + server.too_long,
        "pose": (odom.pose.x_m, odom.pose.y_m, odom.pose.theta_rad, odom.distance_m),
        "target": gw.supervisor.target,
    }


def _replies(rig: Rig, pilot: SocketPilot, expected: int) -> list[dict[str, object]]:
    got: list[dict[str, object]] = []
    for _ in range(200):
        got += pilot.messages()
        if len(got) >= expected:
            break
        rig.advance(rig.period)
    rig.advance(3 * rig.period)
    return got + pilot.messages()


@FUZZ
@given(lines=st.lists(garbage_lines.filter(_invalid), min_size=1, max_size=8))
def test_daemon_answers_every_garbage_line_and_changes_nothing(lines: list[bytes]) -> None:
    with socket_dir() as path, running(CONFIG_DIR / "turtlebot3_burger.yaml", path) as rig:
        pilot = SocketPilot(path)
        try:
            rig.advance(rig.period)
            before = _snapshot(rig)
            speeds: list[tuple[float, ...]] = []
            for line in lines:
                pilot.sock.sendall(line + b"\n")
                rig.advance(rig.period, lambda r: speeds.append(r.gw.prev.wheel_rad_s))
            replies = _replies(rig, pilot, len(lines))
            after = _snapshot(rig)
        finally:
            pilot.close()
    assert len(replies) == len(lines), replies
    for reply in replies:
        assert reply["ok"] is False
        error = reply["error"]
        assert isinstance(error, dict) and error["code"] == "bad_command"
    assert after["parse_errors"] == before["parse_errors"] + len(lines)  # type: ignore[operator]
    before["parse_errors"] = after["parse_errors"]
    assert after == before
    assert all(w == 0.0 for s in speeds for w in s)


@pytest.mark.parametrize("line", [b'{"op": "\\ud800"}', b'{"op": "estop", "id": "\\udc80"}'])
def test_daemon_survives_a_lone_surrogate(line: bytes) -> None:
    with socket_dir() as path, running(CONFIG_DIR / "turtlebot3_burger.yaml", path) as rig:
        pilot = SocketPilot(path)
        try:
            pilot.sock.sendall(line + b"\n")
            replies = _replies(rig, pilot, 1)
        finally:
            pilot.close()
        assert len(replies) == 1
        assert rig.gw.state in (GatewayState.RUNNING, GatewayState.ESTOP)
