"""``wheelgate scan -c``: the identifiers a configured motor's driver declares are that motor's.

A DBC controller's feedback (WD_Feedback, 0x280 + node) has the shape of an ODrive heartbeat of
node 20; with the configuration, it is the configured motor's, found and named, and no
Get_Version goes to a would-be ODrive.  On the virtual bus, with the example's simulated
controllers in this process.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from gateway.apps.scan import ScanSession, ScanTiming, render, scan
from gateway.apps.scan.own import MotorClaims, motor_claims, own_messages
from gateway.apps.scan.registry import load_probes
from gateway.config import load_config
from gateway.core.types import Frame, MotorConfig
from gateway.drive.claims import FrameClaim
from gateway.sim.bus import SimulatedControllers
from gateway.sim.registry import simulator_for
from tests.conftest import CONFIG_DIR

if TYPE_CHECKING:
    from pathlib import Path

    from gateway.apps.scan import ScanReport
    from gateway.core.settings import GatewayConfig

PROBES = load_probes()
TIMING = ScanTiming(2.0, 0.5, 0.25, 0.002)
#: Every VESC PING (controller IDs 0..254): the discovery requests of a scan.
PINGS = 255


def scan_dbc(channel: str, configured: bool) -> tuple[GatewayConfig, ScanReport]:
    """Scan the example_dbc robot's simulated controllers for 1 s, with or without ``-c``."""
    cfg = load_config(CONFIG_DIR / "example_dbc.yaml",
                      {"interface": "virtual", "channel": channel})
    motors = [m for m in cfg.motors if m is not None]
    ctl = SimulatedControllers([simulator_for(m) for m in motors], channel,
                               interface="virtual").start()
    try:
        if configured:
            return cfg, scan("virtual", channel, 1.0, own_messages(cfg, drivers=True), motors,
                             motor_claims(cfg))
        return cfg, scan("virtual", channel, 1.0, own_messages(cfg, drivers=False))
    finally:
        ctl.shutdown()


def test_a_dbc_controllers_feedback_is_its_configured_motor_not_an_odrive(
        channel: str) -> None:
    _, report = scan_dbc(channel, configured=True)
    rows = [(r.protocol, r.node_id, r.seen_by, r.wheel, [h.arbitration_id for h in r.ids])
            for r in report.rows]
    assert rows == [("dbc", 1, "config", "left", [0x281]), ("dbc", 2, "config", "right", [0x282])]
    assert all(h.rate_hz > 50 for r in report.rows for h in r.ids)  # 100/s from the simulator
    assert report.requests_sent == PINGS  # no Get_Version to an "ODrive 20"
    assert not any("not found" in n for n in report.notes)
    assert all(r.title == "DBC" for r in report.controllers)


def test_without_a_configuration_the_guess_is_what_it_is(channel: str) -> None:
    _, report = scan_dbc(channel, configured=False)
    assert [(r.protocol, r.node_id) for r in report.rows] == [("odrive", 20)]
    (row,) = report.rows
    assert any("not an ODrive" in n for n in row.description.notes)


def test_the_motor_claims_are_every_motors_own_frames() -> None:
    cfg = load_config(CONFIG_DIR / "example_dbc.yaml")
    claims = {c.motor.wheel: c for c in motor_claims(cfg)}
    assert set(claims) == {"left", "right"}
    assert claims["left"].owns(0x281, False) and not claims["left"].owns(0x282, False)
    assert not claims["left"].owns(0x281, True)


def test_a_configured_odrive_is_still_found_and_asked_by_its_probe() -> None:
    """The claimed heartbeat goes to the ODrive probe: the axis is found, named, and asked."""
    cfg = load_config(CONFIG_DIR / "turtlebot3_burger.yaml")
    motors = [m for m in cfg.motors if m is not None]
    session = ScanSession(PROBES, TIMING, 0.0, known=motors, claimed=motor_claims(cfg))
    session.on_frame(Frame(0x021, bytes.fromhex("0000000001000100")), 0.1)  # node 1, IDLE
    sent = [f for k in range(2000) for f in session.poll(k / 1000)]
    assert Frame(0x020, b"", is_remote_frame=True) in sent  # Get_Version to node 1
    report = session.report(2.0, "virtual:test")
    assert [(r.protocol, r.node_id, r.seen_by, r.wheel) for r in report.rows] == [
        ("odrive", 1, "heartbeat", "left")]
    assert report.notes == ("configured but not found: 'right' (odrive node 2)",)


def test_no_other_protocols_request_goes_to_a_configured_motors_identifier() -> None:
    """ODrive node 3's Get_Version (RTR 0x060) would land on a configured DBC motor's frame."""
    left = MotorClaims(MotorConfig("left", "dbc", 1), (FrameClaim.exact(0x060, False, 0),))
    session = ScanSession(PROBES, TIMING, 0.0, claimed=[left])
    session.on_frame(Frame(0x061, bytes.fromhex("0000000001000100")), 0.1)  # ODrive node 3
    sent = [f for k in range(2000) for f in session.poll(k / 1000)]
    assert all(f.arbitration_id != 0x060 or f.is_extended_id for f in sent)
    report = session.report(2.0, "virtual:test")
    (odrive,) = report.rows
    assert "Get_Version not asked: 0x060 is 'left''s (dbc node 1, configured)" in (
        odrive.description.notes)


def _scan_odrives(cfg: GatewayConfig, extended: bool) -> ScanReport:
    """A scan with ``cfg``'s motors and claims, hearing ODrive node 1's heartbeat."""
    motors = [m for m in cfg.motors if m is not None]
    session = ScanSession(PROBES, TIMING, 0.0, known=motors, claimed=motor_claims(cfg))
    heartbeat = bytes.fromhex("0000000001000100")  # IDLE
    session.on_frame(Frame(0x021, heartbeat, is_extended_id=extended), 0.1)
    for k in range(2000):
        session.poll(k / 1000)
    return session.report(2.0, "virtual:test")


def test_an_odrive_on_29_bit_identifiers_is_not_the_block_of_its_node_on_11_bit_ones(
        tmp_path: Path) -> None:
    """The block says node 1 on 11-bit identifiers (no extended_id); the axis answers on 29-bit
    ones: its driver would never reach it, so it is not 'left', and the row and the notes say
    what differs."""
    cfg = load_config(CONFIG_DIR / "turtlebot3_burger.yaml")
    report = _scan_odrives(cfg, extended=True)
    (row,) = report.rows
    assert (row.protocol, row.node_id, row.extended, row.wheel) == ("odrive", 1, True, None)
    assert row.description.notes[0] == (
        "not the configuration's 'left' (odrive node 1 on 11-bit identifiers): this controller "
        "answers on 29-bit identifiers (set extended_id: true in that block)")
    assert report.notes == (
        "configured but not found: 'left' (odrive node 1 on 11-bit identifiers; heard on "
        "29-bit identifiers instead), 'right' (odrive node 2)",)
    assert "configured as" not in render(report)
    # The same axis on 11-bit identifiers is 'left'.
    (row,) = _scan_odrives(cfg, extended=False).rows
    assert row.wheel == "left" and not any("not the configuration's" in n
                                           for n in row.description.notes)
    # And a block that says extended_id: true is the 29-bit axis's.
    text = (CONFIG_DIR / "turtlebot3_burger.yaml").read_text("utf-8").replace(
        "  driver: odrive\n", "  driver: odrive\n  extended_id: true\n", 1)
    (tmp_path / "robot.yaml").write_text(text)
    wide = load_config(tmp_path / "robot.yaml")
    (row,) = _scan_odrives(wide, extended=True).rows
    assert row.wheel == "left"
    (row,) = _scan_odrives(wide, extended=False).rows
    assert row.wheel is None and row.description.notes[0] == (
        "not the configuration's 'left' (odrive node 1 on 29-bit identifiers): this controller "
        "answers on 11-bit identifiers (set extended_id: false in that block)")
