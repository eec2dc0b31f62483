"""Fuzzing of every decoder: random frames into every driver, codec and device simulator.

Each driver is built from a shipped configuration (``gateway.config.parse_config`` +
:class:`~gateway.drive.driveset.DriveSet`), with the protocol keys varied where a file ships one
variant (ODrive firmware 0.5 / 0.6, 11-bit / 29-bit IDs), plus a DBC driver with float32
signals (the official ODrive DBC) for NaN and infinity.  Frames are random: IDs at and near the
driver's own, random 11- and 29-bit IDs, DLC 0..8, random data, float32 NaN / infinity / huge
patterns, remote frames.  The rules checked:

* ``on_frame`` never raises and returns a bool;
* a frame is counted in ``driver.rejected`` at most once, and only if the driver claims it;
* a frame whose identifier is none of the driver's is not claimed and not counted;
* a malformed frame on one of the driver's own feedback IDs (wrong length, remote frame,
  non-finite float) is claimed, counted exactly once, and leaves the feedback as it was;
* stored feedback is always finite; ``status``, ``poll`` and ``command`` still work after;
* the pure codecs' decoders return a message or ``None`` or raise ``DecodeError``, nothing else;
* the device simulators (``--sim``) take any frame without raising;
* the candump log reader raises ``CandumpError`` only, and accepts only sane IDs and stamps.
"""

from __future__ import annotations

import copy
import functools
import math
import random
import struct
from typing import TYPE_CHECKING, Any, NamedTuple, TypeAlias, TypeVar

import pytest
import yaml
from hypothesis import HealthCheck, assume, example, given, settings
from hypothesis import strategies as st

from drivers.cia402 import Cia402Codec, Cia402Driver, PdoLayout
from drivers.cia402.enums import CobBase, tpdo_cob_id
from drivers.cia402.sdo import parse_sdo_request, parse_sdo_response
from drivers.dbc import DbcDriver
from drivers.dji import DjiDriver
from drivers.dji.codec import decode_command as dji_decode_command
from drivers.dji.codec import decode_feedback as dji_decode_feedback
from drivers.odrive import Firmware, OdriveCodec, OdriveDriver
from drivers.odrive.enums import AxisState, CmdId
from drivers.vesc import VescDriver
from drivers.vesc.codec import decode as vesc_decode
from drivers.vesc.codec import decode_command as vesc_decode_command
from gateway.config import parse_config
from gateway.core.errors import DecodeError
from gateway.core.types import Frame, MotorConfig
from gateway.drive.driveset import DriveSet
from gateway.sim.registry import simulator_for
from gateway.wire.can import CanIds, WgCodec
from gateway.wire.candump import CandumpError, parse_line
from tests import factories
from tests.conftest import CONFIG_DIR, DATA_DIR, SIM_ODRIVE_ENDPOINTS

if TYPE_CHECKING:
    from collections.abc import Callable

    from gateway.core.settings import GatewayConfig
    from gateway.drive.driver import MotorDriver
    from gateway.sim.device import DeviceSimulator

FUZZ = settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])

#: 0.5 has no parameter access: its watchdog is stated, not written.
NO_ENDPOINTS: dict[str, object] = {"watchdog_endpoints": {}}
#: Case name -> (shipped config, keys merged into its ``motor_defaults``).
CASES: dict[str, tuple[str, dict[str, object]]] = {
    "odrive-0.6": ("turtlebot3_burger.yaml", {}),
    "odrive-0.5": ("turtlebot3_burger.yaml", {"firmware": "0.5", **NO_ENDPOINTS}),
    "odrive-0.6-ext": ("turtlebot3_burger.yaml", {"extended_id": True}),
    "odrive-0.5-ext": ("turtlebot3_burger.yaml",
                       {"firmware": "0.5", "extended_id": True, **NO_ENDPOINTS}),
    "vesc": ("differential_tub.yaml", {}),
    "cia402": ("synchro.yaml", {}),
    "dji-c620": ("mecanum.yaml", {}),
    "dji-c610": ("omni_delta.yaml", {}),
    "dbc": ("example_dbc.yaml", {}),
}
#: The DBC driver on float32 signals: axis 3 of the official ODrive DBC.
DBC_FLOAT = "dbc-float32"
ALL_CASES = [*CASES, DBC_FLOAT]

FLOAT32_MAX = 3.4028234663852886e38
T = TypeVar("T")
SPECIAL_F32 = [math.nan, math.inf, -math.inf, FLOAT32_MAX, -FLOAT32_MAX, 1e-45, -0.0, 1e30]
#: NaN payloads other than Python's own quiet NaN.
NAN_BITS = [0x7FC00000, 0x7F800001, 0xFFFFFFFF, 0xFFC00001, 0x7FBFFFFF]


@functools.cache
def shipped_config(case: str) -> GatewayConfig:
    """The shipped configuration of ``case`` with its protocol keys applied."""
    name, extra = CASES[case]
    path = CONFIG_DIR / name
    doc = yaml.safe_load(path.read_text("utf-8"))
    doc["motor_defaults"].update(extra)
    return parse_config(doc, str(path))


def odrive_dbc_motor() -> MotorConfig:
    axis = 3
    opts: dict[str, object] = {
        "dbc": str(DATA_DIR / "odrive-cansimple-0.5.6.dbc"),
        "command_message": f"Axis{axis}_Set_Input_Vel",
        "command_signal": "Input_Vel",
        "command_unit": "rev/s",
        "feedback_message": f"Axis{axis}_Get_Encoder_Estimates",
        "velocity_signal": "Vel_Estimate",
        "velocity_unit": "rev/s",
        "position_signal": "Pos_Estimate",
        "position_unit": "rev",
        "node_id_in_frame": "none",
        "fault_message": f"Axis{axis}_Heartbeat",
        "fault_signal": "Axis_Error",
    }
    return factories.motor("dbc", axis, options=opts)


@functools.cache
def _prototype(case: str) -> MotorDriver[Any]:
    if case == DBC_FLOAT:
        return DbcDriver([odrive_dbc_motor()])
    ((driver, _),) = DriveSet(shipped_config(case)).groups
    return driver


def _fresh(obj: T, motors: tuple[MotorConfig, ...]) -> T:
    """A deep copy of ``obj`` that shares the (immutable) motor blocks."""
    memo: dict[int, object] = {id(m): m for m in motors}
    memo.update({id(m.options): m.options for m in motors})
    return copy.deepcopy(obj, memo)


def make_driver(case: str) -> MotorDriver[Any]:
    """A fresh driver of ``case`` (every motor of the config uses the same protocol).  DBC
    drivers are copies of one built once, since loading the DBC file takes 30 ms."""
    proto = _prototype(case)
    if isinstance(proto, DbcDriver):
        return _fresh(proto, proto.motors)
    return type(proto)(proto.motors)


def make_simulators(case: str) -> list[DeviceSimulator]:
    """Fresh device simulators for every motor of ``case`` (DBC ones copied, as above)."""
    proto = _prototype(case)
    if isinstance(proto, DbcDriver):
        return _fresh(_prototype_sims(case), proto.motors)
    return [simulator_for(m) for m in proto.motors]


@functools.cache
def _prototype_sims(case: str) -> list[DeviceSimulator]:
    drv = _prototype(case)
    return [simulator_for(m) for m in drv.motors]


class Own(NamedTuple):
    """A feedback identifier of a driver and the data lengths it decodes."""

    arbitration_id: int
    extended: bool
    lengths: frozenset[int]
    #: Whether a remote frame on this ID is a rejection (not a request the driver sends).
    rtr_counted: bool = True
    #: Wrong lengths that are not rejections by design (ODrive 0.5: DLC 0 is a request).
    exempt: frozenset[int] = frozenset()


def own_feedback(drv: MotorDriver[Any]) -> list[Own]:
    """Every identifier ``drv`` decodes feedback from, derived from its public state."""
    nodes = [m.node_id for m in drv.motors]
    eight = frozenset({8})
    if isinstance(drv, OdriveDriver):
        ext = drv.codec.extended_id
        exempt = frozenset({0}) if drv.codec.firmware is Firmware.V0_5 else frozenset()
        return [
            Own(n << 5 | cmd, ext, eight, cmd != CmdId.GET_ERROR, exempt)
            for n in nodes
            for cmd in (CmdId.HEARTBEAT, CmdId.GET_ENCODER_ESTIMATES, CmdId.GET_ERROR)
        ]
    if isinstance(drv, VescDriver):
        # STATUS and STATUS_5.  PONG is left out: the gateway sends no PING, and a malformed
        # PONG is claimed by the pinger's ID in its low byte, not by the sender's.
        return [Own(p << 8 | n, True, eight) for n in nodes for p in (9, 27)]
    if isinstance(drv, DjiDriver):
        return [Own(0x200 + n, False, eight) for n in nodes]
    if isinstance(drv, DbcDriver):
        refs = [r for b in drv.bindings for r in (b.velocity, b.position, b.fault) if r]
        return [Own(r.frame_id, r.is_extended, frozenset({r.message.length})) for r in refs]
    assert isinstance(drv, Cia402Driver), type(drv)
    out = []
    for n, layout in drv.codec.nodes.items():
        out += [
            Own(tpdo_cob_id(layout.tpdo_position, n), False, frozenset({6})),
            Own(tpdo_cob_id(layout.tpdo_velocity, n), False, frozenset({6})),
            Own(CobBase.EMCY + n, False, eight),
            Own(CobBase.SDO_TX + n, False, eight),
            Own(CobBase.HEARTBEAT + n, False, frozenset({1})),
        ]
    return out


def claimable_ids(drv: MotorDriver[Any]) -> frozenset[int]:
    """Every arbitration ID (either ID type) the driver may claim; others are foreign."""
    nodes = [m.node_id for m in drv.motors]
    if isinstance(drv, OdriveDriver):
        return frozenset(n << 5 | cmd for n in nodes for cmd in range(32))
    if isinstance(drv, VescDriver):
        status = {p << 8 | n for n in nodes for p in (9, 14, 15, 16, 27, 58)}
        return frozenset(status | {18 << 8 | x for x in range(256)})  # a PONG names its sender
    return frozenset(o.arbitration_id for o in own_feedback(drv))


# ------------------------------------------------------------------------------- strategies


def f32_bytes() -> st.SearchStrategy[bytes]:
    """Four bytes of an awkward float32, either byte order."""
    special = st.sampled_from(SPECIAL_F32) | st.floats(width=32)
    packed = st.tuples(st.sampled_from("<>"), special).map(lambda p: struct.pack(p[0] + "f", p[1]))
    return packed | st.sampled_from(NAN_BITS).map(lambda b: struct.pack("<I", b))


def payloads() -> st.SearchStrategy[bytes]:
    """0..8 data bytes: random, or float32 patterns (maybe truncated)."""
    floats = st.tuples(f32_bytes(), f32_bytes(), st.integers(0, 8)).map(
        lambda p: (p[0] + p[1])[: p[2]] if p[2] < 8 else p[0] + p[1]
    )
    return st.binary(max_size=8) | floats


@st.composite
def frames(draw: st.DrawFn, own: list[Own]) -> Frame:
    """A random frame, mostly at or near one of ``own``'s identifiers."""
    kind = draw(st.sampled_from(["own", "own", "near", "std", "ext"]))
    if kind in ("own", "near"):
        o = draw(st.sampled_from(own))
        ident = o.arbitration_id + (draw(st.integers(-3, 3)) if kind == "near" else 0)
        ext = o.extended != (draw(st.integers(0, 9)) == 0)  # the other ID type, sometimes
    else:
        ext = kind == "ext"
        ident = draw(st.integers(0, 0x1FFFFFFF if ext else 0x7FF))
    ident = min(max(ident, 0), 0x1FFFFFFF if ext else 0x7FF)
    if draw(st.integers(0, 9)) == 0:
        return Frame(ident, b"", ext, True, draw(st.integers(0, 8)))
    data = draw(payloads())
    dlc = draw(st.integers(0, 8)) if draw(st.integers(0, 19)) == 0 else len(data)
    return Frame(ident, data, ext, False, dlc)


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


# ------------------------------------------------------------------------------- codecs


Decoders: TypeAlias = "list[Callable[[Frame], object]]"


def _wg(ext: bool) -> Callable[[Frame], object]:
    base = 0x18FF0000 if ext else 0x100
    ids = CanIds(base, base + 1, base + 2, base + 3, base + 4, extended=ext)
    return WgCodec(ids).decode


def _dbc_decoders(case: str) -> Decoders:
    drv = make_driver(case)
    assert isinstance(drv, DbcDriver)
    return [drv.codec.decode, drv.codec.decode_request]


CIA402 = Cia402Codec({1: PdoLayout(), 5: PdoLayout(rpdo=1, tpdo_position=1, tpdo_velocity=2)})

def _odrive_decoders(fw: Firmware, ext: bool) -> Decoders:
    codec = OdriveCodec(fw, ext)
    return [codec.decode, codec.decode_command]


def _aims(ids: list[int], ext: bool = False) -> list[Own]:
    return [Own(i, ext, frozenset({8})) for i in ids]


#: Codec name -> (its decoders, which may return None; IDs to aim at).
CODECS: dict[str, tuple[Callable[[], Decoders], list[Own]]] = {
    **{
        f"odrive-{fw.value}{'-ext' if ext else ''}": (
            functools.partial(_odrive_decoders, fw, ext),
            _aims([n << 5 | c for n in (0, 1, 0x3F) for c in range(32)], ext),
        )
        for fw in Firmware
        for ext in (False, True)
    },
    "vesc": (
        lambda: [vesc_decode, vesc_decode_command],
        _aims([p << 8 | n for p in range(64) for n in (0, 10, 255)], True),
    ),
    "cia402": (
        lambda: [CIA402.decode],
        _aims([b + n for b in range(0x80, 0x800, 0x80) for n in (1, 5, 9)]),
    ),
    "dji": (lambda: [dji_decode_feedback, dji_decode_command], _aims(list(range(0x1FE, 0x20A)))),
    "dbc": (functools.partial(_dbc_decoders, "dbc"), _aims(list(range(0x180, 0x290)))),
    DBC_FLOAT: (functools.partial(_dbc_decoders, DBC_FLOAT), _aims(list(range(0x60, 0x80)))),
    "wgproto": (
        lambda: [_wg(False), _wg(True)],
        _aims([0x100 + k for k in range(5)]) + _aims([0x18FF0000 + k for k in range(5)], True),
    ),
}


@pytest.mark.parametrize("name", list(CODECS))
@FUZZ
@given(data=st.data())
def test_codec_decoders_return_none_or_raise_only_decode_error(
    name: str, data: st.DataObject
) -> None:
    make, aims = CODECS[name]
    decoders = make()
    for frame in data.draw(st.lists(frames(aims), min_size=1, max_size=20)):
        for decode in decoders:
            try:
                decode(frame)
            except DecodeError as err:
                assert str(err)


@FUZZ
@given(data=st.data())
def test_sdo_parsers_raise_only_decode_error(data: st.DataObject) -> None:
    aims = [Own(b + n, False, frozenset({8})) for b in (0x580, 0x600) for n in (0, 1, 127, 128)]
    for frame in data.draw(st.lists(frames(aims), min_size=1, max_size=20)):
        for parse in (parse_sdo_response, parse_sdo_request):
            try:
                parse(frame)
            except DecodeError as err:
                assert str(err)


FINITE_STAMPS = ["(1.5)", "(0)", "(1700000000.123456)", "(-1.5)", "(1.5.2)", "()", "1.5", "(x)"]
NON_FINITE_STAMPS = ["(nan)", "(inf)", "(-inf)", "(1e999)", "(NaN)", "(Infinity)"]


def candump_lines(stamps: list[str]) -> st.SearchStrategy[str]:
    """Random text, and lines shaped like ``(stamp) channel ID#DATA [R|T]`` with awkward
    parts: 2- to 9-digit IDs, odd-length and long data, remote frames R0..R9, CAN FD ``##``."""
    ident = st.sampled_from(["123", "7FF", "800", "000", "1FFFFFFF", "20000000", "12", "1234",
                             "12345678", "xyz", ""])
    data = st.binary(max_size=10).map(lambda b: b.hex().upper()) | st.sampled_from(
        ["R", "R0", "R8", "R9", "R-1", "0", "ZZ", "#0", "#1122", " 11"]
    )
    shaped = st.builds(
        "{} {} {}#{}{}".format,
        st.sampled_from(stamps),
        st.sampled_from(["can0", "vcan0", "x" * 40]),
        ident,
        data,
        st.sampled_from(["", " R", " T", " X", " R R"]),
    )
    return st.text(max_size=80) | shaped


def _sign_or_prefix_in_id(line: str) -> bool:
    """IDs like -01, +7F, 0x7, 1_2 (refused, tested on their own below)."""
    parts = line.split()
    ident = parts[2].partition("#")[0] if len(parts) > 2 else ""
    return any(c in ident for c in "+-_xX")


@FUZZ
@given(line=candump_lines(FINITE_STAMPS))
def test_candump_lines_raise_only_candump_error(line: str) -> None:
    assume(not _sign_or_prefix_in_id(line))
    try:
        entry = parse_line(line, 7)
    except CandumpError as err:
        assert str(err).startswith("line 7: ")
    else:
        frame = entry.frame
        assert len(frame.data) <= 8
        assert 0 <= frame.arbitration_id <= (0x1FFFFFFF if frame.is_extended_id else 0x7FF)


@FUZZ
@given(line=candump_lines(NON_FINITE_STAMPS))
@example(line="(inf) can0 069#0000000000000000")
@example(line="(nan) can0 069#0000000000000000")
def test_candump_time_stamps_must_be_finite(line: str) -> None:
    try:
        entry = parse_line(line, 7)
    except CandumpError:
        return
    assert math.isfinite(entry.timestamp_s), line


@pytest.mark.parametrize("ident", ["-01", "+7F", "0x7", "1_2", "-0000001", "0x00007F"])
def test_candump_ids_are_plain_hexadecimal(ident: str) -> None:
    try:
        entry = parse_line(f"(1.5) can0 {ident}#00", 7)
    except CandumpError as err:
        assert "hexadecimal ID" in str(err)
    else:
        raise AssertionError(f"ID {ident!r} read as {entry.frame.arbitration_id}")


# ------------------------------------------------------------------------------- simulators


@pytest.mark.parametrize("case", ALL_CASES)
@FUZZ
@given(data=st.data())
def test_device_simulators_take_any_frame(case: str, data: st.DataObject) -> None:
    drv = make_driver(case)
    sims = make_simulators(case)
    own = own_feedback(drv)
    # Aim at what the simulators read: the host's commands (the driver's enable frames and a
    # command) as well as the feedback IDs.
    host = drv.enable(0.0) + drv.command([0.0] * len(drv.motors), 0.0)
    aims = own + [Own(f.arbitration_id, f.is_extended_id, frozenset({f.dlc})) for f in host]
    t = 0.0
    for frame in data.draw(st.lists(frames(aims), max_size=25)):
        for sim in sims:
            out = sim.handle(frame, t) + sim.tick(t)
            assert all(isinstance(f, Frame) for f in out)
        t += 0.001
