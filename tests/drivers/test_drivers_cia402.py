"""Tests of the CiA 402 driver's contract: malformed and foreign frames, the checks of
setpoints and keys, the frames it claims and how it names them, its liveness, and its simulator
kept apart (the codec: ``test_cia402_codec``; the state machine: ``test_cia402_state_machine``;
on a bus: ``test_drivers_cia402_bus``).
"""

from __future__ import annotations

import math
import random
import subprocess
import sys
from pathlib import Path

import pytest

import drivers.cia402
from drivers.cia402 import Cia402Driver, Cia402Options
from drivers.cia402.codec import PDO_STRUCT, make_heartbeat, make_rpdo, velocity_to_raw
from drivers.cia402.enums import DataType, NmtState, state_from_statusword
from drivers.cia402.sdo import make_sdo_download, make_sdo_download_ack
from drivers.cia402.sim import Cia402Simulator
from drivers.cia402.targets import wrap_delta
from gateway.core.errors import ConfigError, DecodeError, EncodeError
from gateway.core.types import Frame
from gateway.drive.registry import get_driver_class
from gateway.sim.registry import simulator_for
from tests import factories
from tests.drivers.cia402_bench import TWO_PI, hexb

# ===================================================================== malformed frames, bad values


@pytest.mark.parametrize(
    ("frame", "reason"),
    [
        (Frame(0x383, hexb("37 02 C0 1D FE")), "5"),  # short TPDO
        (Frame(0x483, hexb("37 02 E6 03 00 00 00")), "7"),  # long TPDO
        (Frame(0x383, is_remote_frame=True, dlc=6), "11-bit"),
        (Frame(0x703, hexb("05 00")), "1 data byte"),
        (Frame(0x703, hexb("03")), "NMT state"),
        (Frame(0x083, hexb("10 23 05")), "8 data bytes"),
        (Frame(0x583, hexb("60 40 60 00")), "8 data bytes"),
        (Frame(0x583, hexb("E0 40 60 00 00 00 00 00")), "command byte 0xE0"),
        (Frame(0x583, hexb("41 00 10 00 20 00 00 00")), "segmented"),
    ],
)
def test_malformed_frames_are_counted(frame: Frame, reason: str) -> None:
    drv = Cia402Driver([factories.motor("cia402", 3, "left")])
    assert drv.on_frame(frame) is True
    assert sum(drv.rejected.values()) == 1
    assert reason in next(iter(drv.last_rejection.values()))
    with pytest.raises(DecodeError):
        drv.codec.decode(frame)


def test_foreign_frames_are_not_ours() -> None:
    drv = Cia402Driver([factories.motor("cia402", 3, "left")])
    for frame in (Frame(0x384, bytes(6)), Frame(0x080), Frame(0x603, bytes(8)),
                  Frame(0x183, bytes(2)), Frame(0x503, bytes(6)),
                  # a 29-bit frame with the number of our TPDO3 is another device's
                  Frame(0x383, hexb("37 02 C0 1D FE FF"), is_extended_id=True)):
        assert drv.on_frame(frame) is False
    assert not drv.rejected


def test_unexpected_sdo_response_is_counted() -> None:
    drv = Cia402Driver([factories.motor("cia402", 3, "left")])
    assert drv.on_frame(make_sdo_download_ack(3, 0x6040, 0))
    assert drv.rejected == {"unexpected SDO response": 1}


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf, 1e3])
def test_command_rejects_bad_speeds(bad: float) -> None:
    drv = Cia402Driver([factories.motor("cia402", 3, "left", gear_ratio=10.0, max_rpm=5000.0)])
    with pytest.raises(EncodeError, match=r'Expected a wheel speed for CiA 402 node 3 \("left"\) '
                                          r"between -52\.3599 and 52\.3599 rad/s \(max_rpm "
                                          r"5000\), but got"):
        drv.command([bad], 0.0)
    with pytest.raises(EncodeError, match="but got"):
        drv.preview_command([bad])


def test_encode_range_errors() -> None:
    drv = Cia402Driver([factories.motor("cia402", 3, "left")])
    with pytest.raises(EncodeError, match=r"Expected 1 setpoints for the CiA 402 motors \(left\), "
                                          r"but got 2\."):
        drv.command([0.0, 0.0], 0.0)
    huge = Cia402Driver([factories.motor("cia402", 3, "left", max_rpm=1e5,
                                     options={"velocity_factor": 1e5})])
    with pytest.raises(EncodeError, match="target velocity for node 3 between -2147483648 and "):
        huge.preview_command([1e5 * TWO_PI / 60])  # 1e10 units: beyond the int32 of 0x60FF
    with pytest.raises(EncodeError, match="-2147483648 and 2147483647 device units"):
        velocity_to_raw(2.0**31, "target velocity for node 3")
    with pytest.raises(EncodeError, match="0x6060:00"):
        make_sdo_download(3, 0x6060, 0, 200, DataType.INTEGER8)
    with pytest.raises(EncodeError, match="controlword"):
        make_rpdo(0x503, 0x10000, 0)
    with pytest.raises(EncodeError, match="node ID"):
        make_heartbeat(128, NmtState.OPERATIONAL)


def test_config_errors() -> None:
    with pytest.raises(ConfigError, match="unknown key"):
        Cia402Driver([factories.motor("cia402", 3, "left", validate=False, options={"bogus": 1})])
    with pytest.raises(ConfigError, match="tpdo_velocity"):
        Cia402Driver([factories.motor("cia402", 3, "l", validate=False,
                                      options={"tpdo_velocity": 3})])
    with pytest.raises(ConfigError, match=r"1\.\.127, got 0"):
        Cia402Driver([factories.motor("cia402", 0, "left")])
    with pytest.raises(ConfigError, match=r"node 3 is already used by wheel .a."):
        Cia402Driver([factories.motor("cia402", 3, "a"), factories.motor("cia402", 3, "b")])
    with pytest.raises(ConfigError, match=r"^x\.velocity_factor: expected more than 0, "
                                          r"got 0\.0$"):
        Cia402Options.from_block({"velocity_factor": 0}, "x")
    with pytest.raises(ConfigError, match=r"^x\.tpdo_velocity: expected a TPDO other than "):
        Cia402Driver.validate_options({"tpdo_position": 2, "tpdo_velocity": 2}, "x")
    assert get_driver_class("cia402") is Cia402Driver



# ===================================================================== claims, names, simulator

NODE_5 = factories.motor("cia402", 5, "b", options={"rpdo": 1, "tpdo_position": 1,
                                                "tpdo_velocity": 2})


def test_claims_golden() -> None:
    """What the driver takes (each node's EMCY, TPDOs, SDO responses and heartbeat) and what it
    only sends (NMT, the gateway's heartbeat, SYNC; each node's RPDO and SDO requests)."""
    drv = Cia402Driver([factories.motor("cia402", 3, "a"), NODE_5])
    got = [(c.can_id, c.mask, c.extended, c.motor, c.receive) for c in drv.claims()]
    taken = [(cob, 0x7FF, False, 0 if cob & 0x7F == 3 else 1, True) for cob in
             (0x083, 0x085, 0x185, 0x285, 0x383, 0x483, 0x583, 0x585, 0x703, 0x705)]
    sent = [(0x000, 0x7FF, False, None, False), (0x77F, 0x7FF, False, None, False),
            (0x080, 0x7FF, False, None, False), (0x503, 0x7FF, False, 0, False),
            (0x603, 0x7FF, False, 0, False), (0x205, 0x7FF, False, 1, False),
            (0x605, 0x7FF, False, 1, False)]
    assert got == taken + sent
    assert [str(f) for f in drv.receive_filters()] == [f"{c[0]:03X}/7FF" for c in taken]
    quiet = Cia402Driver([factories.motor("cia402", 3, "a", options={"sync": False})])
    assert not [c for c in quiet.claims() if c.can_id == 0x080]  # no SYNC without sync


def test_every_frame_taken_is_claimed_by_its_node() -> None:
    """Every 11-bit ID: on_frame takes it exactly when a claim with receive does, and every
    claim of one motor is that motor's node (CiA 301: function code << 7 | node ID)."""
    drv = Cia402Driver([factories.motor("cia402", 3, "a"), NODE_5])
    claims = drv.claims()
    for cob in range(0x800):
        mine = [c for c in claims if c.matches(cob, False)]
        taken = drv.on_frame(Frame(cob, bytes(8)))  # 8 bytes: malformed for a TPDO or heartbeat
        assert taken == any(c.receive for c in mine), hex(cob)
        for c in mine:
            assert c.motor is None or drv.motors[c.motor].node_id == cob & 0x7F, hex(cob)
        assert drv.on_frame(Frame(cob, bytes(8), is_extended_id=True)) is False
    assert sum(drv.rejected.values()) == 8  # the TPDOs and heartbeats; the EMCYs are 8 bytes


@pytest.mark.parametrize(("cob", "name"), [
    (0x000, "NMT"), (0x080, "SYNC"), (0x083, "EMCY"), (0x185, "TPDO1"), (0x383, "TPDO3"),
    (0x483, "TPDO4"), (0x205, "RPDO1"), (0x503, "RPDO4"), (0x583, "SDO_TX"), (0x603, "SDO_RX"),
    (0x703, "HEARTBEAT"), (0x77F, "HEARTBEAT"), (0x780, None),
])
def test_message_names(cob: int, name: str | None) -> None:
    drv = Cia402Driver([factories.motor("cia402", 3, "a")])
    assert drv.message_name(cob, False) == name
    assert drv.message_name(cob, True) is None


def test_any_frame_of_a_node_keeps_it_alive() -> None:
    """A node is alive while any of its frames is younger than liveness_s: pre-operational
    during the enable sequence it sends no TPDO, only its heartbeat and SDO answers."""
    drv = Cia402Driver([factories.motor("cia402", 3, "a")])
    drv.enable(0.0)
    assert drv.state(0, 0.0).name == "OFFLINE"
    drv.on_frame(Frame(0x703, hexb("7F"), timestamp_s=0.1))  # heartbeat, PRE-OPERATIONAL
    assert drv.state(0, 0.35).name == "ENABLING"
    assert drv.state(0, 0.36).name == "OFFLINE"
    assert drv.LIVENESS_STREAMS == ("any frame; armed, the position TPDO",)
    # (Armed, the position TPDO alone: tests/drivers/test_cia402_position_tpdo.py.)


def test_the_simulator_is_registered_apart_and_never_imported_by_the_driver() -> None:
    motor = factories.motor("cia402", 3, "a")
    assert isinstance(simulator_for(motor), Cia402Simulator)
    production = sorted(
        f"drivers.cia402.{p.stem}" for p in Path(drivers.cia402.__file__).parent.glob("*.py")
        if not p.stem.startswith("sim") and p.stem != "__init__"
    )
    code = (f"import sys, drivers.cia402, {', '.join(production)}\n"
            "print(sorted(m for m in sys.modules if m.startswith(('drivers.cia402.sim', "
            "'gateway.sim'))))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    assert "drivers.cia402.driver" in production and out.stdout.strip() == "[]"


# ===================================================================== the TPDO path's shortcuts


def test_tpdo_counts_and_state_follow_every_frame() -> None:
    """The TPDO path writes ``wrap_delta`` out and decodes a statusword only when it changes
    (issue 15): the unwrapped count is the sum of every step across the int32 wrap, and the
    state always the one of the last statusword, over random TPDO streams."""
    rng = random.Random(15)
    words = [0x0237, 0x0233, 0x0231, 0x0250, 0x0218, 0x021F, 0x1237]
    for _ in range(20):
        drv = Cia402Driver([factories.motor("cia402", 3, "left")])
        axis = drv._axes[0]
        raw = rng.choice([0, rng.randrange(-(1 << 31), 1 << 31), (1 << 31) - 5, -(1 << 31) + 5])
        first, word, expected = raw, words[0], 0
        for k in range(200):
            if rng.random() < 0.2:
                word = rng.choice(words)
            position = rng.random() < 0.5
            if position:
                step = rng.choice([rng.randrange(-5000, 5000), rng.randrange(-(1 << 31), 1 << 31)])
                previous, raw = raw, (raw + step + (1 << 31)) % (1 << 32) - (1 << 31)
                if k:
                    expected += wrap_delta(previous, raw)
            frame = Frame(0x383 if position else 0x483,
                          PDO_STRUCT.pack(word, raw if position else rng.randrange(-9999, 9999)),
                          timestamp_s=0.001 * k)
            if k == 0 and not position:
                frame = Frame(0x383, PDO_STRUCT.pack(word, raw), timestamp_s=0.0)
            assert drv.on_frame(frame)
            assert axis.seq.statusword == word
            assert axis.seq.state is state_from_statusword(word)
            assert axis.counts == expected, (first, k)
