"""Fuzzing of every driver's decoder: random frames into every driver built from a shipped
configuration, and a DBC driver with float32 signals.  The rules checked:

* ``on_frame`` never raises and returns a bool;
* a frame is counted in ``driver.rejected`` at most once, and only if the driver claims it;
* a frame whose identifier is none of the driver's is not claimed and not counted;
* a malformed frame on one of the driver's own feedback IDs (wrong length, remote frame,
  non-finite float) is claimed, counted exactly once, and leaves the feedback as it was;
* stored feedback is always finite; ``status``, ``poll`` and ``command`` still work after.

The drivers and the frames are described in :mod:`tests.drivers.fuzz_decoder_helpers`.
"""

from __future__ import annotations

import math
import random
import struct
from typing import TYPE_CHECKING, Any

import pytest
import yaml
from hypothesis import given
from hypothesis import strategies as st

from drivers.cia402.enums import CobBase
from drivers.odrive import OdriveDriver
from drivers.odrive.enums import AxisState, CmdId
from drivers.vesc import VescDriver
from drivers.vesc.appconf import HOST_ID
from gateway.config import parse_config
from gateway.core.types import Frame
from gateway.drive.driveset import DriveSet
from tests.conftest import CONFIG_DIR, SIM_ODRIVE_ENDPOINTS
from tests.drivers.fuzz_decoder_helpers import (
    ALL_CASES,
    CASES,
    DBC_FLOAT,
    FLOAT32_MAX,
    FUZZ,
    NAN_BITS,
    Own,
    frames,
    make_driver,
    own_feedback,
)

if TYPE_CHECKING:
    from collections.abc import Callable

    from gateway.drive.driver import MotorDriver


def claimable_ids(drv: MotorDriver[Any]) -> frozenset[int]:
    """Every arbitration ID (either ID type) the driver may claim; others are foreign."""
    nodes = [m.node_id for m in drv.motors]
    if isinstance(drv, OdriveDriver):
        return frozenset(n << 5 | cmd for n in nodes for cmd in range(32))
    if isinstance(drv, VescDriver):
        status = {p << 8 | n for n in nodes for p in (9, 14, 15, 16, 27, 58)}
        replies = {p << 8 | HOST_ID for p in (5, 6, 7, 8)}  # the app config's read-back
        return frozenset(status | {18 << 8 | x for x in range(256)} | replies)  # (PONG: any)
    return frozenset(o.arbitration_id for o in own_feedback(drv))


@st.composite
def malformed_own(draw: st.DrawFn, own: list[Own]) -> Frame:
    """A frame on one of ``own``'s IDs that must be rejected: wrong length or remote."""
    o = draw(st.sampled_from(own))
    wrong = sorted(set(range(9)) - o.lengths - o.exempt)
    if o.rtr_counted and draw(st.booleans()):
        return Frame(o.arbitration_id, b"", o.extended, True, draw(st.integers(0, 8)))
    size = draw(st.sampled_from(wrong))
    return Frame(o.arbitration_id, draw(st.binary(min_size=size, max_size=size)), o.extended)


# ------------------------------------------------------------------------------- helpers


def rejected(drv: MotorDriver[Any]) -> int:
    return sum(drv.rejected.values())


def feedbacks(drv: MotorDriver[Any]) -> list[object]:
    return [drv.feedback(i) for i in range(len(drv.motors))]


def assert_feedback_finite(drv: MotorDriver[Any]) -> None:
    for i, m in enumerate(drv.motors):
        fb = drv.feedback(i)
        if fb is not None:
            values = (fb.position_rad, fb.velocity_rad_s)
            assert all(math.isfinite(v) for v in values), f"{m.wheel}: {fb}"


def assert_still_works(drv: MotorDriver[Any], now_s: float, enabled: bool) -> None:
    """Housekeeping and commands after the fuzzing raise nothing."""
    assert len(drv.status(now_s)) == len(drv.motors)
    drv.poll(now_s)
    if enabled:
        drv.command([0.0] * len(drv.motors), now_s)


# ------------------------------------------------------------------------------- drivers


@pytest.mark.parametrize("case", ALL_CASES)
@FUZZ
@given(data=st.data())
def test_random_frames_never_raise_and_are_counted_at_most_once(
    case: str, data: st.DataObject
) -> None:
    drv = make_driver(case)
    own, claimable = own_feedback(drv), claimable_ids(drv)
    enabled = data.draw(st.booleans(), label="enabled")
    if enabled:
        drv.enable(0.0)
        drv.poll(0.001)
    t = 0.01
    for frame in data.draw(st.lists(frames(own), max_size=25), label="frames"):
        before = rejected(drv)
        mine = drv.on_frame(frame.stamped(t))
        counted = rejected(drv) - before
        assert isinstance(mine, bool)
        assert counted in (0, 1)
        assert mine or not counted, f"{frame.to_cansend()} counted but not claimed"
        if frame.arbitration_id not in claimable:
            assert not mine, f"{frame.to_cansend()} is not {case}'s but was claimed"
        assert_feedback_finite(drv)
        t += 0.002
    assert_still_works(drv, t, enabled)


def foreign_sweep(drv: MotorDriver[Any]) -> list[Frame]:
    """Frames on every identifier the driver must not claim: all 11-bit numbers (both ID
    types), the VESC / ODrive 29-bit layouts around its nodes, and 2000 random 29-bit IDs."""
    rng = random.Random(type(drv).__name__)
    numbers = set(range(0x800))
    numbers |= {p << 8 | n for p in range(64) for n in range(256)}
    numbers |= {n << 5 | c for n in range(0x400) for c in range(32)}
    numbers |= {rng.getrandbits(29) for _ in range(2000)}
    claimable = claimable_ids(drv)
    out = []
    for k, ident in enumerate(sorted(numbers - claimable)):
        data = bytes(8) if k % 2 else bytes([k & 0xFF, 1, 2])
        if ident <= 0x7FF:
            out.append(Frame(ident, data, False))
        out.append(Frame(ident, data, True))
    return out


@pytest.mark.parametrize("case", ALL_CASES)
def test_foreign_identifiers_are_neither_claimed_nor_counted(case: str) -> None:
    drv = make_driver(case)
    drv.enable(0.0)
    claimed = [f.to_cansend() for f in foreign_sweep(drv) if drv.on_frame(f)]
    assert not claimed, claimed[:10]
    assert rejected(drv) == 0
    assert all(fb is None for fb in feedbacks(drv))


@pytest.mark.parametrize("case", ALL_CASES)
@FUZZ
@given(data=st.data())
def test_malformed_frames_of_own_ids_are_claimed_counted_and_ignored(
    case: str, data: st.DataObject
) -> None:
    drv = make_driver(case)
    own = own_feedback(drv)
    t = 0.01
    for frame in data.draw(st.lists(malformed_own(own), min_size=1, max_size=10)):
        before, fb = rejected(drv), feedbacks(drv)
        assert drv.on_frame(frame.stamped(t)) is True, frame.to_cansend()
        assert rejected(drv) == before + 1, f"{frame.to_cansend()} not counted"
        assert feedbacks(drv) == fb
        t += 0.002


def odrive_estimates(case: str) -> tuple[MotorDriver[Any], Callable[[bytes], Frame]]:
    drv = make_driver(case)
    assert isinstance(drv, OdriveDriver)
    ident = drv.motors[0].node_id << 5 | CmdId.GET_ENCODER_ESTIMATES
    return drv, lambda data: Frame(ident, data, drv.codec.extended_id)


def dbc_estimates(case: str) -> tuple[MotorDriver[Any], Callable[[bytes], Frame]]:
    drv = make_driver(case)
    return drv, lambda data: Frame(0x069, data)  # Axis3_Get_Encoder_Estimates


non_finite = st.sampled_from([math.nan, math.inf, -math.inf]).map(lambda v: struct.pack("<f", v))
non_finite |= st.sampled_from(NAN_BITS[1:]).map(lambda b: struct.pack("<I", b))
any_f32 = st.floats(width=32).map(lambda v: struct.pack("<f", v)) | non_finite


@pytest.mark.parametrize(
    ("case", "build"),
    [*((c, odrive_estimates) for c in CASES if c.startswith("odrive")), (DBC_FLOAT, dbc_estimates)],
)
@FUZZ
@given(pair=st.tuples(non_finite, any_f32) | st.tuples(any_f32, non_finite), swap=st.booleans())
def test_non_finite_float_feedback_is_counted_and_ignored(
    case: str,
    build: Callable[[str], tuple[MotorDriver[Any], Callable[[bytes], Frame]]],
    pair: tuple[bytes, bytes],
    swap: bool,
) -> None:
    drv, frame = build(case)
    assert drv.on_frame(frame(struct.pack("<ff", 1.0, 0.5)).stamped(0.01))
    good = feedbacks(drv)
    assert good[0] is not None
    data = pair[1] + pair[0] if swap else pair[0] + pair[1]
    assert drv.on_frame(frame(data).stamped(0.02)) is True
    assert rejected(drv) == 1
    assert feedbacks(drv) == good


@pytest.mark.parametrize("case", [c for c in CASES if c.startswith("odrive")] + [DBC_FLOAT])
@FUZZ
@given(pos=st.sampled_from([FLOAT32_MAX, -FLOAT32_MAX]) | st.floats(width=32, allow_nan=False,
                                                                    allow_infinity=False),
       vel=st.sampled_from([FLOAT32_MAX, -FLOAT32_MAX, 0.0]))
def test_huge_finite_float_feedback_stays_finite(case: str, pos: float, vel: float) -> None:
    drv, frame = (dbc_estimates if case == DBC_FLOAT else odrive_estimates)(case)
    for t, p in ((0.01, -FLOAT32_MAX), (0.02, pos)):
        drv.on_frame(frame(struct.pack("<ff", p, vel)).stamped(t))
    assert rejected(drv) == 0
    assert_feedback_finite(drv)


# Unbounded rejected-frame counters: a key per distinct garbage value.


def _same_shape_garbage(case: str, drv: MotorDriver[Any]) -> list[Frame]:
    """200 malformed frames on one ID with one length, differing only in their values."""
    node = drv.motors[0].node_id
    if case.startswith("odrive"):
        ident = node << 5 | CmdId.GET_ENCODER_ESTIMATES
        ext = case.endswith("ext")
        return [Frame(ident, struct.pack("<ff", math.nan, k), ext) for k in range(200)]
    if case.startswith("dji"):
        angles = range(8192, 8392)  # beyond the 13-bit rotor angle
        return [Frame(0x200 + node, struct.pack(">HhhBB", a, 0, 0, 30, 0)) for a in angles]
    if case == "cia402":
        bad_states = [b for b in range(256) if b & 0x7F not in (0x00, 0x04, 0x05, 0x7F)]
        return [Frame(CobBase.HEARTBEAT + node, bytes([b])) for b in bad_states[:200]]
    if case == "vesc":
        return [Frame(9 << 8 | node, bytes([k, k]), True) for k in range(200)]
    if case == DBC_FLOAT:
        return [Frame(0x069, struct.pack("<fI", math.nan, k)) for k in range(200)]
    return [Frame(0x281, bytes([k]), False) for k in range(200)]  # example DBC, 1 byte of 8


@pytest.mark.parametrize("case", ALL_CASES)
def test_rejected_counter_keys_do_not_grow_with_garbage_values(case: str) -> None:
    drv = make_driver(case)
    garbage = _same_shape_garbage(case, drv)
    for k, frame in enumerate(garbage):
        assert drv.on_frame(frame.stamped(0.01 + k * 1e-3))
    assert rejected(drv) == len(garbage)
    assert len(drv.rejected) <= 4, sorted(drv.rejected)[:5]


# The other ID type: a 29-bit frame is never the same identifier as an 11-bit one.

@pytest.mark.parametrize("case", ALL_CASES)
def test_a_frame_of_the_other_id_type_is_not_claimed(case: str) -> None:
    drv = make_driver(case)
    for o in own_feedback(drv):
        for size in range(9):
            frame = Frame(o.arbitration_id, bytes(size), not o.extended)
            assert drv.on_frame(frame) is False, frame.to_cansend()
    assert rejected(drv) == 0


def test_mixed_bus_frames_of_the_other_id_type_reach_their_driver() -> None:
    path = CONFIG_DIR / "turtlebot3_burger.yaml"
    doc = yaml.safe_load(path.read_text("utf-8"))
    doc["motor_defaults"] = {"gear_ratio": 1.0, "max_rpm": 61}
    doc["motors"] = {
        "left": {"driver": "dji", "node_id": 1, "esc": "c620",
                 "no_controller_stop": "acknowledged"},
        "right": {"driver": "odrive", "node_id": 16, "extended_id": True, "invert": True,
                  "watchdog_endpoints": SIM_ODRIVE_ENDPOINTS},
    }
    drives = DriveSet(parse_config(doc, str(path)))
    (dji, _), (odrive, _) = drives.groups
    assert isinstance(odrive, OdriveDriver)
    heartbeat = bytes([0, 0, 0, 0, AxisState.IDLE, 0, 0, 0])
    assert drives.on_frame(Frame(16 << 5 | CmdId.HEARTBEAT, heartbeat, True, timestamp_s=1.0))
    assert odrive.axis_state(0) is AxisState.IDLE
    assert not dji.rejected
