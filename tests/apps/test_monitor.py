"""The monitor's pure core: rates, bus load, labels, motor views and rendering, on simulated
time (no bus, no clock)."""

from __future__ import annotations

import dataclasses
import json
import math
from types import MappingProxyType
from typing import TYPE_CHECKING

import pytest

from gateway.apps.monitor import BusMonitor, FrameLabeler, StatusMonitor, render, snapshot_json
from gateway.config import load_config
from gateway.core.errors import DecodeError
from gateway.core.status import (
    BusHealth,
    BusReport,
    CanErrorState,
    Counters,
    Direction,
    FrameCount,
    MotorReport,
)
from gateway.core.types import DriveFault, DriveState, Frame
from gateway.drive.driveset import DriveSet
from gateway.sim.device import SimFault
from gateway.sim.registry import simulators_for
from gateway.wire.can import CanIds
from tests.conftest import CONFIG_DIR
from tests.wire.status_samples import sample_status

if TYPE_CHECKING:
    from collections.abc import Sequence

    from gateway.apps.monitor import MonitorSnapshot, MotorView
    from gateway.core.settings import GatewayConfig
    from gateway.core.status import GatewayStatus

#: Bits of one 8-byte standard frame: nominal and with worst-case stuffing (by hand:
#: 34 + 64 + 13 = 111; plus floor((34 + 64 - 1) / 4) = 24 stuff bits).
STD8_NOMINAL, STD8_WORST = 111, 135
#: Bits of an extended remote frame: 54 + 13 = 67; plus floor(53 / 4) = 13.
EXT0_NOMINAL, EXT0_WORST = 67, 80
#: rpm per rad/s.
RPM = 60.0 / (2.0 * math.pi)


def default_config() -> GatewayConfig:
    """The embedded demo robot: mecanum on four ODrives (gear 10, right side inverted)."""
    return load_config(None, {})


class Session:
    """A gateway's drivers and the simulated controllers talking on simulated time, without a
    bus: what a recorded log of a real session holds.

    :param config: the robot.
    :param step_s: simulator and command step.
    """

    def __init__(self, config: GatewayConfig, step_s: float = 0.005) -> None:
        self.host = DriveSet(config)
        self.sims = simulators_for(self.host.all_motors())
        self.step_s = step_s
        self.t = 0.0
        self._tx = self.host.enable(0.0)

    def run(self, seconds: float, speeds: Sequence[float]) -> list[tuple[float, Frame, str]]:
        """``seconds`` more of the session with these wheel speeds (model order, rad/s).

        :return: (time, frame, ``"tx"`` from the gateway or ``"rx"`` to it) in bus order.
        """
        out: list[tuple[float, Frame, str]] = []
        for _ in range(round(seconds / self.step_s)):
            t = self.t
            rx = [f for frame in self._tx for sim in self.sims for f in sim.handle(frame, t)]
            rx += [f for sim in self.sims for f in sim.tick(t)]
            out += [(t, f, "tx") for f in self._tx] + [(t, f, "rx") for f in rx]
            for f in rx:
                self.host.on_frame(f.stamped(t))
            self.t = round(t + self.step_s, 9)
            self._tx = self.host.poll(self.t) + self.host.command(
                speeds, self.t, self.host.config.model.neutral_steer
            )
        return out


def feed_all(mon: BusMonitor, frames: Sequence[tuple[float, Frame, str]]) -> None:
    """Feed a session as a log replay does: received frames go to the drivers."""
    for t, frame, direction in frames:
        mon.feed(frame, t, direction, decode=direction == "rx")


def motor(snap: MonitorSnapshot, name: str) -> MotorView:
    return next(m for m in snap.motors if m.name == name)


def ids_by_label(snap: MonitorSnapshot) -> dict[str, float]:
    return {f"{i.direction} {i.label.text}": i.rate_hz for i in snap.ids}


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


def config_at(name: str) -> GatewayConfig:
    return load_config(CONFIG_DIR / name, {})


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


# --------------------------------------------------------------------- motors from a session


def test_motor_states_speeds_positions_and_faults_from_a_simulated_session() -> None:
    cfg = default_config()
    session = Session(cfg)
    mon = BusMonitor(cfg, source="test")
    frames = session.run(2.5, [2.0, 2.0, -1.0, -1.0])
    feed_all(mon, frames)
    snap = mon.snapshot(frames[-1][0])
    assert [m.state for m in snap.motors] == ["enabled"] * 4
    fl, fr = motor(snap, "front_left"), motor(snap, "front_right")
    assert fl.velocity_rad_s == pytest.approx(2.0, abs=1e-3)
    assert fl.motor_rpm == pytest.approx(2.0 * 10 * RPM, abs=0.01)
    assert fr.motor_rpm == pytest.approx(-2.0 * 10 * RPM, abs=0.01)  # inverted
    assert motor(snap, "rear_left").velocity_rad_s == pytest.approx(-1.0, abs=1e-3)
    # At most one encoder period (10 ms at 2 rad/s) behind the simulated wheel.
    assert fl.position_rad is not None
    assert 0.0 <= session.sims[0].wheel_position_rad - fl.position_rad <= 0.02 + 1e-6
    assert fl.feedback_age_s is not None and 0.0 <= fl.feedback_age_s <= 0.01  # 100 Hz stream
    assert (fl.driver, fl.node_id, fl.faults) == ("odrive", 1, ())
    rates = ids_by_label(snap)
    assert rates["rx ODrive node 1 Get_Encoder_Estimates (front_left)"] == pytest.approx(
        100.0, abs=0.5)
    assert rates["tx ODrive node 4 Set_Input_Vel (rear_right)"] == pytest.approx(200.0, abs=0.5)
    assert rates["rx ODrive node 2 Heartbeat (front_right)"] == pytest.approx(10.0, abs=0.5)
    assert dict(snap.errors) == {"rejected by odrive": 0}

    session.sims[0].inject(SimFault.FAULT)
    session.sims[1].inject(SimFault.SILENT)
    feed_all(mon, session.run(0.5, [2.0, 2.0, -1.0, -1.0]))
    snap = mon.snapshot(session.t)
    fl, fr = motor(snap, "front_left"), motor(snap, "front_right")
    assert fl.state == "fault"
    assert fl.faults and fl.detail
    assert fr.state == "offline"
    assert fr.feedback_age_s is not None and fr.feedback_age_s > 0.25
    assert motor(snap, "rear_left").state == "enabled"


def test_motors_that_do_not_report_arming_show_online() -> None:
    cfg = config_at("differential_tub.yaml")
    session = Session(cfg)
    mon = BusMonitor(cfg)
    # 4 rad/s: above the VESCs' minimum ERPM (900, 2.69 rad/s at these wheels).
    feed_all(mon, session.run(1.5, [4.0, 4.0]))
    snap = mon.snapshot(session.t)
    assert [(m.driver, m.state) for m in snap.motors] == [("vesc", "online")] * 2
    assert motor(snap, "left").velocity_rad_s == pytest.approx(4.0, abs=0.01)
    assert motor(snap, "left").feedback_age_s is not None


def test_rejected_frames_are_counted_per_driver() -> None:
    cfg = default_config()
    mon = BusMonitor(cfg)
    mon.feed(Frame(0x069, bytes(3)), 0.1)  # Get_Encoder_Estimates carries 8 bytes
    mon.feed(Frame(0x069, bytes(3)), 0.2, decode=False)  # not given to the drivers
    assert dict(mon.snapshot(0.3).errors) == {"rejected by odrive": 1}


def test_sdo_answers_to_the_gateways_requests_are_no_errors_to_a_listener() -> None:
    cfg = config_at("synchro.yaml")
    session = Session(cfg)
    mon = BusMonitor(cfg)
    frames = session.run(1.0, [0.5, 0.5, 0.5])
    assert any(f.arbitration_id == 0x581 for _, f, _ in frames)  # the enable sequence's SDOs
    feed_all(mon, frames)
    # The drivers would otherwise count every SDO response as unexpected.
    drv = mon.drives.groups[0][0]
    assert drv.rejected["unexpected SDO response"] > 0
    assert dict(mon.snapshot(session.t).errors) == {"rejected by cia402": 0}


# --------------------------------------------------------------------- rendering


def test_render_and_json_of_a_session() -> None:
    cfg = default_config()
    session = Session(cfg)
    mon = BusMonitor(cfg, source="log robot.log")
    mon.count("unreadable lines", 2)
    feed_all(mon, session.run(0.6, [1.0, 1.0, 1.0, 1.0]))
    snap = mon.snapshot(session.t)
    text = render(snap, width=200)
    assert text.startswith("wheelgate monitor: log robot.log")
    assert "load " in text and "% nominal" in text and "% worst case" in text
    assert "front_left    odrive     1  enabled" in text
    assert "rx     100.0        60  ODrive node 3 Get_Encoder_Estimates (rear_left)" in text
    assert "errors: rejected by odrive 0, unreadable lines 2" in text
    narrow = render(snap, width=40)
    assert max(len(line) for line in narrow.splitlines()) == 40
    doc = json.loads(json.dumps(snapshot_json(snap)))
    assert doc["source"] == "log robot.log"
    assert doc["errors"] == {"rejected by odrive": 0, "unreadable lines": 2}
    assert [m["state"] for m in doc["motors"]] == ["enabled"] * 4
    est = next(i for i in doc["ids"] if i["id"] == 0x069)
    assert (est["id_hex"], est["node_id"], est["message"], est["direction"]) == (
        "0x069", 3, "Get_Encoder_Estimates", "rx")


# --------------------------------------------------------------------- daemon status


def daemon_status(t: float, count: int, bits: int, healthy: bool = True) -> GatewayStatus:
    """A daemon's status: one motor, one frame ID, a few counters."""
    return sample_status(
        robot="demo_mecanum",
        motors=(MotorReport("front_right", 2, DriveState.ENABLED, DriveFault.NONE, "", 0.004,
                            1.5, 2.0),),
        counters=Counters(
            MappingProxyType({"send_failures": 2, "bus_reopens": 0, "bad_can_twists": 1}),
            MappingProxyType({"OdriveDriver": MappingProxyType({"malformed: short": 3})}),
            MappingProxyType({})),
        bus=BusReport("virtual", "wheelgate", 1_000_000,
                      BusHealth(healthy, CanErrorState.ACTIVE, MappingProxyType({}), ""), bits, t,
                      (FrameCount(0x069, False, Direction.RX, count),)),
    )


def test_status_monitor_rates_from_successive_replies() -> None:
    mon = StatusMonitor(default_config(), window_s=2.0, source="daemon s.sock")
    for t, n in ((10.0, 0), (11.0, 100), (12.0, 200)):
        mon.update(daemon_status(t, n, n * STD8_NOMINAL))
    snap = mon.snapshot()
    assert (snap.time_s, snap.window_s, snap.elapsed_s) == (12.0, 2.0, 2.0)
    assert [(i.label.text, i.rate_hz, i.count) for i in snap.ids] == [
        ("ODrive node 3 Get_Encoder_Estimates (rear_left)", 100.0, 200)]
    assert snap.load.nominal_percent == pytest.approx(100 * 100 * STD8_NOMINAL / 1e6)
    assert snap.load.worst_percent is None  # the daemon does not count worst-case bits
    assert "n/a worst case" in render(snap)
    assert snap.state == "running"
    assert snap.notes == ()
    fr = snap.motors[0]
    assert (fr.driver, fr.state, fr.velocity_rad_s) == ("odrive", "enabled", 2.0)
    assert fr.motor_rpm == pytest.approx(-2.0 * 10 * RPM)
    assert dict(snap.errors) == {"rejected by odrive": 3, "send failures": 2,
                                 "frames unsent": 0, "receive failures": 0,
                                 "bus reopens": 0, "bad can twists": 1, "fd frames ignored": 0}
    # The window slides: the reply at 10 s is dropped once the one at 11 s is 2 s old.
    mon.update(daemon_status(13.0, 400, 400 * STD8_NOMINAL, healthy=False))
    snap = mon.snapshot()
    assert snap.ids[0].rate_hz == 150.0
    assert snap.notes == ("the daemon reports its CAN bus as unhealthy",)


def test_status_monitor_robot_mismatch() -> None:
    mon = StatusMonitor(config_at("turtlebot3_burger.yaml"))
    for t, n in ((0.0, 0), (1.0, 100)):
        mon.update(daemon_status(t, n, n * STD8_NOMINAL))
    snap = mon.snapshot()
    assert "the daemon runs robot 'demo_mecanum'" in snap.notes[0]
    assert snap.motors[0].motor_rpm is None  # no such wheel in this config


def test_status_monitor_shows_the_bus_errors_and_the_faults() -> None:
    config = config_at("turtlebot3_burger.yaml")
    mon = StatusMonitor(config)
    status = sample_status(robot=config.name)
    health = status.bus.health
    assert health is not None
    mon.update(dataclasses.replace(status, reason="motor 'right' faulted", bus=dataclasses.replace(
        status.bus, health=dataclasses.replace(health, error_state=CanErrorState.BUS_OFF,
                                               last_error_frame="bus-off"))))
    snap = mon.snapshot()
    assert snap.notes == ("CAN controller bus-off: bus-off", "gateway: motor 'right' faulted")
    errors = dict(snap.errors)
    assert (errors["error frames"], errors["error frames: no ack"],
            errors["error frames: bus off"]) == (2, 2, 0)
    assert "error frames: tx timeout" not in errors  # zero counts are left out
    right = snap.motors[1]
    assert (right.state, right.faults, right.detail) == (
        "fault", ("over_temperature", "encoder"), "MOTOR_OVERTEMP")
    mon.update(dataclasses.replace(status, bus=dataclasses.replace(status.bus, health=None)))
    assert not any(name.startswith("error frames") for name, _ in mon.snapshot().errors)


def test_status_monitor_needs_a_reply_first() -> None:
    with pytest.raises(DecodeError, match="expected a status reply"):
        StatusMonitor(default_config()).snapshot()
