"""Steering actuators on the CiA 402 driver: cyclic synchronous position mode (CSP, mode 8).

Golden frames follow CiA 301 / CiA 402 as the canopen library (christiansandberg/canopen)
implements them: the RPDO layout is the
"RPDO3 = 6040 + 607A" entry of the DS402 default pattern (controlword u16 + target position
i32, little endian, as the worked example "RPDO4 (6040 + 60FF): enable op + 1000" =
``0F 00 E8 03 00 00``), the SDO frames the "Worked examples (node 3)" (``2F 60 60 00 03 ..``
for 0x6060 = 3; mode 8 is CSP in the 0x6060 table and in ``canopen.profiles.p402``
``OP_MODE_NAMES``), the mapping entries ``index << 16 | subindex << 8 | bits`` of CiA 301.
"""

from __future__ import annotations

import itertools
import math
from typing import TYPE_CHECKING

import pytest
from canopen.profiles.p402 import OperationMode as P402Mode
from hypothesis import given
from hypothesis import strategies as st

from drivers.cia402 import Cia402Codec, Cia402Driver, Cia402Options, PdoLayout
from drivers.cia402.codec import make_rpdo, make_sync, make_tpdo, position_to_raw
from drivers.cia402.enums import DataType, OperationMode, State, supported_mode_bit
from drivers.cia402.phase import Phase
from drivers.cia402.sdo import make_sdo_download
from drivers.cia402.sequence import NodeSequencer
from drivers.cia402.steps import SdoExpectStep, SdoWriteStep, configuration_steps
from gateway.bus.can_bus import send_frames
from gateway.core.errors import ConfigError, EncodeError
from gateway.core.types import DriveFault, DriveState, Frame, MotorConfig
from gateway.sim.device import SimFault
from tests import factories
from tests.drivers.cia402_bench import Bench, benches

if TYPE_CHECKING:
    from collections.abc import Callable, Iterator

DT = 0.001
TWO_PI = 2.0 * math.pi
CPR = 4096
GEAR = 12.8
#: One position count at the steering angle (rad).
COUNT_STEER = TWO_PI / CPR / GEAR


def steer_motor(node_id: int = 5, zero_rad: float = 0.3, *, invert: bool = False,
                gear: float = GEAR, **options: object) -> MotorConfig:
    """A CiA 402 steering actuator ``"fl steering"`` of the factory
    (:func:`tests.factories.steer_motor`), ``CPR`` counts per revolution."""
    return factories.steer_motor(
        "cia402", node_id, ("front_left",), wheel="fl steering", zero_rad=zero_rad,
        gear_ratio=gear, invert=invert, options={"counts_per_rev": CPR, **options},
    )


DRIVE = factories.motor("cia402", 3, "front_left", gear_ratio=10.0)
STEER = steer_motor()


def hexb(text: str) -> bytes:
    return bytes.fromhex(text)


# ===================================================================== golden frames


@pytest.mark.parametrize(
    ("frame", "cob", "data"),
    [
        # RPDO4 of node 5 with 6040 + 607A: enable operation, target 100000 (0x000186A0)
        (make_rpdo(0x505, 0x000F, 100_000), 0x505, "0F 00 A0 86 01 00"),
        (make_rpdo(0x505, 0x000F, -1), 0x505, "0F 00 FF FF FF FF"),
        # 0x6060 = 8 (cyclic synchronous position) by expedited SDO, 1 byte
        (make_sdo_download(5, 0x6060, 0, 8, DataType.INTEGER8), 0x605,
         "2F 60 60 00 08 00 00 00"),
        # RPDO4 mapping entry 2 = 0x607A0020 (target position, sub 0, 32 bits)
        (make_sdo_download(5, 0x1603, 2, 0x607A0020, DataType.UNSIGNED32), 0x605,
         "23 03 16 02 20 00 7A 60"),
        # TPDO3 (6041 + 6064): OPERATION ENABLED, position -2 (int32 little endian)
        (make_tpdo(0x385, 0x0237, -2), 0x385, "37 02 FE FF FF FF"),
    ],
)
def test_golden_frames(frame: Frame, cob: int, data: str) -> None:
    assert frame == Frame(cob, hexb(data))


def test_csp_is_mode_8_as_canopen_names_it() -> None:
    csp = OperationMode.CYCLIC_SYNCHRONOUS_POSITION
    assert P402Mode.CODE2NAME[csp] == "CYCLIC SYNCHRONOUS POSITION"
    assert P402Mode.SUPPORTED[P402Mode.CODE2NAME[csp]] == 0x80  # bit of 0x6502
    assert supported_mode_bit(csp) == 0x80


def test_position_to_raw_rounds_and_wraps() -> None:
    assert position_to_raw(2.5, "x") == 2 and position_to_raw(-1.6, "x") == -2
    assert position_to_raw(float(1 << 31), "x") == -(1 << 31)
    assert position_to_raw(float((1 << 32) + 7), "x") == 7
    with pytest.raises(EncodeError, match=r"Expected x as a finite number of position units, "
                                          r"but got nan\."):
        position_to_raw(math.nan, "x")


def test_configuration_steps_of_a_steering_actuator() -> None:
    steps = configuration_steps(5, Cia402Options.from_block(STEER.options, "s"), position=True)
    writes = {(s.index, s.subindex): s for s in steps if isinstance(s, SdoWriteStep)}
    assert writes[(0x1603, 1)].value == 0x60400010
    assert writes[(0x1603, 2)].value == 0x607A0020
    assert writes[(0x1403, 2)].value == 1  # synchronous: the target applies at the SYNC
    mode = writes[(0x6060, 0)]
    assert (mode.value, mode.what) == (8, "modes of operation = cyclic synchronous position")
    expect = [s for s in steps if isinstance(s, SdoExpectStep)]
    assert [(s.index, s.expected) for s in expect] == [(0x6061, 8)]
    drive = configuration_steps(3, Cia402Options.from_block(DRIVE.options, "d"))
    assert SdoWriteStep(0x1603, 2, 0x60FF0020, DataType.UNSIGNED32,
                        "RPDO4 mapping entry 2 (0x60FF)") in drive


def test_steering_refuses_event_driven_pdos() -> None:
    with pytest.raises(ConfigError) as err:
        Cia402Driver([steer_motor(sync=False)])
    assert str(err.value) == (
        "motor 'fl steering'.sync: expected true for a steering actuator (cyclic "
        "synchronous position mode takes its target at every SYNC), got false")


def test_steering_refuses_zero_outside_int32_positions() -> None:
    with pytest.raises(ConfigError) as err:
        Cia402Driver([steer_motor(zero_rad=4e6)])
    assert str(err.value) == (
        "motor 'fl steering'.zero_rad: expected a motor position within the drive's "
        "int32 position range (-3.2942e+06 to 3.2942e+06 rad at 4096 counts per revolution), "
        "got 4000000.0")


def test_non_finite_angle_is_refused() -> None:
    drv = Cia402Driver([DRIVE, STEER])
    with pytest.raises(EncodeError) as err:
        drv.command([0.0, math.inf], 0.0)
    assert str(err.value) == (
        'Expected a finite steering angle for CiA 402 node 5 ("fl steering") in rad, but got '
        "inf.")
    with pytest.raises(EncodeError, match="finite steering angle"):
        drv.preview_command([0.0, math.nan])


def test_preview_of_a_mixed_driver() -> None:
    drv = Cia402Driver([DRIVE, STEER])
    frames = drv.preview_command([1.0, 0.1])
    # drive: 1 rad/s x 10 = 95.49 RPM -> 95; steering: (0.3 + 0.1 x 12.8) rad -> 1030 counts
    assert frames == [Frame(0x503, hexb("0F 00 5F 00 00 00")),
                      Frame(0x505, hexb("0F 00 06 04 00 00")), make_sync()]
    assert round((0.3 + 0.1 * GEAR) * CPR / TWO_PI) == 0x406


# ===================================================================== position round trip


@given(
    angle=st.floats(-math.pi, math.pi),
    zero_counts=st.integers(-(1 << 31), (1 << 31) - 1),
    gear=st.floats(0.5, 100.0),
    invert=st.booleans(),
)
def test_position_round_trip_within_one_count(
    angle: float, zero_counts: int, gear: float, invert: bool
) -> None:
    """Angle -> RPDO target -> the same count as 0x6064 -> feedback angle, across the wrap."""
    motor = steer_motor(zero_rad=zero_counts * TWO_PI / CPR, invert=invert, gear=gear)
    drv = Cia402Driver([motor])
    raw = drv.preview_command([angle])[0].data[2:]
    at_zero = position_to_raw(zero_counts, "zero")
    drv.on_frame(Frame(0x385, make_tpdo(0x385, 0x0237, at_zero).data, timestamp_s=1.0))
    fb = drv.feedback(0)
    assert fb is not None and abs(fb.position_rad) <= 1e-9
    value = int.from_bytes(raw, "little", signed=True)
    drv.on_frame(Frame(0x385, make_tpdo(0x385, 0x0237, value).data, timestamp_s=1.01))
    fb = drv.feedback(0)
    assert fb is not None
    assert fb.position_rad == pytest.approx(angle, abs=0.5 * TWO_PI / CPR / gear * 1.0001)


# ===================================================================== sequencer


def phase_of(seq: NodeSequencer) -> Phase:
    return seq.phase  # (a call: mypy does not carry a narrowed attribute across calls)


def test_walk_waits_for_the_position_before_any_controlword() -> None:
    seq = NodeSequencer(5, "node 5", Cia402Codec({5: PdoLayout()}), (), position=True)
    seq.start(0.0)
    seq.on_status(0x0250)  # SWITCH ON DISABLED
    assert seq.poll(0.01) == [] and phase_of(seq) is Phase.WALKING
    assert seq.poll(0.02) == []  # still no position: a CSP drive would run to target 0
    seq.hold = -123456
    assert seq.poll(0.03) == [Frame(0x505, hexb("06 00 C0 1D FE FF"))]  # shutdown, hold
    seq.start(1.0)
    seq.on_status(0x0250)
    seq.poll(1.0)
    seq.poll(1.6)
    assert phase_of(seq) is Phase.FAILED
    assert seq.error == ("node 5: no position actual value (0x6064) in a TPDO within 0.5 s; a "
                         "cyclic synchronous position drive is only enabled with its target "
                         "set to where it stands")


# ===================================================================== on the virtual bus


@pytest.fixture
def bench(channel: str) -> Iterator[Callable[..., Bench]]:
    with benches(channel) as make:
        yield make


def rpdo_targets(b: Bench, cob: int, since: int = 0) -> list[int]:
    """The target positions of the RPDOs on ``cob`` that the bench sent (from ``since``)."""
    return [int.from_bytes(f.data[2:], "little", signed=True)
            for f in b.sent[since:] if f.arbitration_id == cob]


def test_steer_fault_and_recover(bench: Callable[..., Bench]) -> None:
    b = bench([STEER])
    sim = b.sims[0]
    assert sim.object_value(0x6502) & 0x80  # CSP supported by a steering drive
    assert b.enable([0.0])
    assert sim.object_value(0x6061) == 8 and sim.object_value(0x1603, 2) == 0x607A0020
    assert sim.steer_rad == pytest.approx(0.0, abs=COUNT_STEER)  # enabled where it stood
    b.run(0.3, [0.5])
    fb = b.drv.feedback(0)
    assert fb is not None
    assert fb.position_rad == pytest.approx(0.5, abs=COUNT_STEER)
    assert sim.steer_rad == pytest.approx(0.5, abs=COUNT_STEER)
    assert fb.velocity_rad_s == pytest.approx(0.0, abs=TWO_PI / 60 / GEAR)  # 1 RPM motor
    assert sim.position_counts == round((0.3 + 0.5 * GEAR) * CPR / TWO_PI)  # absolute
    assert sim.object_value(0x6041) & 0x1000  # CSP: "drive follows the target"
    sim.inject(SimFault.FAULT)
    assert b.run(0.1, [0.5], until=lambda: b.drv.state(0, b.t) is DriveState.FAULT)
    status = b.drv.status(b.t)[0]
    assert DriveFault.OVER_CURRENT in status.faults
    assert 'node 5 ("fl steering")' in status.detail
    assert b.drv.command([0.5], b.t) == [make_sync()]  # no RPDO while faulted
    b.run(0.2, [0.5])
    sim.clear(SimFault.FAULT)
    sim.model.position_rad += 0.2  # pushed by hand while unpowered
    start = len(b.sent)
    assert b.enable([-0.4])
    # re-enabled where it stands now, not at the last target: every walk RPDO holds position
    here = round((0.3 + 0.5 * GEAR + 0.2) * CPR / TWO_PI)
    walk = rpdo_targets(b, 0x505, start)
    assert walk and all(abs(v - here) <= 1 for v in walk[:3])
    b.run(0.4, [-0.4])
    fb = b.drv.feedback(0)
    assert fb is not None and fb.position_rad == pytest.approx(-0.4, abs=COUNT_STEER)
    assert sim.steer_rad == pytest.approx(-0.4, abs=COUNT_STEER)
    assert b.drv.status(b.t)[0].faults == DriveFault.NONE and not b.drv.rejected


def test_target_slews_at_max_rpm(bench: Callable[..., Bench]) -> None:
    b = bench([STEER])
    assert b.enable([0.0])
    start = len(b.sent)
    b.run(0.1, [1.0])
    targets = rpdo_targets(b, 0x505, start)
    per_cycle = 3000 / 60 * CPR * DT  # 204.8 counts per 1 ms cycle
    steps = [y - x for x, y in itertools.pairwise(targets)]
    assert max(steps) <= math.ceil(per_cycle) and max(steps) >= math.floor(per_cycle)
    assert targets[-1] == round((0.3 + 1.0 * GEAR) * CPR / TWO_PI)  # reached in ~41 ms
    b.run(0.6, [1.0])  # the motor lags (2000 rad/s^2 in the model) and settles
    assert b.sims[0].steer_rad == pytest.approx(1.0, abs=COUNT_STEER)


def test_absolute_position_across_the_int32_wrap(bench: Callable[..., Bench]) -> None:
    zero_counts = (1 << 31) - 2000
    motor = steer_motor(zero_rad=zero_counts * TWO_PI / CPR, gear=1.0)
    b = bench([motor])
    assert b.enable([0.0])
    fb = b.drv.feedback(0)
    assert fb is not None and fb.position_rad == pytest.approx(0.0, abs=TWO_PI / CPR)
    b.run(0.5, [6.0])  # 6 rad at the motor = 3912 counts: past 2^31 - 1
    assert b.sims[0].position_counts < 0  # 0x6064 wrapped
    assert rpdo_targets(b, 0x505)[-1] < 0  # and so did the target
    fb = b.drv.feedback(0)
    assert fb is not None and fb.position_rad == pytest.approx(6.0, abs=TWO_PI / CPR)
    assert b.sims[0].steer_rad == pytest.approx(6.0, abs=TWO_PI / CPR)


def test_disable_releases_where_it_stands(bench: Callable[..., Bench]) -> None:
    b = bench([STEER])
    assert b.enable([0.0])
    b.run(0.2, [0.25])
    here = b.sims[0].position_counts
    frames = b.drv.disable(b.t)
    assert frames == [make_rpdo(0x505, 0x0006, here), make_sync()]  # SHUTDOWN, no wait
    send_frames(b.gw, frames)
    assert b.run(0.05, [0.25], until=lambda: b.drv.phase(0) is Phase.IDLE)
    assert b.sims[0].state is State.READY_TO_SWITCH_ON
    assert b.drv.state(0, b.t) is DriveState.DISABLED
    assert b.sims[0].steer_rad == pytest.approx(0.25, abs=COUNT_STEER)


def test_mixed_driver_sends_each_node_its_kind(bench: Callable[..., Bench]) -> None:
    b = bench([DRIVE, STEER])
    drive_sim, steer_sim = b.sims
    assert b.enable([0.0, 0.0])
    assert drive_sim.object_value(0x6061) == 3 and steer_sim.object_value(0x6061) == 8
    assert drive_sim.object_value(0x1603, 2) == 0x60FF0020
    assert steer_sim.object_value(0x1603, 2) == 0x607A0020
    start = len(b.sent)
    b.run(0.5, [4.0, -0.3])
    cycle = b.sent[-3:]
    assert [f.arbitration_id for f in cycle] == [0x503, 0x505, 0x080]
    assert cycle[0] == make_rpdo(0x503, 0x000F, round(4.0 * 10 * 60 / TWO_PI))  # RPM
    assert cycle[1] == make_rpdo(0x505, 0x000F, round((0.3 - 0.3 * GEAR) * CPR / TWO_PI))
    assert sum(f.arbitration_id == 0x080 for f in b.sent[start:]) == 500  # one SYNC per bus
    drive_fb, steer_fb = b.drv.feedback(0), b.drv.feedback(1)
    assert drive_fb is not None and steer_fb is not None
    assert drive_fb.velocity_rad_s == pytest.approx(4.0, abs=TWO_PI / 60 / 10)
    assert drive_sim.wheel_velocity_rad_s == pytest.approx(4.0, abs=0.01)
    assert steer_fb.position_rad == pytest.approx(-0.3, abs=COUNT_STEER)
    assert steer_sim.steer_rad == pytest.approx(-0.3, abs=COUNT_STEER)
    assert steer_sim.model.target_position_rad is not None
    assert drive_sim.model.target_position_rad is None  # velocity mode
