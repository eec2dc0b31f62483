"""The per-frame fast paths give the same results as the general code they shortcut.

Issue 6: received frames built past ``Frame.__new__``, the CiA 402 statusword table and the
ODrive error-word mapping on plain ints.  Issue 15: the bus edge's frame tallies counted in C,
and the loop's dispatch table.  And the ODrive velocity frames against the checked builder.
"""

from __future__ import annotations

import math
import random
from typing import TYPE_CHECKING

import can
import pytest
from hypothesis import given
from hypothesis import strategies as st

from drivers.cia402.enums import STATUSWORD_MASK, state_from_statusword
from drivers.odrive.codec import OdriveCodec
from drivers.odrive.enums import (
    AXIS_ERROR_05_FAULTS,
    AXIS_ERROR_FAULTS,
    CmdId,
    Firmware,
    error_faults,
)
from gateway.bus.can_bus import drain, to_frame, to_message
from gateway.config import load_config
from gateway.core.types import (
    DriveFault,
    Frame,
    frame_of,
)
from gateway.drive.driveset import DriveSet
from gateway.runtime.loop import Gateway
from gateway.wire.busload import frame_bits
from tests.conftest import CONFIG_DIR

if TYPE_CHECKING:
    from pathlib import Path


def test_received_frames_equal_frame_field_for_field(channel: str) -> None:
    # drain and to_frame build frames with tuple.__new__, past Frame.__new__: every field,
    # receive time included, must be what Frame(...) gives.
    tx = can.Bus(interface="virtual", channel=channel)
    rx = can.Bus(interface="virtual", channel=channel)
    try:
        frames = [Frame(0x123, b"\x01\x02"), Frame(0x1ABCDEF, b"", True, True, 4),
                  Frame(0x7FF, bytes(range(8)), False, False, 8)]
        for f in frames:
            tx.send(to_message(f))
        got = drain(rx, timestamp_s=7.0)
        assert [type(g) for g in got] == [Frame] * 3
        assert [tuple(g) for g in got] == [tuple(f.stamped(7.0)) for f in frames]
        msg = to_message(frames[2])
        msg.timestamp = 3.5
        assert tuple(to_frame(msg)) == tuple(frames[2].stamped(3.5))
        assert tuple(to_frame(msg, 1.25)) == tuple(frames[2].stamped(1.25))
        remote = to_message(frames[1])
        remote.data = bytearray(b"\x09")  # a remote frame's payload is never taken
        assert tuple(to_frame(remote, 0.0)) == tuple(frames[1])
    finally:
        tx.shutdown()
        rx.shutdown()


def test_statusword_table_matches_the_mask_scan() -> None:
    # state_from_statusword indexes a table over statusword & 0x6F: the same answer as
    # scanning STATUSWORD_MASK for every 16-bit statusword.
    for word in range(1 << 16):
        expected = next(
            (s for s, mask in STATUSWORD_MASK.items() if word & mask == s), None
        )
        assert state_from_statusword(word) is expected


@pytest.mark.parametrize("firmware", list(Firmware))
def test_odrive_error_faults_match_the_flag_tables(firmware: Firmware) -> None:
    # error_faults tests plain int masks: the same flags as testing the IntFlag members.
    table = AXIS_ERROR_FAULTS if firmware is Firmware.V0_6 else AXIS_ERROR_05_FAULTS
    rng = random.Random(6)
    words = [0, 0xFFFFFFFF, *(1 << b for b in range(32)),
             *(rng.getrandbits(32) for _ in range(300))]
    for bits in words:
        expected = DriveFault.NONE
        rest = bits
        for flag, fault in table.items():
            if bits & flag:
                expected |= fault
                rest &= ~int(flag)
        if rest:
            expected |= DriveFault.OTHER
        got = error_faults(firmware, bits)
        assert got is expected or (got == expected and type(got) is DriveFault)


def test_tally_counts_ids_and_bits_as_frame_bits_does(channel: str) -> None:
    frames = [Frame(0x123, b"\x01\x02"), Frame(0x1ABCDEF, b"", True, True, 4),
              Frame(0x123, bytes(8)), Frame(0x7FF, b"", False, True, 8), Frame(0x10, b""),
              Frame(0x124, bytes(12), dlc=12)]
    gw = Gateway(load_config(None, {"interface": "virtual", "channel": channel}))
    try:
        gw.edge._tally(frames, True)
        gw.edge._tally(frames[:2], False)
        gw.edge._tally([], False)
        assert gw.edge.id_counts == {(0x123, False, True): 2, (0x1ABCDEF, True, True): 1,
                                (0x7FF, False, True): 1, (0x10, False, True): 1,
                                (0x124, False, True): 1,
                                (0x123, False, False): 1, (0x1ABCDEF, True, False): 1}
        expected = sum(frame_bits(0 if f.is_remote_frame else f.dlc, f.is_extended_id)
                       for f in frames + frames[:2])
        assert gw.edge.bits == expected
        # The same, frame by frame, as the tally was written before it counted in C.
        rng = random.Random(9)
        pool = [Frame(rng.choice((0x10, 0x123, 0x7FF, 0x1ABCDEF)), bytes(rng.randrange(9)),
                      rng.random() < 0.3, rng.random() < 0.2) for _ in range(40)]
        ids: dict[tuple[int, bool, bool], int] = dict(gw.edge.id_counts)
        bits = gw.edge.bits
        for _ in range(50):
            burst = rng.sample(pool, rng.randrange(6))
            sent = rng.random() < 0.5
            gw.edge._tally(burst, sent)
            for f in burst:
                key = (f.arbitration_id, f.is_extended_id, sent)
                ids[key] = ids.get(key, 0) + 1
                bits += frame_bits(0 if f.is_remote_frame else f.dlc, f.is_extended_id)
        assert gw.edge.id_counts == ids
        assert gw.edge.bits == bits
    finally:
        gw.close()


@given(
    st.lists(st.tuples(st.integers(0, 0x3E), st.floats(-50.0, 50.0)), min_size=1, max_size=6,
             unique_by=lambda t: t[0]),
    st.floats(-300.0, 300.0), st.booleans(),
)
def test_odrive_velocity_frames_match_the_checked_builder(
    axes: list[tuple[int, float]], speed: float, extended: bool
) -> None:
    # OdriveCodec.set_input_vels builds the cycle's frames with frame_of, past Frame.__new__
    # and the per-frame checks: the same frames, field for field, as make_set_input_vel.
    codec = OdriveCodec(Firmware.V0_6, extended)
    ids = [(codec.arbitration_id(node, CmdId.SET_INPUT_VEL), scale) for node, scale in axes]
    fast = codec.set_input_vels(ids, [speed] * len(axes))
    slow = [codec.make_set_input_vel(node, speed * scale / (2.0 * math.pi))
            for node, scale in axes]
    assert [tuple(f) for f in fast] == [tuple(f) for f in slow]
    assert frame_of((0x123, b"\x01", True, False, 1, 2.5)) == Frame(0x123, b"\x01", True,
                                                                    timestamp_s=2.5)


@pytest.mark.parametrize("path", [None, *sorted(CONFIG_DIR.glob("*.yaml"))],
                         ids=lambda p: "default" if p is None else p.stem)
def test_the_loops_dispatch_table_is_the_routers(path: Path | None) -> None:
    """Issue 15: the loop hands a frame straight to ``DriveSet.takers[(id, extended)]``; that
    is the ``on_frame`` of the driver the router names, for every identifier the drivers
    claim, and the router's other identifiers (wide claims) are left to ``DriveSet.on_frame``."""
    drives = DriveSet(load_config(path))
    router = drives._router
    claimed = [(ident, c.extended) for drv, _ in drives.groups for c in drv.claims()
               if c.receive for ident in (c.identifiers() or [])]
    assert claimed
    assert set(drives.takers) == set(claimed)
    for key, taker in drives.takers.items():
        owner = router.owner(*key)
        assert owner is not None and taker == owner.on_frame
    rng = random.Random(5)
    for _ in range(2000):
        ext = rng.random() < 0.5
        key = (rng.randrange(1 << (29 if ext else 11)), ext)
        if key not in drives.takers:
            assert router.owner(*key) is None or router._wide
