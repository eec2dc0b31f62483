"""Shared drivers, simulators and strategies of the decoder fuzzing (test_fuzz_decoders_*).

Each driver is built from a shipped configuration (``gateway.config.parse_config`` +
:class:`~gateway.drive.driveset.DriveSet`), with the protocol keys varied where a file ships one
variant (ODrive firmware 0.5 / 0.6, 11-bit / 29-bit IDs), plus a DBC driver with float32
signals (the official ODrive DBC) for NaN and infinity.  Frames are random: IDs at and near the
driver's own, random 11- and 29-bit IDs, DLC 0..8, random data, float32 NaN / infinity / huge
patterns, remote frames.
"""

from __future__ import annotations

import copy
import functools
import math
import struct
from typing import TYPE_CHECKING, Any, NamedTuple, TypeVar

import yaml
from hypothesis import HealthCheck, settings
from hypothesis import strategies as st

from drivers.cia402 import Cia402Driver
from drivers.cia402.enums import CobBase, tpdo_cob_id
from drivers.dbc import DbcDriver
from drivers.dji import DjiDriver
from drivers.odrive import Firmware, OdriveDriver
from drivers.odrive.enums import CmdId
from drivers.vesc import VescDriver
from gateway.config import parse_config
from gateway.core.types import Frame, MotorConfig
from gateway.drive.driveset import DriveSet
from tests import factories
from tests.conftest import CONFIG_DIR, DATA_DIR

if TYPE_CHECKING:

    from gateway.core.settings import GatewayConfig
    from gateway.drive.driver import MotorDriver

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
