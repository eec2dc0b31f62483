"""The monitor's pure core on frames: rates, bus load and labels, on simulated time (no bus, no
clock)."""

from __future__ import annotations

import dataclasses
import math

import pytest

from gateway.apps.monitor import BusMonitor, FrameLabeler
from gateway.core.types import Frame
from gateway.wire.can import CanIds
from tests.apps.monitor_helpers import STD8_NOMINAL, STD8_WORST, config_at, default_config

#: Bits of an extended remote frame: 54 + 13 = 67; plus floor(53 / 4) = 13.
EXT0_NOMINAL, EXT0_WORST = 67, 80


# --------------------------------------------------------------------- rates and load


def periodic(can_id: int, rate_hz: float, seconds: float, offset_s: float, dlc: int = 8
             ) -> list[tuple[float, Frame]]:
    """Frames at exactly ``rate_hz`` starting at ``offset_s`` (times away from the window's
    edges so that float rounding cannot move a frame across one)."""
    n = round(seconds * rate_hz)
    return [(offset_s + k / rate_hz, Frame(can_id, bytes(dlc))) for k in range(n)]


def test_rates_and_bus_load_are_exact_on_simulated_time() -> None:
    mon = BusMonitor(default_config(), window_s=2.0, start_s=0.0)
    frames = periodic(0x069, 100.0, 5.0, 0.0025) + periodic(0x021, 10.0, 5.0, 0.05)
    for t, frame in sorted(frames, key=lambda p: p[0]):
        mon.feed(frame, t, decode=False)
    snap = mon.snapshot(5.0)
    rates = {i.arbitration_id: i.rate_hz for i in snap.ids}
    counts = {i.arbitration_id: i.count for i in snap.ids}
    assert rates == {0x069: 100.0, 0x021: 10.0}
    assert counts == {0x069: 500, 0x021: 50}
    assert snap.frames == 550
    assert snap.window_s == 2.0
    assert snap.load.bitrate == 1_000_000
    assert snap.load.frames_per_s == 110.0
    # 110 frames/s of 111 bits (135 worst case) on 1 Mbit/s.
    assert snap.load.nominal_percent == pytest.approx(100 * 110 * STD8_NOMINAL / 1e6, rel=1e-12)
    assert snap.load.worst_percent == pytest.approx(100 * 110 * STD8_WORST / 1e6, rel=1e-12)


def test_extended_remote_frames_count_their_own_bits() -> None:
    mon = BusMonitor(default_config(), window_s=1.0, start_s=0.0)
    for k in range(50):
        mon.feed(Frame(0x1B0A, b"", True, True, 0), 0.01 + k * 0.02, decode=False)
    snap = mon.snapshot(1.0)
    assert snap.ids[0].remote and snap.ids[0].extended
    assert snap.load.nominal_percent == pytest.approx(100 * 50 * EXT0_NOMINAL / 1e6, rel=1e-12)
    assert snap.load.worst_percent == pytest.approx(100 * 50 * EXT0_WORST / 1e6, rel=1e-12)


def test_window_slides_and_counts_stay() -> None:
    mon = BusMonitor(default_config(), window_s=2.0, start_s=0.0)
    for t, frame in periodic(0x069, 100.0, 3.0, 0.0025):
        mon.feed(frame, t, decode=False)
    assert mon.snapshot(3.0).ids[0].rate_hz == 100.0
    # One second after the last frame, half the window is empty.
    assert mon.snapshot(4.0).ids[0].rate_hz == 50.0
    later = mon.snapshot(5.5)
    assert later.ids[0].rate_hz == 0.0
    assert later.ids[0].count == 300
    assert later.load.nominal_percent == 0.0


def test_rate_before_a_whole_window_uses_the_time_since_the_start() -> None:
    mon = BusMonitor(default_config(), window_s=2.0, start_s=0.0)
    for t, frame in periodic(0x069, 100.0, 0.5, 0.0025):
        mon.feed(frame, t, decode=False)
    snap = mon.snapshot(0.5)
    assert snap.window_s == 0.5
    assert snap.ids[0].rate_hz == 100.0


def test_directions_are_counted_apart() -> None:
    mon = BusMonitor(default_config(), window_s=1.0, start_s=0.0)
    for k in range(10):
        mon.feed(Frame(0x069, b"", is_remote_frame=True), 0.05 + k * 0.1, "tx", decode=False)
        mon.feed(Frame(0x069, bytes(8)), 0.06 + k * 0.1, "rx", decode=False)
    snap = mon.snapshot(1.0)
    assert [(i.direction, i.remote, i.rate_hz) for i in snap.ids] == [
        ("rx", False, 10.0), ("tx", True, 10.0)]


@pytest.mark.parametrize("window", [0.0, -1.0, math.nan, math.inf])
def test_bad_window_is_refused(window: float) -> None:
    with pytest.raises(ValueError, match="expected a positive number of seconds"):
        BusMonitor(default_config(), window_s=window)


# --------------------------------------------------------------------- labels


def test_labels_of_odrive_frames_name_driver_node_message_and_wheel() -> None:
    labels = FrameLabeler(default_config())
    est = labels.label(Frame(0x069, bytes(8)))
    assert est.text == "ODrive node 3 Get_Encoder_Estimates (rear_left)"
    assert (est.source, est.node_id, est.message, est.wheels) == (
        "odrive", 3, "Get_Encoder_Estimates", ("rear_left",))
    assert labels.label(Frame(0x06D, bytes(8))).text == "ODrive node 3 Set_Input_Vel (rear_left)"
    assert labels.label(Frame(0x021, bytes(8))).text == "ODrive node 1 Heartbeat (front_left)"
    assert labels.label(Frame(0x069, is_remote_frame=True)).text == (
        "ODrive node 3 Get_Encoder_Estimates RTR (rear_left)")
    # A node that is not configured, an ID nobody uses.
    assert labels.label(Frame(0x0A9, bytes(8))).text == "0x0A9"
    assert labels.label(Frame(0x7FF, bytes(2))).source is None
    assert labels.label_id(0x12345, True).text == "0x00012345"


def test_labels_of_the_gateways_own_messages_follow_the_config() -> None:
    cfg = default_config()
    assert FrameLabeler(cfg).label(Frame(0x100, bytes(8))).text == "WG_Twist_Cmd"
    ids = CanIds(twist=0x18FF0010, odom_pose=0x18FF0011, odom_velocity=0x18FF0012,
                 status=0x18FF0013, error=0x18FF0014, extended=True)
    moved = dataclasses.replace(cfg, loop=dataclasses.replace(cfg.loop, can_ids=ids))
    labels = FrameLabeler(moved)
    assert labels.label(Frame(0x18FF0012, bytes(8), True)).text == "WG_Odom_Velocity"
    assert labels.label(Frame(0x18FF0013, bytes(8), True)).source == "wheelgate"
    assert labels.label(Frame(0x100, bytes(8))).text == "0x100"


@pytest.mark.parametrize(("config", "frame", "text"), [
    ("differential_tub.yaml", Frame(0x1B0A, bytes(8), True), "VESC node 10 STATUS_5 (left)"),
    ("differential_tub.yaml", Frame(0x30B, bytes(4), True), "VESC node 11 SET_RPM (right)"),
    ("mecanum.yaml", Frame(0x200, bytes(8)),
     "DJI COMMAND_ESC_1_4 (front_left, front_right, rear_left, rear_right)"),
    ("mecanum.yaml", Frame(0x203, bytes(8)), "DJI node 3 FEEDBACK_ESC_3 (rear_left)"),
    ("synchro.yaml", Frame(0x080, b""),
     "CiA 402 SYNC (wheel_1, wheel_2, wheel_3, synchro steering)"),
    ("synchro.yaml", Frame(0x502, bytes(8)), "CiA 402 node 2 RPDO4 (wheel_2)"),
    ("synchro.yaml", Frame(0x703, bytes(1)), "CiA 402 node 3 HEARTBEAT (wheel_3)"),
    ("synchro.yaml", Frame(0x504, bytes(6)), "CiA 402 node 4 RPDO4 (synchro steering)"),
    ("example_dbc.yaml", Frame(0x282, bytes(8)), "DBC node 2 WD_Feedback (right)"),
])
def test_labels_of_other_protocols(config: str, frame: Frame, text: str) -> None:
    assert FrameLabeler(config_at(config)).label(frame).text == text
