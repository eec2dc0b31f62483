"""``wheelgate scan``'s pure classifier: golden frames of each protocol (the worked examples of
the protocols' references) sorted into controllers, the identifiers two protocols share given
to the right one, what each controller owns, and the probes' descriptions."""

from __future__ import annotations

import pytest

from gateway.apps.scan.classify import Classified, classify
from gateway.apps.scan.registry import load_probes
from gateway.core.types import Frame
from gateway.drive.labels import OWN_MESSAGES
from gateway.drive.scan import Answer, Found, Heard, ScanProbe
from gateway.wire.can import CanIds

PROBES = load_probes()
#: The gateway's own messages at their default identifiers (0x100..0x104).
OWN = {(getattr(CanIds(), k), False): name for k, name in OWN_MESSAGES.items()}


def heard(arb: int, data: str, ext: bool = False, rate_hz: float = 10.0, count: int = 10,
          remote: bool = False) -> Heard:
    """Traffic on one identifier whose latest frame carries ``data`` (hex)."""
    last = None if remote else Frame(arb, bytes.fromhex(data), ext)
    return Heard(arb, ext, count, rate_hz, last)


def found(*traffic: Heard) -> list[tuple[str, int, str]]:
    """``(protocol, node, seen_by)`` of every controller the traffic shows."""
    cls = classify(PROBES, traffic, OWN)
    return [(s.probe.PROTOCOL, s.found.node_id, s.found.seen_by) for s in cls.devices]


def probe(protocol: str) -> ScanProbe:
    return next(p for p in PROBES if p.PROTOCOL == protocol)


def test_the_probes_load_in_precedence_order() -> None:
    assert [p.PROTOCOL for p in PROBES] == ["canopen", "dji", "vesc", "odrive"]
    assert [p.DRIVER for p in PROBES] == ["cia402", "dji", "vesc", "odrive"]


@pytest.mark.parametrize(("traffic", "expected"), [
    # ODrive heartbeats, node 3 (0x061): 0.6 (CLOSED_LOOP, SUCCESS, trajectory done), 0.5.
    (heard(0x061, "0000000008000100"), ("odrive", 3, "heartbeat")),
    (heard(0x061, "0000000008000080"), ("odrive", 3, "heartbeat")),
    # 29-bit identifiers: node 0xFEDCBA's heartbeat (0xFEDCBA << 5 | 1).
    (heard(0x1FDB9741, "0000000001000000", ext=True), ("odrive", 0xFEDCBA, "heartbeat")),
    # CANopen: a heartbeat (operational) of node 3, the boot-up of node 5.
    (heard(0x703, "05"), ("canopen", 3, "heartbeat")),
    (heard(0x705, "00", count=1), ("canopen", 5, "boot-up")),
    # VESC 23: STATUS (700 ERPM, 12.3 A, duty 0.5) and STATUS_5 (tacho 4200, 24.5 V).
    (heard(0x917, "000002BC007B01F4", ext=True), ("vesc", 23, "status")),
    (heard(0x1B17, "0000106800F50000", ext=True), ("vesc", 23, "status")),
    # DJI ESC 1: ecd 8191, 1500 rpm, -200, 35 degC, at the ESC's rate.
    (heard(0x201, "1FFF05DCFF382300", rate_hz=1000.0), ("dji", 1, "feedback")),
    (heard(0x207, "1FFF05DCFF382300", rate_hz=1000.0), ("dji", 7, "feedback")),
])
def test_each_protocol_is_found_by_its_golden_frame(traffic: Heard,
                                                    expected: tuple[str, int, str]) -> None:
    assert found(traffic) == [expected]


@pytest.mark.parametrize("traffic", [
    heard(0x061, "00000000080001"),  # a heartbeat of 7 bytes
    heard(0x061, "00000000FF000000"),  # axis state 255: no state
    heard(0x703, "06"),  # no NMT state
    heard(0x703, "0500"),  # two bytes
    heard(0x780, "05"),  # node 128
    heard(0x917, "000002BC007B01F4"),  # STATUS with an 11-bit identifier
    heard(0x10917, "000002BC007B01F4", ext=True),  # bits above 15
    heard(0x317, "000002BC", ext=True),  # a command (SET_RPM), not a status
    heard(0x201, "FFFF05DCFF382300", rate_hz=1000.0),  # angle 65535 > 8191
    heard(0x20C, "1FFF05DCFF382300", rate_hz=1000.0),  # past the feedback range
    heard(0x061, "", remote=True),  # only requests heard
])
def test_frames_that_only_look_like_a_protocol_show_no_controller(traffic: Heard) -> None:
    cls = classify(PROBES, [traffic], OWN)
    assert cls.devices == ()
    assert cls.unknown == (traffic,)


def test_a_canopen_heartbeat_takes_the_identifiers_an_odrive_would_share() -> None:
    """0x181 is ODrive node 12's heartbeat and CANopen node 1's TPDO1: with node 1's heartbeat
    on 0x701 it is the CANopen node's (and ODrive node 56's heartbeat 0x701 has 8 bytes, not
    one)."""
    tpdo1 = heard(0x181, "0000000001000000", rate_hz=100.0)
    assert found(tpdo1) == [("odrive", 12, "heartbeat")]
    cls = classify(PROBES, [tpdo1, heard(0x701, "7F")], OWN)
    assert [(s.probe.PROTOCOL, s.found.node_id) for s in cls.devices] == [("canopen", 1)]
    assert cls.devices[0].heard == (tpdo1, heard(0x701, "7F"))
    assert found(heard(0x701, "0000000001000000")) == [("odrive", 56, "heartbeat")]


def test_an_odrive_at_node_16_is_not_taken_for_dji_escs() -> None:
    """0x201 and 0x209 are ODrive node 16's heartbeat (10 Hz) and estimates (100 Hz), and DJI
    ESC 1's feedback and a GM6020's: DJI only at an ESC's rate or beside another DJI ID."""
    odrive = [heard(0x201, "0000000001000000"), heard(0x209, "0000000000000000", rate_hz=100.0)]
    assert found(*odrive) == [("odrive", 16, "heartbeat")]
    cls = classify(PROBES, odrive, OWN)
    assert cls.devices[0].heard == tuple(odrive)
    esc1 = heard(0x201, "1FFF05DCFF382300", rate_hz=1000.0)
    assert found(esc1) == [("dji", 1, "feedback")]
    slow = [heard(0x201, "1FFF05DCFF382300", rate_hz=20.0),
            heard(0x202, "000000000000", rate_hz=20.0)]
    assert found(*slow) == []  # 0x202 has 6 bytes: no feedback, so nothing beside 0x201
    slow[1] = heard(0x202, "0000000000002300", rate_hz=20.0)
    assert found(*slow) == [("dji", 1, "feedback"), ("dji", 2, "feedback")]


def test_vesc_status_comes_before_an_odrive_with_29_bit_identifiers() -> None:
    """VESC 1's STATUS 0x901 is also ODrive node 0x48's heartbeat in 29-bit identifiers."""
    assert found(heard(0x901, "0000000001000000", ext=True)) == [("vesc", 1, "status")]


def test_the_gateways_own_messages_are_named_not_taken_for_a_controller() -> None:
    """WG_Odom_Pose on 0x101 is where an ODrive at node 8 would send its heartbeat."""
    pose = heard(0x101, "0000000001000000", rate_hz=20.0)
    cls = classify(PROBES, [pose, heard(0x123, "01", rate_hz=25.0)], OWN)
    assert cls.devices == ()
    assert cls.own == (("WG_Odom_Pose", pose),)
    assert [h.arbitration_id for h in cls.unknown] == [0x123]
    assert found(pose) == []
    assert classify(PROBES, [pose], {}).devices[0].found == Found(8, False, "heartbeat")


def test_a_controller_lists_the_identifiers_it_owns() -> None:
    """A gateway's commands to the controllers (and their other frames) go with them."""
    traffic = [
        heard(0x061, "0000000008000100"), heard(0x069, "00004841000010C0"),
        heard(0x06D, "0000204100000000", rate_hz=100.0),  # Set_Input_Vel from a gateway
        heard(0x705, "05"), heard(0x185, "3702E6030000"), heard(0x605, "2B40600006000000"),
        heard(0x085, "1023050000000000"),
        heard(0x917, "000002BC007B01F4", ext=True), heard(0x317, "000002BC", ext=True),
        heard(0x202, "1FFF05DCFF382300", rate_hz=1000.0),
        heard(0x200, "0FA0F060000003E8", rate_hz=1000.0),  # the DJI command of ESC 1..4
        heard(0x7FF, "00"),
    ]
    cls = classify(PROBES, traffic, OWN)
    owned = {s.probe.PROTOCOL: sorted(h.arbitration_id for h in s.heard) for s in cls.devices}
    assert owned == {"canopen": [0x085, 0x185, 0x605, 0x705], "dji": [0x200, 0x202],
                     "vesc": [0x317, 0x917], "odrive": [0x061, 0x069, 0x06D]}
    assert [h.arbitration_id for h in cls.unknown] == [0x7FF]


def test_discovery_answers_show_controllers_that_send_nothing_unasked() -> None:
    vesc = probe("vesc")
    ping = vesc.discovery()[23]
    pong = Answer(ping, Frame(0x12FE, bytes((23, 0)), True))
    shown = vesc.found_by(pong)
    assert shown is not None
    cls = classify(PROBES, [], OWN, [(vesc, shown)])
    assert [(s.probe.PROTOCOL, s.found) for s in cls.devices] == [
        ("vesc", Found(23, True, "pong"))]
    assert vesc.found_by(Answer(ping, None)) is None
    # Heard by its status too: the status is what showed it.
    both = classify(PROBES, [heard(0x917, "000002BC007B01F4", ext=True)], OWN,
                    [(vesc, Found(23, True, "pong"))])
    assert [s.found.seen_by for s in both.devices] == ["status"]


def test_owner_names_the_controller_an_identifier_belongs_to() -> None:
    cls = classify(PROBES, [heard(0x061, "0000000001000000")], OWN)
    owner = cls.owner(0x06D, False)
    assert owner is not None and owner.found.node_id == 3
    assert cls.owner(0x06D, True) is None
    assert Classified().owner(0x06D, False) is None


# ----------------------------------------------------------------------------- descriptions


def test_the_odrive_description_reads_the_heartbeat_estimates_and_version() -> None:
    odrive = probe("odrive")
    f = Found(3, False, "heartbeat")
    traffic = [heard(0x061, "0008000008000100"), heard(0x069, "00004841000010C0")]
    (ask,) = odrive.requests(f, traffic)
    assert ask.frame == Frame(0x060, b"", is_remote_frame=True)
    version = Frame(0x060, bytes([2, 4, 4, 58, 0, 6, 10, 0]))
    assert ask.answered_by(version)
    assert not ask.answered_by(Frame(0x060, b"", is_remote_frame=True))
    d = odrive.describe(f, traffic, [Answer(ask, version)])
    assert (d.state, d.errors, d.firmware, d.hardware) == (
        "CLOSED_LOOP_CONTROL", "DC_BUS_OVER_REGEN_CURRENT", "0.6.10", "4.4.58")
    assert d.readings == (("position_turns", 12.5), ("velocity_turns_s", -2.25),
                          ("procedure_result", "SUCCESS"))
    # No answer: 0.5 (which has no Get_Version), its error word in hex.
    d = odrive.describe(f, traffic, [Answer(ask, None)])
    assert (d.errors, d.firmware) == ("0x00000800", None)
    assert d.notes == ("no answer to Get_Version: firmware 0.5 (which has none), or an axis "
                       "that is not an ODrive",)
    # A "heartbeat" in state UNDEFINED, which no ODrive reports, with no version: doubtful.
    undefined = [heard(0x061, "0000000000000100")]
    d = odrive.describe(f, undefined, [Answer(ask, None)])
    assert d.state == "UNDEFINED" and len(d.notes) == 2
    assert d.notes[1].startswith("doubtful: its heartbeat says axis state UNDEFINED (0)")
    assert len(odrive.describe(f, undefined, [Answer(ask, version)]).notes) == 0


def test_the_canopen_description_reads_the_sdo_answers() -> None:
    canopen = probe("canopen")
    f = Found(5, False, "heartbeat")
    traffic = [heard(0x705, "7F")]
    asks = canopen.requests(f, traffic)
    assert [a.frame for a in asks] == [
        Frame(0x605, bytes.fromhex("4000100000000000")),
        *(Frame(0x605, bytes.fromhex(f"40 18 10 0{sub} 00 00 00 00")) for sub in "1234")]
    values = ["43 00 10 00 92 01 02 00", "43 18 10 01 9A 00 00 00", "43 18 10 02 24 09 03 00",
              "80 18 10 03 11 00 09 06", None]
    answers = [Answer(a, None if v is None else Frame(0x585, bytes.fromhex(v)))
               for a, v in zip(asks, values, strict=True)]
    assert all(a.request.answered_by(a.frame) for a in answers if a.frame is not None)
    assert not asks[0].answered_by(Frame(0x585, bytes.fromhex("43 18 10 01 9A 00 00 00")))
    d = canopen.describe(f, traffic, answers)
    assert d.state == "pre-operational"
    assert d.device_type == 0x00020192
    assert d.identity is not None
    assert (d.identity.vendor_id, d.identity.product_code, d.identity.revision,
            d.identity.serial) == (0x9A, 0x030924, None, None)
    assert d.notes == ("SDO read of 0x1018:03 aborted: 0x06090011 Subindex does not exist",
                       "no answer to the SDO read of 0x1018:04")
    # A node that answers nothing (a master's heartbeat): one note.
    d = canopen.describe(f, traffic, [Answer(a, None) for a in asks])
    assert d.notes == ("no answer to any SDO read: not an SDO server (a master's heartbeat, "
                       "such as a gateway's host_node_id), or gone",)
    # A stopped node serves no SDO: nothing to ask.
    stopped = [heard(0x705, "04")]
    assert canopen.requests(f, stopped) == ()
    assert "NMT STOPPED" in canopen.describe(f, stopped, []).notes[0]


def test_the_vesc_and_dji_descriptions_read_the_latest_frames() -> None:
    vesc, dji = probe("vesc"), probe("dji")
    f = Found(23, True, "status")
    traffic = [heard(0x917, "000002BC007B01F4", ext=True),
               heard(0x1B17, "0000106800F50000", ext=True)]
    ping = vesc.discovery()[23]
    assert ping.frame == Frame(0x1117, bytes((254,)), True)
    d = vesc.describe(f, traffic, [Answer(ping, Frame(0x12FE, bytes((23, 0)), True))])
    assert d.hardware == "VESC"
    assert d.readings == (("erpm", 700), ("current_a", 12.3), ("duty", 0.5),
                          ("tachometer", 4200), ("v_in_v", 24.5))
    d = vesc.describe(Found(9, True, "pong"), [], [Answer(vesc.discovery()[9], None)])
    assert d.notes[0].startswith("no status messages") and d.notes[1] == "no PONG"
    d = dji.describe(Found(1, False, "feedback"), [heard(0x201, "1FFF05DCFF382300")], [])
    assert d.readings == (("angle_count", 8191), ("speed_rpm", 1500), ("current_raw", -200),
                          ("temperature_c", 35))
    assert dji.requests(Found(1, False, "feedback"), []) == ()
