"""The status reply's JSON form (:mod:`gateway.wire.socket.status`): the model round-trips
through it, the JSON does too, and a malformed reply is refused naming the key."""

from __future__ import annotations

import copy
import dataclasses
import json
import math
from typing import TYPE_CHECKING, Any

import pytest
from hypothesis import HealthCheck, given, settings

from gateway.core.errors import EncodeError
from gateway.wire.socket import ProtocolError, encode_data_line, reply_ok, reply_ok_data
from gateway.wire.socket.status import status_from_json, status_to_json
from tests.wire.status_samples import ERROR_FRAMES, EVENTS, sample_status, statuses

if TYPE_CHECKING:
    from collections.abc import Callable

    from gateway.core.status import GatewayStatus

#: The JSON of :func:`sample_status`, written out: the format, key by key, in the order the
#: daemon writes it.
SAMPLE_JSON: dict[str, Any] = {
    "robot": "tb3",
    "state": "running",
    "reason": "",
    "command": {
        "target": {"vx_m_s": 0.2, "vy_m_s": 0.0, "wz_rad_s": 0.5},
        "applied": {"vx_m_s": 0.1, "vy_m_s": 0.0, "wz_rad_s": 0.25},
        "cmd_timeout_active": False, "speed_scale": 0.8, "accel_scale": 1.0,
    },
    "motors": [
        {"name": "left", "node_id": 1, "state": "enabled", "faults": [], "detail": "",
         "feedback_age_s": 0.002, "position_rad": 1.5, "velocity_rad_s": 6.0,
         "controller_stop": {"guard": "configured", "timeout_s": 0.25, "state": "confirmed"}},
        {"name": "right", "node_id": 2, "state": "fault",
         "faults": ["over_temperature", "encoder"], "detail": "MOTOR_OVERTEMP",
         "feedback_age_s": None, "position_rad": None, "velocity_rad_s": None,
         "controller_stop": {"guard": "none", "timeout_s": None, "state": "not applicable"}},
    ],
    "tracking": {"tolerance_rad_s": 1.0, "tolerance_ratio": 0.2, "time_s": 0.5,
                 "steer_tolerance_rad": 0.2, "worst_ratio": 0.25, "steer_worst_ratio": 0.0},
    "odometry": {"x": 1.0, "y": -0.5, "theta": 0.25, "vx": 0.1, "vy": 0.0, "wz": 0.25,
                 "slip": 0.001, "distance": 2.5, "t": 12.5},
    "counters": {
        **dict.fromkeys(EVENTS, 0),
        "cycles": 2000, "frames_sent": 4000, "frames_received": 3900, "faults": 1,
        "rejected_frames": {"OdriveDriver": {"bad length": 2}},
        "commands_not_followed": {"VescDriver": {"below minimum ERPM": 3}},
    },
    "socket": {"path": "/run/wheelgate/wheelgate.sock", "clients": 1, "accepted": 3,
               "refused": 0, "evicted": 0, "too_long": 0, "malformed": 1, "dropped_partial": 0,
               "slow_disconnects": 0, "idle_timeouts": 0, "partial_timeouts": 0,
               "deferred": 0},
    "timing": {"cycles": 2000, "missed": 1, "rate_hz": 200.0, "achieved_hz": 199.9,
               "lateness_p50_us": 12.0, "lateness_p99_us": 80.0, "lateness_max_us": 120.0,
               "cost_p50_us": 150.0, "cost_p99_us": 400.0, "cost_max_us": 700.0,
               "latency_samples": 5, "latency_p50_us": 900.0, "latency_p99_us": 1500.0,
               "latency_max_us": 1600.0, "late_on_cpu": 1, "late_runnable": 0,
               "late_asleep": 0, "burst_gap_max_ms": 8.5},
    "last_error": {"code": "motor_fault", "message": "motor 'right' (odrive node 2) faulted"},
    "realtime": ["gc: 100 start-up objects frozen"],
    "bus": {
        "interface": "virtual", "channel": "wheelgate", "bitrate": 500_000, "healthy": True,
        "error_state": "active",
        "error_frames": {**dict.fromkeys(ERROR_FRAMES, 0), "error_frames": 2, "no_ack": 2},
        "last_error_frame": "no ACK", "bits": 123_456, "time_s": 12.5,
        "frames": [{"id": 0x21, "extended": False, "direction": "rx", "count": 10},
                   {"id": 0x21, "extended": False, "direction": "tx", "count": 11},
                   {"id": 0x18FF0013, "extended": True, "direction": "tx", "count": 3}],
    },
    "config": {"path": "/etc/wheelgate/robot.yaml", "fingerprint": "1c291ca3"},
}


def _keys(value: object) -> object:
    """Every object's keys in order, recursively (``==`` on dicts ignores the order)."""
    if isinstance(value, dict):
        return [(k, _keys(v)) for k, v in value.items()]
    if isinstance(value, list):
        return [_keys(v) for v in value]
    return value


def test_the_sample_is_written_key_by_key_in_order() -> None:
    written = status_to_json(sample_status())
    assert written == SAMPLE_JSON
    assert _keys(written) == _keys(SAMPLE_JSON)


def test_the_sample_reads_back() -> None:
    assert status_from_json(SAMPLE_JSON) == sample_status()


@pytest.mark.timeout(60)
@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(statuses())
def test_the_model_round_trips_through_its_json(status: GatewayStatus) -> None:
    text = json.dumps(status_to_json(status))
    back = status_from_json(json.loads(text))
    assert back == status
    # ... and the JSON through the model: the same text again, key order included.
    assert json.dumps(status_to_json(back)) == text
    # The daemon's shortcut for a payload that is JSON data already gives the same line.
    assert reply_ok_data(3, status_to_json(status)) == reply_ok(3, status_to_json(status))


def test_the_data_line_is_the_line_of_any_json_data() -> None:
    np = pytest.importorskip("numpy")
    payload = {"a": [np.float32(0.5), np.int64(3), 1.25, (1, 2)], "s": "\ud800", "n": None,
               "inf": np.float32("inf")}
    assert reply_ok_data(1, payload) == reply_ok(1, payload)
    assert b'"s":"\\ud800"' in reply_ok_data(1, payload)  # a lone surrogate: escaped
    with pytest.raises(EncodeError, match="expected keys other than"):
        reply_ok_data(1, {"id": 2})
    with pytest.raises(EncodeError, match="expected JSON data"):
        encode_data_line({"x": math.nan})
    with pytest.raises(EncodeError, match="expected JSON data, got object"):
        encode_data_line({"x": object()})


def test_a_reply_reads_with_its_ok_and_id_and_keys_of_newer_daemons() -> None:
    reply = {"ok": True, "id": 7, **SAMPLE_JSON, "future": {"x": 1}}
    reply["motors"] = [{**m, "temperature_c": 40} for m in SAMPLE_JSON["motors"]]
    assert status_from_json(reply) == sample_status()


def test_integers_stay_integers() -> None:
    doc = copy.deepcopy(SAMPLE_JSON)
    doc["timing"]["rate_hz"] = 200
    doc["motors"][0]["controller_stop"]["timeout_s"] = 1
    text = json.dumps(status_to_json(status_from_json(doc)))
    assert '"rate_hz": 200,' in text and '"timeout_s": 1,' in text
    assert json.loads(text) == doc


def test_null_is_nan_where_a_number_is_needed_and_none_where_the_model_allows_it() -> None:
    doc = copy.deepcopy(SAMPLE_JSON)
    doc["odometry"]["x"] = None  # a float that was not finite, as the protocol writes it
    doc["motors"][0]["velocity_rad_s"] = None
    status = status_from_json(doc)
    assert math.isnan(status.odometry.pose.x_m)
    assert status.motors[0].velocity_rad_s is None
    assert status_to_json(status) == doc
    command = dataclasses.replace(sample_status().command, speed_scale=math.inf,
                                  accel_scale=math.nan)
    written = status_to_json(sample_status(command=command))["command"]
    assert isinstance(written, dict)
    assert written["speed_scale"] is None and written["accel_scale"] is None


def _drop(*path: str | int) -> Callable[[dict[str, Any]], None]:
    def mutate(doc: dict[str, Any]) -> None:
        target: Any = doc
        for key in path[:-1]:
            target = target[key]
        del target[path[-1]]
    return mutate


def _set(value: object, *path: str | int) -> Callable[[dict[str, Any]], None]:
    def mutate(doc: dict[str, Any]) -> None:
        target: Any = doc
        for key in path[:-1]:
            target = target[key]
        target[path[-1]] = value
    return mutate


@pytest.mark.parametrize(("mutate", "message"), [
    (_drop("robot"), "status.robot: expected a string, got nothing"),
    (_set(None, "bus"), "status.bus: expected an object, got null"),
    (_set("running!", "state"),
     'status.state: expected one of "disabled", "enabling", "running", "fault", "estop", '
     '"stopping", got "running!"'),
    (_set("2", "motors", 1, "node_id"), 'status.motors[1].node_id: expected an integer, got "2"'),
    (_set(True, "timing", "cycles"), "status.timing.cycles: expected an integer, got true"),
    (_set("on", "motors", 0, "state"),
     'status.motors[0].state: expected one of "offline", "disabled", "enabling", "enabled", '
     '"fault", got "on"'),
    (_set("gremlins", "motors", 1, "faults", 1),
     'status.motors[1].faults[1]: expected one of "over_temperature", "over_current", '
     '"over_voltage", "under_voltage", "encoder", "motor", "controller", "watchdog", '
     '"communication", "estop", "other", got "gremlins"'),
    (_set("now", "motors", 0, "feedback_age_s"),
     'status.motors[0].feedback_age_s: expected a number or null, got "now"'),
    (_set("soon", "motors", 0, "controller_stop", "guard"),
     'status.motors[0].controller_stop.guard: expected one of "configured", "stated", '
     '"unstated", "none", got "soon"'),
    (_set("1", "odometry", "x"), 'status.odometry.x: expected a number, got "1"'),
    (_set(0, "command", "cmd_timeout_active"),
     "status.command.cmd_timeout_active: expected true or false, got 0"),
    (_drop("command", "applied", "wz_rad_s"),
     "status.command.applied.wz_rad_s: expected a number, got nothing"),
    (_set(1.5, "counters", "cycles"), "status.counters.cycles: expected an integer count, "
                                      "got 1.5"),
    (_set([], "counters", "rejected_frames", "OdriveDriver"),
     "status.counters.rejected_frames.OdriveDriver: expected an object, got []"),
    (_set("2", "counters", "commands_not_followed", "VescDriver", "below minimum ERPM"),
     'status.counters.commands_not_followed.VescDriver.below minimum ERPM: expected an integer '
     'count, got "2"'),
    (_set("oops", "last_error", "code"),
     'status.last_error.code: expected one of "none", "infeasible_twist", "motor_fault", '
     '"feedback_timeout", "estop", "bus_error", "bad_command", "command_timeout", '
     '"not_enabled", "tracking_error", got "oops"'),
    (_set("x", "realtime"), 'status.realtime: expected an array, got "x"'),
    (_set([1], "realtime"), "status.realtime[0]: expected a string, got 1"),
    (_drop("socket", "path"), "status.socket.path: expected a string, got nothing"),
    (_drop("bus", "error_state"),
     'status.bus.error_state: expected one of "active", "warning", "passive", "bus_off", '
     'got nothing'),
    (_set("up", "bus", "frames", 2, "direction"),
     'status.bus.frames[2].direction: expected one of "rx", "tx", got "up"'),
    (_set(None, "bus", "frames", 0), "status.bus.frames[0]: expected an object, got null"),
])
def test_a_malformed_reply_names_the_key(mutate: Callable[[dict[str, Any]], None],
                                         message: str) -> None:
    doc = copy.deepcopy(SAMPLE_JSON)
    mutate(doc)
    with pytest.raises(ProtocolError) as err:
        status_from_json(doc)
    assert str(err.value) == message


@pytest.mark.parametrize("value", [[], "status", None, 3])
def test_a_reply_that_is_no_object(value: object) -> None:
    with pytest.raises(ProtocolError, match=r"^status: expected an object, got "):
        status_from_json(value)


def test_keys_older_daemons_did_not_send_read_as_absent() -> None:
    doc = copy.deepcopy(SAMPLE_JSON)
    del doc["tracking"]
    del doc["timing"]["burst_gap_max_ms"]
    for key in ("late_on_cpu", "late_runnable", "late_asleep"):
        del doc["timing"][key]
    for key in ("healthy", "error_state", "error_frames", "last_error_frame"):
        del doc["bus"][key]
    del doc["motors"][0]["controller_stop"]
    del doc["counters"]["rejected_frames"]
    del doc["counters"]["commands_not_followed"]
    del doc["socket"]["deferred"]
    status = status_from_json(doc)
    assert status.tracking is None
    assert status.timing.burst_gap_max_ms is None and status.timing.late_on_cpu == 0
    assert status.bus.health is None
    assert status.motors[0].controller_stop is None
    assert not status.counters.rejected_frames and not status.counters.commands_not_followed
    assert status.socket.counters.deferred == 0
    written = status_to_json(status)
    assert "tracking" not in written and "healthy" not in written["bus"]  # type: ignore[operator]
    assert "burst_gap_max_ms" not in written["timing"]  # type: ignore[operator]
    old_tracking = {k: v for k, v in SAMPLE_JSON["tracking"].items() if k != "steer_worst_ratio"}
    tracked = status_from_json({**SAMPLE_JSON, "tracking": old_tracking}).tracking
    assert tracked is not None and tracked.steer_worst_ratio == 0.0
