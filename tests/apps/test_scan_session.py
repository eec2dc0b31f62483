"""``wheelgate scan``'s course on simulated time (no bus, no clock): silent while listening,
the requests' golden bytes and order, answers read and not counted as traffic, no request on
another protocol's identifier, and the report as a table and as JSON."""

from __future__ import annotations

import json

import pytest

from gateway.apps.scan import ScanReport, ScanSession, ScanTiming, render, report_json
from gateway.apps.scan.own import own_messages
from gateway.apps.scan.registry import load_probes
from gateway.apps.scan.report import ScannedDevice
from gateway.config import load_config
from gateway.core.types import Frame, MotorConfig
from gateway.drive.scan import Description, Heard, Identity
from tests.conftest import CONFIG_DIR

PROBES = load_probes()
#: Listen 0.5 s, answers within 0.25 s, a request every 2 ms, 2 s in all.
TIMING = ScanTiming(2.0, 0.5, 0.25, 0.002)
HEARTBEAT_3 = Frame(0x061, bytes.fromhex("0000000001000100"))  # ODrive node 3, IDLE
BOOT_UP_5 = Frame(0x705, b"\x00")  # CANopen node 5
PING = 0x1100  # (17 << 8): PING to controller 0; the pinger is 254


def sdo_read(index: int, sub: int) -> Frame:
    return Frame(0x605, bytes([0x40, index & 0xFF, index >> 8, sub, 0, 0, 0, 0]))


def run(session: ScanSession, until_s: float, answer: dict[Frame, Frame] | None = None,
        start_s: float = 0.0) -> list[tuple[float, Frame]]:
    """Poll every millisecond until ``until_s``; each frame sent is answered at once when
    ``answer`` has it.  The frames sent, with their times."""
    sent = []
    for k in range(round((until_s - start_s) * 1000)):
        t = start_s + k / 1000
        for frame in session.poll(t):
            sent.append((t, frame))
            if answer and frame in answer:
                session.on_frame(answer[frame], t)
    return sent


def test_nothing_goes_out_while_listening_then_one_request_every_2_ms() -> None:
    session = ScanSession(PROBES, TIMING, 0.0)
    session.on_frame(HEARTBEAT_3, 0.1)
    session.on_frame(BOOT_UP_5, 0.2)
    assert run(session, 0.5) == []
    sent = run(session, 0.51, start_s=0.5)
    # The interviews first (CANopen, then ODrive: probe order), then the VESC PINGs.
    assert [f for _, f in sent] == [
        sdo_read(0x1000, 0), Frame(0x060, b"", is_remote_frame=True),
        Frame(PING, b"\xfe", True), Frame(PING + 1, b"\xfe", True),
        Frame(PING + 2, b"\xfe", True)]
    assert [t for t, _ in sent] == [0.5, 0.502, 0.504, 0.506, 0.508]


def test_answers_are_read_and_lead_to_the_next_request() -> None:
    known = [MotorConfig("rear_left", "cia402", 5), MotorConfig("rear_right", "vesc", 7)]
    session = ScanSession(PROBES, TIMING, 0.0, known=known)
    session.on_frame(HEARTBEAT_3, 0.1)
    session.on_frame(BOOT_UP_5, 0.2)
    answers = {
        sdo_read(0x1000, 0): Frame(0x585, bytes.fromhex("43 00 10 00 92 01 02 00")),
        sdo_read(0x1018, 1): Frame(0x585, bytes.fromhex("43 18 10 01 00 00 00 00")),
        sdo_read(0x1018, 4): Frame(0x585, bytes.fromhex("43 18 10 04 05 00 00 00")),
        Frame(0x060, b"", is_remote_frame=True): Frame(0x060, bytes([2, 0, 0, 0, 0, 6, 11, 0])),
        Frame(PING + 23, b"\xfe", True): Frame(0x12FE, bytes([23, 0]), True),
    }
    sent = [f for _, f in run(session, 2.0, answers)]
    # Each answer lets the next read out before any PING; 0x1018:02 gets none.
    assert sent[:5] == [sdo_read(0x1000, 0), Frame(0x060, b"", is_remote_frame=True),
                        sdo_read(0x1018, 1), sdo_read(0x1018, 2), Frame(PING, b"\xfe", True)]
    assert [f for f in sent if f.arbitration_id == 0x605] == [
        sdo_read(0x1000, 0), *(sdo_read(0x1018, s) for s in (1, 2, 3, 4))]
    assert len(sent) == session.requests_sent == 5 + 1 + 255
    assert sorted(f.arbitration_id for f in sent if f.is_extended_id) == list(
        range(PING, PING + 255))
    report = session.report(2.0, "virtual:test")
    assert [(r.protocol, r.node_id, r.seen_by) for r in report.rows] == [
        ("canopen", 5, "boot-up"), ("odrive", 3, "heartbeat"), ("vesc", 23, "pong")]
    canopen, odrive, vesc = report.rows
    assert canopen.wheel == "rear_left" and odrive.wheel is None
    assert canopen.description.device_type == 0x00020192
    assert canopen.description.identity == Identity(0, None, None, 5)
    assert canopen.description.notes == ("no answer to the SDO read of 0x1018:02",
                                         "no answer to the SDO read of 0x1018:03")
    assert (odrive.description.state, odrive.description.firmware) == ("IDLE", "0.6.11")
    assert vesc.description.hardware == "VESC"
    # Answers are not traffic: each controller lists only what it sent unasked.
    assert [h.arbitration_id for h in canopen.ids] == [0x705]
    assert [h.arbitration_id for h in odrive.ids] == [0x061]
    assert vesc.ids == ()
    assert report.notes == ("configured but not found: 'rear_right' (vesc node 7)",)


def test_late_answers_are_not_traffic_and_other_frames_are() -> None:
    session = ScanSession(PROBES, TIMING, 0.0)
    run(session, 0.6)  # every PING to 0..49 went out by now
    session.on_frame(Frame(0x12FE, bytes([3, 0]), True), 1.5)  # PING 3 timed out at 0.756
    for k in range(10):
        session.on_frame(Frame(0x123, b"\x01"), 0.1 * k)
    report = session.report(2.0, "virtual:test")
    assert [(r.protocol, r.node_id, [h.arbitration_id for h in r.ids]) for r in report.rows] == [
        ("unknown", None, [0x123])]
    (row,) = report.rows
    assert row.ids[0].count == 10 and row.ids[0].rate_hz == pytest.approx(10.0)


def test_no_request_goes_to_another_protocols_identifier() -> None:
    """ODrive node 0's Get_Version would be an RTR on 0x000, CANopen's NMT; node 56's on
    0x700, which puts a DJI C620 into quick ID-setting mode; an ODrive with 29-bit identifiers
    at node 136 takes the VESC PINGs 0x1100..0x111F; 0x060 is a gateway message here."""
    own = {(0x060, False): "WG_Something"}
    session = ScanSession(PROBES, TIMING, 0.0, own_ids=own)
    for frame in (Frame(0x001, bytes.fromhex("0000000001000100")),  # ODrive node 0
                  Frame(0x705, b"\x05"),  # CANopen node 5
                  Frame(0x701, bytes.fromhex("0000000001000100")),  # ODrive node 56
                  Frame(0x202, bytes.fromhex("1FFF05DCFF382300")),  # DJI ESC 2
                  Frame(0x1101, bytes.fromhex("0000000001000100"), True),  # ODrive node 136
                  HEARTBEAT_3):
        session.on_frame(frame, 0.1)
    sent = [f for _, f in run(session, 2.0)]
    ids = {(f.arbitration_id, f.is_extended_id) for f in sent}
    assert not ids & {(0x000, False), (0x700, False), (0x060, False)}
    pings = {f.arbitration_id for f in sent if f.is_extended_id and not f.is_remote_frame}
    assert pings == set(range(PING + 32, PING + 255))
    assert Frame(0x1100, b"", True, is_remote_frame=True) in sent  # node 136's Get_Version
    assert (0x605, False) in ids
    report = session.report(2.0, "virtual:test")
    notes = {(r.protocol, r.node_id): r.description.notes for r in report.rows}
    assert notes[("odrive", 0)] == ("Get_Version not asked: every CANopen device takes 0x000",)
    assert notes[("odrive", 56)] == ("Get_Version not asked: every DJI device takes 0x700",)
    assert notes[("odrive", 3)] == ("Get_Version not asked: 0x060 is wheelgate's WG_Something",)
    assert report.notes == ("VESC PING not sent to 32 node(s): 0x00001100 is ODrive node "
                            "136's (and 31 more)",)


def test_a_scan_cut_short_says_what_it_did_not_ask() -> None:
    session = ScanSession(PROBES, ScanTiming(0.4, 0.1, 0.25), 0.0)
    session.on_frame(HEARTBEAT_3, 0.05)
    run(session, 0.4)
    report = session.report(0.4, "virtual:test")
    assert report.notes == ("VESC: 106 of 255 discovery requests not sent before the scan "
                            "ended: give a longer --timeout",)
    listening = ScanSession(PROBES, TIMING, 0.0)
    listening.on_frame(HEARTBEAT_3, 0.05)
    report = listening.report(0.3, "virtual:test")
    assert report.notes == ("the scan ended while listening: nothing was asked",)
    assert report.rows[0].description.notes == (
        "found too late to be asked anything: give a longer --timeout",)


# ----------------------------------------------------------------------------- the report

REPORT = ScanReport("socketcan:can0", 2.0, (
    ScannedDevice("canopen", "CANopen", "cia402", 5, False, "boot-up",
                  (Heard(0x705, False, 1, 0.5, None),),
                  Description(state="booted (pre-operational)", device_type=0x00020192,
                              identity=Identity(0x9A, 0x30924, 0x10000, 5)), "rear_left"),
    ScannedDevice("odrive", "ODrive", "odrive", 3, False, "heartbeat",
                  (Heard(0x061, False, 20, 10.0, None), Heard(0x069, False, 200, 100.0, None)),
                  Description(state="IDLE", errors="none", firmware="0.6.11",
                              hardware="4.4.58")),
    ScannedDevice("wheelgate", "wheelgate", None, None, False, None,
                  (Heard(0x103, False, 10, 5.0, None),), message="WG_Status"),
    ScannedDevice("unknown", "unknown", None, None, True, None,
                  (Heard(0x18FF0001, True, 50, 25.0, None),)),
), 257, ("a note about the scan",))

TEXT = """\
PROTOCOL      NODE  FOUND BY   DETAILS
CANopen          5  boot-up    configured as 'rear_left'; booted
                               (pre-operational); device type 0x00020192 (CiA
                               402); vendor 0x0000009A, product 0x00030924,
                               revision 0x00010000, serial 0x00000005; ids 0x705
                               once
ODrive           3  heartbeat  IDLE; errors none; firmware 0.6.11; hardware
                               4.4.58; ids 0x061 10/s, 0x069 100/s
wheelgate        -  -          WG_Status; ids 0x103 5/s
unknown          -  -          ids 0x18FF0001 25/s
2 controllers (1 CANopen, 1 ODrive) on socketcan:can0 in 2 s; 257 request(s)
  sent
note: a note about the scan"""


def test_the_table_fits_80_columns() -> None:
    assert render(REPORT) == TEXT
    assert max(len(line) for line in render(REPORT).splitlines()) <= 80
    empty = ScanReport("virtual:wheelgate", 1.5, ())
    assert render(empty) == "no controller answered in 1.5 s on virtual:wheelgate"


def test_the_json_has_every_key_on_every_row() -> None:
    rows = json.loads(json.dumps(report_json(REPORT)))
    assert [(r["protocol"], r["node_id"]) for r in rows] == [
        ("canopen", 5), ("odrive", 3), ("wheelgate", None), ("unknown", None)]
    assert all(set(r) == set(rows[0]) for r in rows)
    assert rows[0]["identity"] == {"vendor_id": 0x9A, "product_code": 0x30924,
                                   "revision": 0x10000, "serial": 5}
    assert rows[0]["wheel"] == "rear_left" and rows[0]["driver"] == "cia402"
    assert rows[1]["ids"] == [
        {"id": 0x061, "id_hex": "0x061", "extended": False, "count": 20, "rate_hz": 10.0},
        {"id": 0x069, "id_hex": "0x069", "extended": False, "count": 200, "rate_hz": 100.0}]
    assert rows[2]["message"] == "WG_Status"
    assert rows[3]["ids"][0]["id_hex"] == "0x18FF0001"


def test_the_gateways_own_frames_come_from_the_configuration() -> None:
    """Its five messages always; with the configuration's drivers, what they send to all their
    controllers: the gateway's CANopen heartbeat (host node 127), SYNC and NMT, DJI commands."""
    wg = {(0x100 + k, False): name for k, name in enumerate(
        ("WG_Twist_Cmd", "WG_Odom_Pose", "WG_Odom_Velocity", "WG_Status", "WG_Error"))}
    dji = load_config(CONFIG_DIR / "mecanum.yaml")
    assert own_messages(dji, drivers=False) == wg
    assert own_messages(dji, drivers=True) == {**wg, (0x200, False): "DJI COMMAND_ESC_1_4"}
    tricycle = load_config(CONFIG_DIR / "tricycle.yaml")
    bus_wide = {k: v for k, v in own_messages(tricycle, drivers=True).items() if k not in wg}
    assert bus_wide == {(0x000, False): "CiA 402 NMT", (0x77F, False): "CiA 402 HEARTBEAT",
                        (0x080, False): "CiA 402 SYNC"}


def test_only_a_pong_as_the_firmware_sends_it_shows_a_vesc() -> None:
    """vedderb/bldc ``comm_can.c`` answers a PING with two bytes, its ID and HW_TYPE (one byte,
    the ID, before HW_TYPE was added).  Eight bytes on 0x12FE that start with a pinged ID, a
    remote frame there, or a PONG naming an ID not pinged are no answer: counted as traffic on the
    identifier, no VESC made of them, and the real PONG after them still answers."""
    session = ScanSession(PROBES, TIMING, 0.0)
    run(session, 0.6)  # PINGs 0..49 went out from 0.5 s, 2 ms apart: PING k at 0.5 + 0.002 k
    session.on_frame(Frame(0x12FE, bytes([23, 0, 0, 0, 0, 0, 0, 0]), True), 0.6)
    session.on_frame(Frame(0x12FE, b"", True, is_remote_frame=True), 0.6)
    session.on_frame(Frame(0x12FE, bytes([200]), True), 0.6)  # PING 200 has not gone out
    session.on_frame(Frame(0x12FE, bytes([30, 0, 0]), True), 0.6)  # three bytes
    session.on_frame(Frame(0x12FE, bytes([23, 0]), True), 0.61)  # VESC 23, HW_TYPE_VESC
    session.on_frame(Frame(0x12FE, bytes([31]), True), 0.61)  # VESC 31, old firmware
    report = session.report(2.0, "virtual:test")
    assert [(r.protocol, r.node_id, r.seen_by) for r in report.rows] == [
        ("vesc", 23, "pong"), ("vesc", 31, "pong"), ("unknown", None, None)]
    unknown = report.rows[2]
    assert [(h.arbitration_id, h.is_extended_id, h.count) for h in unknown.ids] == [
        (0x12FE, True, 4)]
    assert [r.description.hardware for r in report.rows[:2]] == ["VESC", "VESC"]
