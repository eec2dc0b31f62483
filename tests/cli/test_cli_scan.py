"""``wheelgate scan`` on python-can's virtual bus: the simulators of every protocol in this
process, powered during the scan; what the scan sent, read off the bus; beside a running
gateway; nothing on the bus; bad usage."""

from __future__ import annotations

import collections
import json
import threading
import time
from typing import TYPE_CHECKING, Any

import can
import pytest
import yaml

import gateway.cli.commands.scan as scan_command
from gateway.bus.link import Link
from gateway.cli import main
from gateway.config import load_config
from gateway.core.types import Frame, GatewayState
from gateway.drive.driveset import DriveSet
from gateway.sim.bus import SimulatedControllers
from gateway.sim.registry import simulators_for
from tests.conftest import CONFIG_DIR

if TYPE_CHECKING:
    from pathlib import Path

    from click.testing import CliRunner

    from gateway.runtime.daemon import Daemon

#: One controller of each protocol on one bus: ODrive 0.6 node 1 (answers Get_Version), a
#: factory VESC 10 (no status: only PING finds it), a CiA 402 drive at node 5 (boot-up only, no
#: heartbeat from the factory), DJI ESC 2 (0x202).
MIXED: dict[str, Any] = {
    "name": "mixed_bus", "drive": "mecanum",
    "geometry": {"wheel_radius": 0.05, "wheelbase": 0.4, "track": 0.36},
    "motor_defaults": {"gear_ratio": 10.0, "max_rpm": 3000},
    "motors": {
        "front_left": {"node_id": 1, "driver": "odrive", "firmware": "0.6",
                       "controller_timeout_s": 0.25,
                       "watchdog_endpoints": {"fw_version": "0.0.0", "enable_watchdog": 1,
                                              "watchdog_timeout": 2}},
        "front_right": {"node_id": 10, "driver": "vesc", "pole_pairs": 7,
                        "controller_timeout_s": 1.0},
        "rear_left": {"node_id": 5, "driver": "cia402"},
        "rear_right": {"node_id": 2, "driver": "dji", "esc": "c620",
                       "no_controller_stop": "acknowledged", "gear_ratio": 19.2, "max_rpm": 9000},
    },
    "limits": {"max_wheel_accel_rad_s2": 30.0},
    "bus": {"interface": "virtual", "channel": "wheelgate", "bitrate": 1000000},
}
#: What the simulators send: every frame on these identifiers is theirs (data frames).
SIM_IDS = {(0x020, False), (0x021, False), (0x029, False), (0x202, False), (0x705, False),
           (0x585, False), (0x12FE, True)}


def write_mixed(tmp_path: Path, channel: str) -> Path:
    raw = dict(MIXED, bus={**MIXED["bus"], "channel": channel})
    path = tmp_path / "mixed.yaml"
    path.write_text(yaml.safe_dump(raw))
    return path


def sdo_read(index: int, sub: int) -> Frame:
    return Frame(0x605, bytes([0x40, index & 0xFF, index >> 8, sub, 0, 0, 0, 0]))


def test_the_scan_finds_every_protocol_and_sends_only_reads(
        runner: CliRunner, tmp_path: Path, channel: str) -> None:
    path = write_mixed(tmp_path, channel)
    sims = simulators_for(DriveSet(load_config(path)).all_motors())
    ctl = SimulatedControllers(sims, channel)
    tap = can.Bus(interface="virtual", channel=channel)
    power = threading.Timer(0.2, ctl.start)  # powered while the scan listens: a boot-up
    try:
        power.start()
        result = runner.invoke(main, ["scan", "-c", str(path), "--json", "--timeout", "1.6"])
        seen = []
        while (msg := tap.recv(0)) is not None:
            seen.append(Frame(msg.arbitration_id, bytes(msg.data), msg.is_extended_id,
                              msg.is_remote_frame, msg.dlc))
    finally:
        power.cancel()
        ctl.shutdown()
        tap.shutdown()
    assert result.exit_code == 0, result.output
    rows = {(r["protocol"], r["node_id"]): r for r in json.loads(result.stdout)}
    assert set(rows) == {("odrive", 1), ("vesc", 10), ("canopen", 5), ("dji", 2)}
    odrive, vesc = rows[("odrive", 1)], rows[("vesc", 10)]
    canopen, dji = rows[("canopen", 5)], rows[("dji", 2)]
    assert (odrive["seen_by"], odrive["state"], odrive["errors"], odrive["firmware"]) == (
        "heartbeat", "IDLE", "none", "0.0.0")
    assert [i["id_hex"] for i in odrive["ids"]] == ["0x021", "0x029"]
    assert (vesc["seen_by"], vesc["hardware"], vesc["ids"]) == ("pong", "VESC", [])
    assert (canopen["seen_by"], canopen["state"], canopen["device_type"]) == (
        "boot-up", "booted (pre-operational)", 0x00020192)
    assert canopen["identity"] == {"vendor_id": 0, "product_code": 0x402,
                                   "revision": 0x00010000, "serial": 5}
    assert (dji["seen_by"], dji["readings"]["temperature_c"]) == ("feedback", 35)
    assert {r["wheel"] for r in rows.values()} == {"front_left", "front_right", "rear_left",
                                                   "rear_right"}
    assert all(r["notes"] == [] for r in (odrive, canopen))
    # What reached the bus from the scan: reads only, each once.
    sent = [f for f in seen if (f.arbitration_id, f.is_extended_id) not in SIM_IDS
            or f.is_remote_frame]
    expected = [Frame(0x020, b"", False, True), sdo_read(0x1000, 0),
                *(sdo_read(0x1018, s) for s in (1, 2, 3, 4)),
                *(Frame(0x1100 + k, b"\xfe", True) for k in range(255))]
    assert collections.Counter(sent) == collections.Counter(expected)


def test_the_text_table_fits_80_columns_and_names_what_it_found(
        runner: CliRunner, tmp_path: Path, channel: str) -> None:
    path = write_mixed(tmp_path, channel)
    ctl = SimulatedControllers(simulators_for(DriveSet(load_config(path)).all_motors()),
                               channel)
    ctl.step(time.monotonic())  # powered before the scan: the CANopen boot-up is gone
    ctl.start()
    try:
        result = runner.invoke(main, ["scan", "-c", str(path), "--timeout", "1.2"])
    finally:
        ctl.shutdown()
    assert result.exit_code == 0, result.output
    lines = result.stdout.splitlines()
    assert max(map(len, lines)) <= 80
    assert lines[0].split() == ["PROTOCOL", "NODE", "FOUND", "BY", "DETAILS"]
    firsts = [line.split()[:3] for line in lines if line[:1].strip()][1:4]
    # The CANopen node booted before the scan and sends no heartbeat: it is not there.
    assert firsts == [["DJI", "2", "feedback"], ["ODrive", "1", "heartbeat"],
                      ["VESC", "10", "pong"]]
    text = " ".join(result.stdout.split())
    assert "3 controllers (1 DJI, 1 ODrive, 1 VESC) on virtual:" in text
    assert "note: configured but not found: 'rear_left' (cia402 node 5)" in text
    assert "note: a CANopen node that booted before the scan and sends no heartbeat" in text


def test_the_empty_bus_hint_names_ip_link_only_for_socketcan(
        monkeypatch: pytest.MonkeyPatch) -> None:
    links: dict[str, Link] = {}
    monkeypatch.setattr(scan_command, "read_link", links.get)
    assert "ip -details link show can0" in scan_command.nothing_found_hint("socketcan", "can0")
    multicast = scan_command.nothing_found_hint("udp_multicast", "239.74.163.2")
    assert "ip -details" not in multicast and "udp_multicast:239.74.163.2" in multicast
    assert "bitrate" not in multicast  # (a network carries frames, at no bitrate of its own)
    links["vcan0"] = Link("vcan0", "vcan", True, None, None)  # no bitrate to name
    assert ("that the link is up at the controllers' bitrate (ip -details link show vcan0)"
            in scan_command.nothing_found_hint("socketcan", "vcan0"))


def test_the_empty_bus_hint_names_the_bitrate_the_scan_ran_at(
        monkeypatch: pytest.MonkeyPatch) -> None:
    # The usual reason for silence at a first power-on: a bitrate other than the controllers'.
    links: dict[str, Link] = {"can0": Link("can0", "can", True, 500000, "ERROR-ACTIVE")}
    monkeypatch.setattr(scan_command, "read_link", links.get)
    hint = " ".join(scan_command.nothing_found_hint("socketcan", "can0").split())
    assert ("that the controllers talk at 500000 bit/s, the link's (at another bitrate N: sudo "
            "ip link set can0 down && sudo ip link set can0 up type can bitrate N restart-ms "
            "100), the wiring") in hint
    links["can0"] = Link("can0", "can", False, 250000, "STOPPED")
    assert ("the link: it is down (bring it up at the controllers' bitrate: sudo ip link set "
            "can0 down && sudo ip link set can0 up type can bitrate 250000 restart-ms 100)"
            in scan_command.nothing_found_hint("socketcan", "can0"))
    assert "bitrate 1000000 restart-ms" in scan_command.nothing_found_hint(
        "socketcan", "can0", 1000000)  # (the configuration's, when the scan was told one)
    assert ("that the controllers talk at python-can's default bitrate of its pcan interface "
            "(give theirs with --bitrate)") in scan_command.nothing_found_hint("pcan", "X")
    assert ("that the controllers talk at 1000000 bit/s, the bitrate the scan used" in
            scan_command.nothing_found_hint("pcan", "X", 1000000))


def test_beside_a_running_gateway(runner: CliRunner, daemon: Daemon, channel: str) -> None:
    """The daemon's simulated ODrives are found armed, its messages named; it runs on,
    with no fault."""
    config = str(CONFIG_DIR / "turtlebot3_burger.yaml")
    result = runner.invoke(main, ["--interface", "virtual", "--channel", channel, "scan", "-c",
                                  config, "--json", "--timeout", "1"])
    assert result.exit_code == 0, result.output
    rows = json.loads(result.stdout)
    odrives = [(r["node_id"], r["wheel"], r["state"], r["firmware"]) for r in rows
               if r["protocol"] == "odrive"]
    assert odrives == [(1, "left", "CLOSED_LOOP_CONTROL", "0.0.0"),
                       (2, "right", "CLOSED_LOOP_CONTROL", "0.0.0")]
    own = {r["message"] for r in rows if r["protocol"] == "wheelgate"}
    assert "WG_Status" in own
    assert all(r["node_id"] is None for r in rows if r["protocol"] in ("wheelgate", "unknown"))
    assert daemon.gateway.state is GatewayState.RUNNING
    assert all(not s.faults and s.state.name == "ENABLED"
               for s in daemon.gateway.drives.status(0.0))


def test_nothing_on_the_bus_says_so_and_exits_0(runner: CliRunner, channel: str) -> None:
    result = runner.invoke(main, ["--interface", "virtual", "--channel", channel, "scan",
                                  "--timeout", "0.3"])
    assert result.exit_code == 0, result.output
    text = " ".join(result.stdout.split())
    assert text.startswith(f"no controller answered in 0.3 s on virtual:{channel}")
    assert "hint: python-can's virtual bus" in text
    result = runner.invoke(main, ["--interface", "virtual", "--channel", channel, "scan",
                                  "--json", "--timeout", "0.3"])
    assert result.exit_code == 0
    assert json.loads(result.stdout) == []
    assert "no controller answered in 0.3 s" in " ".join(result.stderr.split())


@pytest.mark.parametrize("value", ["0", "-1", "nan", "inf", "3601", "soon"])
def test_a_bad_timeout_is_a_usage_error(runner: CliRunner, value: str) -> None:
    result = runner.invoke(main, ["scan", "--timeout", value])
    assert result.exit_code == 2, result.output
    assert "--timeout" in result.stderr
