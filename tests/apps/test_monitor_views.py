"""The monitor's pure core on a session: motor views, rendering, and the monitor of the daemon's
status, on simulated time (no bus, no clock)."""

from __future__ import annotations

import dataclasses
import json
import math
import re
from types import MappingProxyType
from typing import TYPE_CHECKING

import pytest

from gateway.apps.monitor import BusMonitor, StatusMonitor, render, snapshot_json
from gateway.core.errors import DecodeError
from gateway.core.status import (
    BusErrorState,
    BusHealth,
    BusReport,
    Counters,
    Direction,
    FrameCount,
    MotorReport,
)
from gateway.core.types import DriveFault, DriveState, Frame
from gateway.sim.device import SimFault
from tests.apps.monitor_helpers import STD8_NOMINAL, Session, config_at, default_config
from tests.wire.status_samples import sample_status

if TYPE_CHECKING:
    from collections.abc import Sequence

    from gateway.apps.monitor import MonitorSnapshot, MotorView
    from gateway.core.status import GatewayStatus
#: rpm per rad/s.
RPM = 60.0 / (2.0 * math.pi)


def feed_all(mon: BusMonitor, frames: Sequence[tuple[float, Frame, str]]) -> None:
    """Feed a session as a log replay does: received frames go to the drivers."""
    for t, frame, direction in frames:
        mon.feed(frame, t, direction, decode=direction == "rx")


def motor(snap: MonitorSnapshot, name: str) -> MotorView:
    return next(m for m in snap.motors if m.name == name)


def ids_by_label(snap: MonitorSnapshot) -> dict[str, float]:
    return {f"{i.direction} {i.label.text}": i.rate_hz for i in snap.ids}


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


def test_the_measured_load_beside_the_budget() -> None:
    # The budget of the configuration (gateway.config.budget) stands beside the measured load.
    # A session's frames are the drivers' alone: without the gateway's WG_* reports (110 a
    # second of 111 bits, 1.221 % of 1 Mbit/s) the measured load is the budget's less those,
    # within the window's edges (a heartbeat more or less).
    cfg = default_config()
    session = Session(cfg)
    mon = BusMonitor(cfg, source="log robot.log", window_s=1.0)
    feed_all(mon, session.run(3.0, [1.0, 1.0, 1.0, 1.0]))
    snap = mon.snapshot(session.t)
    assert snap.load.budget_percent == pytest.approx((14.985, 18.225))
    assert snap.load.nominal_percent == pytest.approx(14.985 - 1.221, abs=0.1)
    assert "load 13.7 % nominal, 16.7 % worst case  budget 15.0-18.2 %" in render(snap, 200)
    doc = json.loads(json.dumps(snapshot_json(snap)))
    assert doc["load"]["budget_percent"] == pytest.approx([14.985, 18.225])
    assert snap.notes == ()
    # Another node's frames (1000 a second, 8 bytes, 11.1 %): more than the budget, said.
    other = Session(cfg)
    mon = BusMonitor(cfg, source="bus", window_s=1.0)
    frames = other.run(3.0, [1.0, 1.0, 1.0, 1.0])
    frames += [(k / 1000.0, Frame(0x7E0, bytes(8)), "rx") for k in range(3000)]
    feed_all(mon, sorted(frames, key=lambda f: f[0]))
    snap = mon.snapshot(other.t)
    assert snap.load.nominal_percent == pytest.approx(14.985 - 1.221 + 11.1, abs=0.2)
    assert snap.notes == (
        "the bus carries 24.8 %, more than the configuration's periodic frames need "
        "(15.0-18.2 %): frames it does not know (another node on the bus, a controller's "
        "message rates other than its block states)",)
    assert "note: the bus carries 24.8 %" in render(snap, 200)


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
                      BusHealth(healthy, BusErrorState.ACTIVE, MappingProxyType({}), ""), bits, t,
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
    assert "n/a worst case  budget 15.0-18.2 %" in render(snap)
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
    assert snap.load.budget_percent is None  # (this config's budget is another robot's)


def test_status_monitor_shows_the_bus_errors_and_the_faults() -> None:
    config = config_at("turtlebot3_burger.yaml")
    mon = StatusMonitor(config)
    status = sample_status(robot=config.name)
    health = status.bus.health
    assert health is not None
    mon.update(dataclasses.replace(status, reason="motor 'right' faulted", bus=dataclasses.replace(
        status.bus, health=dataclasses.replace(health, error_state=BusErrorState.BUS_OFF,
                                               last_error_frame="bus-off"))))
    snap = mon.snapshot()
    assert snap.notes == ("CAN controller bus-off: bus-off", "gateway: motor 'right' faulted")
    errors = dict(snap.errors)
    assert (errors["bus error frames"], errors["bus error frames: no ack"],
            errors["bus error frames: bus off"]) == (2, 2, 0)
    assert "bus error frames: tx timeout" not in errors  # zero counts are left out
    # On the screen each is said once: the total, its classes in parentheses.
    text = render(snap, 200)
    assert "bus error frames 2 (no ack 2, bus off 0)" in text
    assert "error frames:" not in text and text.count("error frames") == 1
    right = snap.motors[1]
    assert (right.state, right.faults, right.detail) == (
        "fault", ("over_temperature", "encoder"), "MOTOR_OVERTEMP")
    mon.update(dataclasses.replace(status, bus=dataclasses.replace(status.bus, health=None)))
    assert not any("error frames" in name for name, _ in mon.snapshot().errors)


def test_status_monitor_needs_a_reply_first() -> None:
    with pytest.raises(DecodeError, match="expected a status reply"):
        StatusMonitor(default_config()).snapshot()


# --------------------------------------------------------------------- the screen at 80 x 24

#: The swerve robot's steering angles (rad) and how the screen writes them.
ANGLES = {"front_left": (0.7853981633974483, "+45.0"), "front_right": (0.3217505, "+18.4"),
          "rear_left": (-0.7853981633974483, "-45.0"), "rear_right": (-0.3217505, "-18.4")}
_SGR = re.compile(r"\x1b\[[0-9;]*m")


def swerve_snapshot(fault: bool = False) -> MonitorSnapshot:
    """The swerve robot's daemon, twice a second apart: four drive motors (the second faulted
    if ``fault``), four steering actuators at :data:`ANGLES`, 40 frame IDs."""
    cfg = config_at("swerve.yaml")
    motors = [MotorReport(m.wheel, m.node_id, DriveState.ENABLED, DriveFault.NONE, "", 0.004,
                          3.0, -2.7755575615628914e-17) for m in cfg.motors if m is not None]
    if fault:
        motors[1] = MotorReport("front_right", 2, DriveState.FAULT, DriveFault.OVER_CURRENT,
                                "", None, None, None)
    motors += [MotorReport(a.wheel, a.node_id, DriveState.ENABLED, DriveFault.NONE, "", 0.004,
                           ANGLES[a.steers[0]][0], 0.0) for a in cfg.steering]
    mon = StatusMonitor(cfg, source="daemon /run/wheelgate/wheelgate.sock")
    for t, n in ((10.0, 0), (11.0, 100)):
        status = daemon_status(t, n, n * STD8_NOMINAL)
        frames = tuple(FrameCount(can_id, False, Direction.RX, n) for can_id in range(1, 41))
        mon.update(dataclasses.replace(status, robot="swerve", motors=tuple(motors),
                                       bus=dataclasses.replace(status.bus, frames=frames)))
    return mon.snapshot()


def test_swerve_fits_80_by_24_with_its_steering_angles_and_pages_the_ids() -> None:
    lines = render(swerve_snapshot(), 80, 24).splitlines()
    assert len(lines) <= 24 and max(len(ln) for ln in lines) <= 80, "\n".join(lines)
    header = next(ln for ln in lines if ln.startswith("WHEEL"))
    assert header.split() == ["WHEEL", "NODE", "STATE", "rad/s", "rpm", "steer", "deg", "age",
                              "ms", "FAULTS"]
    rows = {ln.split()[0]: ln.split() for ln in lines[lines.index(header) + 1:][:4]}
    for (wheel, (_, angle)), node in zip(ANGLES.items(), ("1/5", "2/6", "3/7", "4/9"),
                                         strict=True):
        assert rows[wheel][1:3] == [node, "enabled"]
        assert rows[wheel][5] == angle  # the steering angle beside its wheel, in degrees
        assert rows[wheel][3] == "0.000"  # not -0.000
    assert not any("steering" in ln for ln in lines)
    page = next(ln for ln in lines if ln.startswith("IDs "))
    per = int(page.split()[1].split("-")[1])
    pages = -(-40 // per)
    assert per >= 6
    assert page == f"IDs 1-{per} of 40, page 1/{pages} (a taller terminal shows more)"
    assert lines[lines.index(page) - 1].startswith(f"0x{per:03X} rx")
    second = render(swerve_snapshot(), 80, 24, page=1)
    assert f"IDs {per + 1}-{2 * per} of 40, page 2/{pages}" in second
    assert f"\n0x{per + 1:03X} rx" in second
    assert page in render(swerve_snapshot(), 80, 24, page=pages)  # the pages go round
    assert lines[-2].startswith("errors: rejected by odrive 3, send failures 2")


def test_swerve_on_a_big_terminal_has_a_row_per_motor_and_every_id() -> None:
    lines = render(swerve_snapshot(), 140, 80).splitlines()
    at = next(i for i, ln in enumerate(lines) if ln.startswith("front_left"))
    assert lines[at].split()[:3] == ["front_left", "odrive", "1"]
    assert lines[at + 1].split()[:8] == ["steering", "odrive", "5", "enabled", "0.000", "0.0",
                                         "0.785", "+45.0"]
    assert sum(ln.startswith("0x0") for ln in lines) == 40
    assert "  q: quit" not in lines[0]
    assert render(swerve_snapshot(), 140, 80, keys=True).splitlines()[0].endswith("q: quit")


def test_faults_errors_and_notes_in_colour() -> None:
    snap = dataclasses.replace(swerve_snapshot(fault=True), state="fault",
                               notes=("gateway: motor 'front_right' faulted",))
    plain = render(snap, 80, 24)
    assert "\x1b" not in plain
    text = render(snap, 80, 24, colour=True)
    assert _SGR.sub("", text) == plain  # only colour is added
    lines = text.splitlines()
    assert "\x1b[31m    gateway fault\x1b[0m" in lines
    fault = next(ln for ln in lines if ln.startswith("front_right"))
    assert "\x1b[31mfault" in fault and fault.endswith("\x1b[0m")
    assert "errors: \x1b[33mrejected by odrive 3" in text
    assert "\x1b[33mnote: gateway: motor 'front_right' faulted\x1b[0m" in lines


def test_short_terminals_give_way_but_keep_the_width_and_the_height() -> None:
    snap = swerve_snapshot(fault=True)
    for width, height in ((80, 14), (80, 9), (60, 5), (30, 2)):
        lines = render(snap, width, height).splitlines()
        assert len(lines) <= height and max(len(ln) for ln in lines) <= width, (width, height)
    lines = render(snap, 80, 14).splitlines()
    assert sum(ln.split()[0] in ANGLES for ln in lines) == 4  # every wheel before more IDs
    assert lines[-1] == "errors: rejected by odrive 3, send failures 2, bad can twists 1, others 0"
    assert lines[-2].startswith("IDs 1-4 of 40")
    assert render(snap, 80, 9).splitlines()[4] == (
        "... 3 more motors (a taller terminal shows them)")
