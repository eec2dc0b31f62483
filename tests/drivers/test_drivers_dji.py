"""Tests of the DJI C620 / C610 driver: codec, PI loop, driver and simulator on a virtual bus.

Golden frames are the worked examples of the RoboMaster C620/C610 user guides' CAN protocol
sections ("Worked
examples" table), which were checked against DJI's ``CAN_receive.c``.
"""

from __future__ import annotations

import math
import subprocess
import sys
from typing import TYPE_CHECKING

import can
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import drivers.dji.sim
from drivers.dji import (
    C610,
    C620,
    M2006_GEAR_RATIO,
    M3508_GEAR_RATIO,
    TEMP_HYSTERESIS_C,
    DjiDriver,
    DjiFeedback,
    DjiFrameId,
    DjiOptions,
    EscModel,
    SpeedPi,
)
from drivers.dji.codec import (
    COMMAND_STRUCT,
    decode_command,
    decode_feedback,
    encode_command,
    encode_feedback,
    feedback_fields,
    message_name,
    unwrap_delta,
)
from drivers.dji.protection import ACK_KEY
from drivers.dji.sim import DjiMotorModel, DjiSimulator
from gateway.bus.can_bus import drain, send_frames
from gateway.core.errors import ConfigError, DecodeError, EncodeError
from gateway.core.types import DriveFault, DriveState, Frame, MotorConfig
from gateway.drive.claims import FrameClaim
from gateway.drive.registry import get_driver_class
from gateway.sim.bus import SimulatedControllers
from gateway.sim.device import SimFault
from gateway.sim.registry import simulator_for
from tests import factories
from tests.conftest import REPO

if TYPE_CHECKING:
    from collections.abc import Callable, Sequence

TWO_PI = 2.0 * math.pi


def motor(
    node_id: int = 1,
    esc: str = "c620",
    gear: float | None = None,
    invert: bool = False,
    *,
    validate: bool = True,
    **options: object,
) -> MotorConfig:
    """A DJI motor block of the factory (:func:`tests.factories.motor`): wheel ``w<node>``, the
    gearbox of the ESC's motor unless ``gear`` is given, no controller stop acknowledged."""
    ratio = gear if gear is not None else (M3508_GEAR_RATIO if esc == "c620" else M2006_GEAR_RATIO)
    return factories.motor(
        "dji", node_id, f"w{node_id}", gear_ratio=ratio, invert=invert, max_rpm=20000.0,
        validate=validate, options={"esc": esc, "no_controller_stop": "acknowledged", **options},
    )


def feedback_frame(
    esc_id: int, angle: int, rpm: int = 0, current: int = 0, temp: int = 35, t: float = 0.0
) -> Frame:
    frame = encode_feedback(DjiFeedback(esc_id, angle, rpm, current, temp))
    return frame.stamped(t)


def currents_in(frames: Sequence[Frame]) -> dict[int, int]:
    out: dict[int, int] = {}
    for f in frames:
        decoded = decode_command(f)
        assert decoded is not None
        out.update(decoded)
    return out


# ===================================================================== codec: golden bytes


def slots(**by_esc: int) -> list[int]:
    """The eight raw set points of ESC 1..8, ``e<n>=value`` for the ones that are not 0."""
    raw = [0] * 8
    for key, value in by_esc.items():
        raw[int(key[1:]) - 1] = value
    return raw


def test_golden_command_esc_1_4() -> None:
    # spec section 4, worked example 1: 4000, -4000, 0, 1000 on 0x200.
    frames = encode_command(slots(e1=4000, e2=-4000, e4=1000), (0,))
    assert frames == [Frame(0x200, bytes.fromhex("0FA0F060000003E8"))]
    assert C620.raw_to_amps(4000) == pytest.approx(4.88, abs=0.005)


def test_golden_command_esc_5_8() -> None:
    # spec section 4, worked example 2: ESC5 = -16384 (-20 A), ESC6 = +16384 on 0x1FF.
    frames = encode_command(slots(e5=-16384, e6=16384), (1,))
    assert frames == [Frame(0x1FF, bytes.fromhex("C000400000000000"))]
    assert C620.amps_to_raw(-20.0) == -16384


def test_golden_feedback() -> None:
    # spec section 4, worked example 3: ecd 8191, 1500 rpm, -200 current, 35 degC on 0x201.
    frame = Frame(0x201, bytes.fromhex("1FFF05DCFF382300"))
    assert decode_feedback(frame) == DjiFeedback(1, 8191, 1500, -200, 35)
    assert feedback_fields(frame) == (8191, 1500, -200, 35, 0)
    assert encode_feedback(DjiFeedback(1, 8191, 1500, -200, 35)) == frame


def test_golden_feedback_through_driver_gives_output_rpm() -> None:
    # 1500 rotor rpm = 78.11 rpm at the M3508 output (spec worked example 3).
    drv = DjiDriver([motor(1)])
    assert drv.measurement(0) is None
    assert drv.on_frame(Frame(0x201, bytes.fromhex("1FFF05DCFF382300"), timestamp_s=1.0))
    fb = drv.feedback(0)
    assert fb is not None
    assert fb.velocity_rad_s * 60.0 / TWO_PI == pytest.approx(78.11, abs=0.005)
    assert fb.position_rad == 0.0
    assert drv.measurement(0) == DjiFeedback(1, 8191, 1500, -200, 35)


def test_golden_wrap() -> None:
    # spec section 4, worked example 4: last ecd 8100, new 50 -> +142 counts.
    assert unwrap_delta(8100, 50) == 142
    assert unwrap_delta(50, 8100) == -142
    assert unwrap_delta(0, 4096) == 4096
    assert unwrap_delta(0, 4097) == -4095


def test_only_the_groups_asked_for() -> None:
    assert encode_command(slots(e2=100), (0,)) == [
        Frame(0x200, bytes.fromhex("0000006400000000"))
    ]
    assert encode_command(slots(e8=-1), (1,)) == [Frame(0x1FF, bytes.fromhex("000000000000FFFF"))]
    both = encode_command(slots(e7=1, e3=2), (0, 1))
    assert [f.arbitration_id for f in both] == [0x200, 0x1FF]
    assert encode_command(slots(), ()) == []


def test_encode_refuses_what_does_not_fit_an_int16() -> None:
    with pytest.raises(EncodeError, match="Expected int16 current set points for DJI ESCs"):
        encode_command(slots(e3=40000), (0,))


def test_message_names() -> None:
    assert [message_name(i) for i in (0x200, 0x1FF, 0x700, 0x201, 0x208, 0x209, 0x069)] == [
        "COMMAND_ESC_1_4", "COMMAND_ESC_5_8", "QUICK_ID_SET", "FEEDBACK_ESC_1",
        "FEEDBACK_ESC_8", None, None,
    ]


@pytest.mark.parametrize(
    ("frame", "message"),
    [
        (Frame(0x201, bytes(7)), "Expected 8 data bytes for DJI feedback 0x201, but got 7."),
        (Frame(0x202, bytes(9)), "but got 9."),
        (Frame(0x203, bytes(8), is_extended_id=True), "but got a 29-bit ID."),
        (Frame(0x204, is_remote_frame=True, dlc=8), "but got a remote frame."),
        (Frame(0x205, bytes.fromhex("2000000000000000")), "between 0 and 8191, but got 8192."),
    ],
)
def test_decode_rejects_malformed(frame: Frame, message: str) -> None:
    for decode in (decode_feedback, feedback_fields):
        with pytest.raises(DecodeError) as info:
            decode(frame)
        assert message in str(info.value)


@pytest.mark.parametrize("ident", [0x069, 0x200, 0x1FF, 0x209, 0x20B, 0x700])
def test_decode_ignores_foreign_ids(ident: int) -> None:
    assert decode_feedback(Frame(ident, bytes(8))) is None


def test_decode_command_checks() -> None:
    assert decode_command(Frame(0x201, bytes(8))) is None
    with pytest.raises(DecodeError, match="Expected 8 data bytes for DJI command 0x200"):
        decode_command(Frame(0x200, bytes(4)))
    with pytest.raises(DecodeError, match="29-bit"):
        decode_command(Frame(0x1FF, bytes(8), is_extended_id=True))


def test_encode_feedback_range() -> None:
    with pytest.raises(EncodeError, match="Expected angle for ESC 1 between 0 and 8191"):
        encode_feedback(DjiFeedback(1, 8192, 0, 0, 0))
    with pytest.raises(EncodeError, match="Expected temperature for ESC 2 between 0 and 255"):
        encode_feedback(DjiFeedback(2, 0, 0, 0, 256))


# ===================================================================== codec: round trips

_slot = st.integers(-16384, 16384)


@given(st.lists(_slot, min_size=8, max_size=8), st.sets(st.integers(0, 1)))
def test_command_round_trip(raw: list[int], groups: set[int]) -> None:
    frames = encode_command(raw, sorted(groups))
    decoded = currents_in(frames)
    assert decoded == {k + 1: raw[k] for g in groups for k in range(4 * g, 4 * g + 4)}
    assert all(f.dlc == 8 and not f.is_extended_id for f in frames)


@given(
    st.integers(1, 8),
    st.integers(0, 8191),
    st.integers(-32768, 32767),
    st.integers(-32768, 32767),
    st.integers(0, 255),
)
def test_feedback_round_trip(esc: int, angle: int, rpm: int, cur: int, temp: int) -> None:
    fb = DjiFeedback(esc, angle, rpm, cur, temp)
    assert decode_feedback(encode_feedback(fb)) == fb


@given(st.sampled_from([C620, C610]), st.floats(-20.0, 20.0))
def test_amps_round_trip_within_half_lsb(model: EscModel, amps: float) -> None:
    amps = max(-model.full_scale_a, min(model.full_scale_a, amps))
    lsb = model.full_scale_a / model.full_scale_raw
    assert abs(model.raw_to_amps(model.amps_to_raw(amps)) - amps) <= lsb / 2 + 1e-12


@given(st.integers(0, 8191), st.lists(st.integers(-4095, 4095), max_size=300))
def test_unwrap_many_turns_both_directions(start: int, steps: list[int]) -> None:
    true_total, last, total = 0, start, 0
    for step in steps:
        true_total += step
        count = (start + true_total) % 8192
        total += unwrap_delta(last, count)
        last = count
    assert total == true_total


# ===================================================================== PI controller


def test_pi_anti_windup() -> None:
    pi = SpeedPi(kp_a_per_rad_s=0.1, ki_a_per_rad=1.0, limit_a=20.0)
    integral = 0.0
    for _ in range(1000):  # 1 s saturated at full positive current
        out, integral = pi.step(integral, 1000.0, 0.001)
        assert out == 20.0
    assert integral == 0.0  # held: the proportional term alone saturates
    out, integral = pi.step(integral, -1.0, 0.001)
    assert out == pytest.approx(-0.101)  # reverses at once, nothing to unwind


def test_pi_integrates_to_the_limit_only() -> None:
    pi = SpeedPi(0.0, 10.0, 5.0)
    integral = 0.0
    for _ in range(100):
        out, integral = pi.step(integral, 1.0, 0.1)
    assert out == integral == 5.0
    assert pi.step(integral, -1.0, 0.1)[1] == pytest.approx(4.0)


def test_pi_non_finite_error_gives_zero() -> None:
    assert SpeedPi(0.1, 1.0, 20.0).step(3.0, math.nan, 0.001) == (0.0, 0.0)


def _clip(value: float, limit: float) -> float:
    return min(max(value, -limit), limit)


def _reference_step(
    pi: SpeedPi, integral_a: float, error: float, dt: float
) -> tuple[float, float]:
    """The control law of drivers.dji.pi as its docstring states it, with min / max."""
    lim = pi.limit_a
    p = pi.kp_a_per_rad_s * error
    integral = _clip(integral_a + pi.ki_a_per_rad * error * max(dt, 0.0), lim)
    if (p + integral > lim and error > 0.0) or (p + integral < -lim and error < 0.0):
        integral = _clip(integral_a, lim)  # conditional integration
    return _clip(p + integral, lim), integral


@given(
    st.floats(-30.0, 30.0),
    st.floats(-1e4, 1e4),
    st.floats(-0.01, 0.1),
    st.floats(0.0, 10.0),
    st.floats(0.0, 100.0),
    st.floats(0.1, 20.0),
)
def test_pi_step_is_the_stated_law(
    integral: float, err: float, dt: float, kp: float, ki: float, limit: float
) -> None:
    pi = SpeedPi(kp, ki, limit)
    assert pi.step(integral, err, dt) == _reference_step(pi, integral, err, dt)


@given(
    st.floats(-10.0, 10.0),
    st.floats(-1e4, 1e4),
    st.floats(0.0, 0.1),
    st.floats(0.0, 10.0),
    st.floats(0.0, 100.0),
)
def test_pi_output_within_limit(
    integral: float, err: float, dt: float, kp: float, ki: float
) -> None:
    pi = SpeedPi(kp, ki, 10.0)
    out, new_integral = pi.step(integral, err, dt)
    assert abs(out) <= 10.0 and abs(new_integral) <= 10.0


# ===================================================================== driver: config


def test_registry_and_options() -> None:
    assert get_driver_class("dji") is DjiDriver
    assert DjiDriver.NODE_ID_RANGE == (1, 8)
    ack = {"no_controller_stop": "acknowledged"}
    opts = DjiDriver.validate_options(ack, "robot.yaml: wheels[0].motor")
    assert opts == {
        "esc": "c620",
        "kp": 0.1,
        "ki": 1.0,
        "max_current_a": 0.0,
        "liveness_s": 0.1,
        "max_temp_c": 80.0,
        "no_controller_stop": "acknowledged",
    }
    assert DjiDriver([motor(1)]).live.liveness_s == 0.1
    assert DjiDriver.Options is DjiOptions
    assert ACK_KEY in DjiOptions.specs()  # the acknowledgement is a key of its own name
    assert DjiDriver.OPTIONS["liveness_s"].default == 0.1
    assert DjiDriver.BUS_WIDE == ("liveness_s",)


@pytest.mark.parametrize(
    ("motors", "message"),
    [
        ([motor(1, esc="c630", validate=False)], "esc: expected one of 'c620', 'c610', got 'c630'"),
        (
            [motor(1, esc="c610", validate=False, max_current_a=15.0)],
            "at most 10 A for a C610, got 15",
        ),
        ([motor(1, validate=False, max_current_a=25.0)], "expected at most 20, got 25.0"),
        ([motor(1), motor(1)], "node 1 is already used by wheel 'w1'"),
        ([motor(0)], "expected int 1..8, got 0"),
        ([motor(9)], "expected int 1..8, got 9"),
        (
            [motor(1), motor(2, liveness_s=0.2)],
            "motor 'w2'.liveness_s: expected 0.1 like motor 'w1' on the same DJI bus, got 0.2",
        ),
        ([motor(1, validate=False, speed_kp=1.0)], "speed_kp: unknown key"),
        ([motor(1, validate=False, kp="fast")], "expected float, got 'fast'"),
    ],
)
def test_config_errors(motors: list[MotorConfig], message: str) -> None:
    with pytest.raises(ConfigError) as info:
        DjiDriver(motors)
    assert message in str(info.value)


# ===================================================================== driver: commands


def test_preview_command_golden() -> None:
    # kp = 0.1 A per rad/s and gear 1: 48.828125 rad/s -> 4.8828125 A -> raw 4000 (spec example 1);
    # 200 rad/s saturates at 20 A -> raw 16384 (spec example 2).
    drv = DjiDriver([motor(i, gear=1.0) for i in (1, 2, 3, 4, 5, 6)])
    speeds = [48.828125, -48.828125, 0.0, 12.20703125, -200.0, 200.0]
    assert drv.preview_command(speeds) == [
        Frame(0x200, bytes.fromhex("0FA0F060000003E8")),
        Frame(0x1FF, bytes.fromhex("C000400000000000")),
    ]
    # preview changes nothing: not armed, no feedback, so a real command is all zeros.
    assert currents_in(drv.command(speeds, 0.0)) == dict.fromkeys(range(1, 9), 0)


def test_command_zero_without_feedback_even_when_enabled() -> None:
    drv = DjiDriver([motor(1), motor(6)])
    assert drv.enable(0.0) == []
    frames = drv.command([5.0, -5.0], 0.001)
    assert [f.arbitration_id for f in frames] == [0x200, 0x1FF]
    assert all(f.data == bytes(8) for f in frames)
    assert drv.state(0, 0.001) is DriveState.OFFLINE


def test_command_only_high_group() -> None:
    drv = DjiDriver([motor(5), motor(8)])
    assert [f.arbitration_id for f in drv.command([0.0, 0.0], 0.0)] == [0x1FF]
    assert [f.arbitration_id for f in drv.disable(0.0)] == [0x1FF]


def test_command_validation() -> None:
    drv = DjiDriver([motor(3)])
    with pytest.raises(EncodeError) as info:
        drv.command([1.0, 2.0], 0.0)
    assert str(info.value) == "Expected 1 setpoints for the DJI motors (w3), but got 2."
    limit = 20000.0 * TWO_PI / 60.0 / M3508_GEAR_RATIO
    with pytest.raises(EncodeError) as info:
        drv.command([120.0], 0.0)
    assert str(info.value) == (
        f'Expected a wheel speed for DJI node 3 ("w3") between {-limit:.6g} and {limit:.6g} '
        "rad/s (max_rpm 20000), but got 120.0."
    )
    for bad in (math.nan, -120.0):
        with pytest.raises(EncodeError, match=f"but got {bad}"):
            drv.preview_command([bad])


def test_rounds_to_the_nearest_raw_value() -> None:
    # C610, gear 1, kp 0.1: 0.996 rad/s -> 0.0996 A -> 99.6 raw: 100 (99 if truncated).
    drv = DjiDriver([motor(1, esc="c610", gear=1.0), motor(2, esc="c610", gear=1.0)])
    assert currents_in(drv.preview_command([0.996, -0.996])) == {1: 100, 2: -100, 3: 0, 4: 0}


def test_c610_saturates_at_its_own_full_scale() -> None:
    drv = DjiDriver([motor(3, esc="c610", gear=1.0), motor(4, gear=1.0)])
    cur = currents_in(drv.preview_command([500.0, -500.0]))
    assert (cur[3], cur[4]) == (10000, -16384)
    assert C610.raw_to_amps(10000) == 10.0
    limited = DjiDriver([motor(3, esc="c610", gear=1.0, max_current_a=2.5)])
    assert currents_in(limited.preview_command([500.0]))[3] == 2500


def test_invert_flips_current_and_feedback() -> None:
    drv = DjiDriver([motor(1, gear=1.0, invert=True)])
    assert currents_in(drv.preview_command([10.0]))[1] == -C620.amps_to_raw(1.0)
    drv.on_frame(feedback_frame(1, 100, rpm=60, t=0.0))
    drv.on_frame(feedback_frame(1, 200, rpm=60, t=0.001))
    fb = drv.feedback(0)
    assert fb is not None
    assert fb.position_rad == pytest.approx(-100 * TWO_PI / 8192)
    assert fb.velocity_rad_s == pytest.approx(-TWO_PI)


@settings(max_examples=50)
@given(
    st.lists(st.floats(-50.0, 50.0), min_size=3, max_size=3),
    st.lists(st.integers(0, 8191), min_size=3, max_size=3),
)
def test_never_sends_0x700(speeds: list[float], angles: list[int]) -> None:
    drv = DjiDriver([motor(1), motor(4), motor(7)])
    frames = drv.enable(0.0) + drv.preview_command(speeds)
    for k, angle in enumerate(angles):
        drv.on_frame(feedback_frame((1, 4, 7)[k], angle, t=0.0))
    frames += drv.command(speeds, 0.0) + drv.command(speeds, 0.001) + drv.poll(0.001)
    frames += drv.disable(0.002)
    ids = {f.arbitration_id for f in frames}
    assert DjiFrameId.QUICK_ID_SET not in ids
    assert ids <= {0x200, 0x1FF}


# ===================================================================== driver: frames in


def test_on_frame_counts_malformed_and_ignores_others() -> None:
    drv = DjiDriver([motor(1), motor(2)])
    assert not drv.on_frame(Frame(0x069, bytes(8)))
    assert not drv.on_frame(Frame(0x203, bytes(8)))  # ESC 3 is not ours (e.g. a GM6020)
    assert not drv.on_frame(Frame(0x200, bytes(8)))
    assert drv.on_frame(Frame(0x201, bytes(7)))
    assert not drv.on_frame(Frame(0x202, bytes(8), is_extended_id=True))  # another device's
    assert drv.on_frame(Frame(0x202, is_remote_frame=True, dlc=8))
    assert drv.on_frame(Frame(0x201, bytes.fromhex("FFFF000000000000")))
    assert drv.rejected == {"malformed feedback": 3}
    assert drv.last_rejection["malformed feedback"].startswith("Expected")
    assert drv.feedback(0) is None and drv.feedback(1) is None


def test_claims_filters_and_names() -> None:
    drv = DjiDriver([motor(6), motor(2)])
    claims = drv.claims()
    assert claims == (
        FrameClaim.exact(0x202, False, 1),
        FrameClaim.exact(0x206, False, 0),
        FrameClaim.exact(0x200, False, None, receive=False),
        FrameClaim.exact(0x1FF, False, None, receive=False),
    )
    filters = drv.receive_filters()
    assert [(f.can_id, f.extended) for f in filters] == [(0x202, False), (0x206, False)]
    assert drv.message_name(0x206, False) == "FEEDBACK_ESC_6"
    assert drv.message_name(0x1FF, False) == "COMMAND_ESC_5_8"
    assert drv.message_name(0x206, True) is None
    for ident in range(0x1F0, 0x210):  # it takes exactly the frames it claims
        for ext in (False, True):
            claimed = any(c.receive and c.matches(ident, ext) for c in claims)
            assert drv.on_frame(Frame(ident, bytes(8), ext)) is claimed, hex(ident)


def test_the_driver_imports_no_simulator() -> None:
    code = (
        "import sys, drivers.dji; "
        "print([m for m in sys.modules if m == 'drivers.dji.sim' or m.startswith('gateway.sim')])"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, check=True
    )
    assert out.stdout.strip() == "[]"


@settings(max_examples=50)
@given(st.integers(0, 8191), st.lists(st.integers(-4095, 4095), min_size=1, max_size=200))
def test_driver_position_unwraps(start: int, steps: list[int]) -> None:
    gear = M2006_GEAR_RATIO
    drv = DjiDriver([motor(2, esc="c610", gear=gear)])
    drv.on_frame(feedback_frame(2, start, temp=0))
    total = 0
    for k, step in enumerate(steps, 1):
        total += step
        drv.on_frame(feedback_frame(2, (start + total) % 8192, temp=0, t=k * 1e-3))
    fb = drv.feedback(0)
    assert fb is not None
    assert fb.position_rad == pytest.approx(total * TWO_PI / 8192 / gear, abs=1e-12)


# ===================================================================== driver: states

_HOT, _WARM, _COOL = 81, int(80 - TEMP_HYSTERESIS_C) + 1, int(80 - TEMP_HYSTERESIS_C)


def _event(drv: DjiDriver, event: str, t: float) -> None:
    if event == "enable":
        drv.enable(t)
    elif event == "disable":
        drv.disable(t)
    elif event == "silence":
        pass  # time goes on without feedback
    else:
        temp = {"feedback": 35, "hot": _HOT, "warm": _WARM, "cool": _COOL}[event]
        drv.on_frame(feedback_frame(1, 0, temp=temp, t=t))


_SETUP: dict[DriveState, tuple[str, ...]] = {
    DriveState.OFFLINE: (),
    DriveState.DISABLED: ("feedback",),
    DriveState.ENABLED: ("feedback", "enable"),
    DriveState.FAULT: ("feedback", "enable", "hot"),
}


@pytest.mark.parametrize(
    ("start", "event", "end"),
    [
        (DriveState.OFFLINE, "feedback", DriveState.DISABLED),
        (DriveState.OFFLINE, "enable", DriveState.OFFLINE),
        (DriveState.OFFLINE, "hot", DriveState.FAULT),
        (DriveState.DISABLED, "enable", DriveState.ENABLED),
        (DriveState.DISABLED, "silence", DriveState.OFFLINE),
        (DriveState.DISABLED, "hot", DriveState.FAULT),
        (DriveState.ENABLED, "disable", DriveState.DISABLED),
        (DriveState.ENABLED, "feedback", DriveState.ENABLED),
        (DriveState.ENABLED, "silence", DriveState.OFFLINE),
        (DriveState.ENABLED, "hot", DriveState.FAULT),
        (DriveState.FAULT, "warm", DriveState.FAULT),  # hysteresis
        (DriveState.FAULT, "cool", DriveState.DISABLED),  # cleared, but stays disarmed
        (DriveState.FAULT, "enable", DriveState.FAULT),  # cannot arm while hot
        (DriveState.FAULT, "disable", DriveState.FAULT),
        (DriveState.FAULT, "silence", DriveState.OFFLINE),
    ],
)
def test_state_transitions(start: DriveState, event: str, end: DriveState) -> None:
    drv = DjiDriver([motor(1)])
    t = 0.0
    for step in _SETUP[start]:
        t += 0.001
        _event(drv, step, t)
    assert drv.state(0, t) is start
    t += 0.2 if event == "silence" else 0.001
    _event(drv, event, t)
    assert drv.state(0, t) is end
    current = currents_in(drv.command([5.0], t))[1]
    assert (current != 0) == (end is DriveState.ENABLED)


def test_current_only_when_the_base_says_enabled() -> None:
    """The command loop's ENABLED test agrees with MotorDriver.state, whatever set the fault
    (here a protection fault of the base, while armed)."""
    drv = DjiDriver([motor(1), motor(2)])
    for esc in (1, 2):
        drv.on_frame(feedback_frame(esc, 0, t=0.0))
    drv.enable(0.0)
    drv.protection_fault(0, "test")  # gateway.controller_watchdog: required -> FAULT
    assert drv.is_armed(0) and drv.state(0, 0.001) is DriveState.FAULT
    assert drv.state(1, 0.001) is DriveState.ENABLED
    cur = currents_in(drv.command([5.0, 5.0], 0.001))
    assert cur[1] == 0 and cur[2] != 0
    assert drv.integrals_a[0] == 0.0


def test_fault_status_and_recovery_needs_enable() -> None:
    drv = DjiDriver([motor(1)])
    drv.on_frame(feedback_frame(1, 0, t=0.0))
    drv.enable(0.0)
    drv.on_frame(feedback_frame(1, 0, temp=_HOT, t=0.001))
    (status,) = drv.status(0.001)
    assert status.state is DriveState.FAULT
    assert DriveFault.OVER_TEMPERATURE in status.faults
    assert "81 degC above max_temp_c 80 (host-side)" in status.detail
    drv.on_frame(feedback_frame(1, 0, temp=_COOL, t=0.002))
    assert drv.status(0.002)[0].faults == DriveFault.NONE
    assert drv.state(0, 0.002) is DriveState.DISABLED
    drv.enable(0.002)
    assert drv.state(0, 0.002) is DriveState.ENABLED


def test_c610_ignores_temperature_byte() -> None:
    drv = DjiDriver([motor(1, esc="c610")])
    drv.on_frame(feedback_frame(1, 0, temp=200))
    assert drv.state(0, 0.0) is DriveState.DISABLED


# ===================================================================== simulator alone


def test_sim_quantises_and_reports() -> None:
    sim = DjiSimulator(motor(3), initial_position_rad=-TWO_PI / 8192 * 0.5)
    (frame,) = sim.tick(0.0)
    fb = decode_feedback(frame)
    assert fb == DjiFeedback(3, 8191, 0, 0, 35)  # floor of -0.5 count wraps to 8191
    assert sim.tick(0.0005) == []  # next feedback due at 1 ms
    assert len(sim.tick(0.001)) == 1
    sim.handle(Frame(0x700, bytes(8)), 0.001)
    sim.handle(Frame(0x200, bytes(4)), 0.001)
    sim.handle(Frame(0x200, COMMAND_STRUCT.pack(0, 0, 20000, 0)), 0.001)
    assert (sim.id_set_requests, sim.malformed, sim.command_raw) == (1, 1, 16384)
    c610 = DjiSimulator(motor(1, esc="c610"), temperature_c=50)
    assert c610.measure().temperature_c == 0


def test_sim_physics_exact_and_steady_state() -> None:
    a, b = DjiMotorModel(current_a=2.0, armed=True), DjiMotorModel(current_a=2.0, armed=True)
    a.step(0.01)
    b.step(0.005)
    b.step(0.005)
    assert a.velocity_rad_s == pytest.approx(b.velocity_rad_s)
    assert a.position_rad == pytest.approx(b.position_rad)
    a.step(100.0)
    assert a.velocity_rad_s == pytest.approx(a.torque_constant_nm_a * 2.0 / a.damping_nm_s_rad)
    with pytest.raises(ConfigError, match="inertia_kg_m2"):
        DjiMotorModel(inertia_kg_m2=0.0)


@pytest.mark.parametrize(("timeout", "held"), [(None, True), (0.1, False)])
def test_sim_command_timeout(timeout: float | None, held: bool) -> None:
    sim = DjiSimulator(motor(1), command_timeout_s=timeout)
    sim.handle(Frame(0x200, COMMAND_STRUCT.pack(1000, 0, 0, 0)), 0.0)
    for k in range(1, 201):
        sim.tick(k * 1e-3)
    assert (sim.command_raw == 1000) == held


def test_simulator_for() -> None:
    for find in (drivers.dji.sim.simulator_for, simulator_for):
        sim = find(motor(4, esc="c610"))
        assert isinstance(sim, DjiSimulator)
        assert sim.esc is C610 and sim.esc_id == 4
        assert sim.command_timeout_s is None


# ===================================================================== on the virtual bus


class Rig:
    """Driver + simulators on a virtual bus; simulators at 1 kHz, the driver every
    ``period_ms``."""

    def __init__(self, drv: DjiDriver, gw: can.BusABC, ctl: SimulatedControllers) -> None:
        self.drv, self.gw, self.ctl, self.ms = drv, gw, ctl, 0

    @property
    def t(self) -> float:
        return self.ms * 0.001

    def run(
        self,
        seconds: float,
        setpoints: Sequence[float],
        period_ms: int = 1,
        probe: DjiSimulator | None = None,
    ) -> list[float]:
        """Run; return ``probe.steer_rad`` every ms (nothing without a probe)."""
        trace = []
        for _ in range(round(seconds * 1000)):
            self.ms += 1
            self.ctl.step(self.t)
            for f in drain(self.gw):
                self.drv.on_frame(f.stamped(self.t))
            if self.ms % period_ms == 0:
                send_frames(self.gw, self.drv.poll(self.t) + self.drv.command(setpoints, self.t))
            if probe is not None:
                trace.append(probe.steer_rad)
        return trace


def _rig(
    channel: str, motors: list[MotorConfig], sims: list[DjiSimulator], test: Callable[[Rig], None]
) -> None:
    drv = DjiDriver(motors)
    gw = can.Bus(interface="virtual", channel=channel)
    try:
        with SimulatedControllers(sims, channel) as ctl:
            test(Rig(drv, gw, ctl))
    finally:
        gw.shutdown()
    assert all(s.id_set_requests == 0 for s in sims)


@pytest.mark.parametrize("esc", ["c620", "c610"])
def test_pi_converges_on_bus(channel: str, esc: str) -> None:
    motors = [motor(1, esc=esc), motor(6, esc=esc, invert=True)]
    sims = [DjiSimulator(m) for m in motors]

    def check(rig: Rig) -> None:
        rig.drv.enable(rig.t)
        rig.run(1.0, [15.0, 8.0])
        for i, (sim, target) in enumerate(zip(sims, (15.0, 8.0), strict=True)):
            assert sim.wheel_velocity_rad_s == pytest.approx(target, rel=0.01)
            fb = rig.drv.feedback(i)
            assert fb is not None
            assert fb.velocity_rad_s == pytest.approx(target, rel=0.02)
        assert sims[1].command_raw < 0 < sims[0].command_raw  # inverted motor turns backwards
        before = sims[0].wheel_velocity_rad_s
        send_frames(rig.gw, rig.drv.disable(rig.t))
        rig.run(0.5, [15.0, 8.0])  # disarmed: zero current, the wheels coast down
        assert all(s.command_raw == 0 for s in sims)
        assert 0.0 < sims[0].wheel_velocity_rad_s < 0.98 * before

    _rig(channel, motors, sims, check)


@pytest.mark.parametrize("drop", [False, True])
def test_position_matches_ground_truth_across_wraps(channel: str, drop: bool) -> None:
    m = motor(2)
    start = (8100 + 0.5) * TWO_PI / 8192  # just below the 13-bit wrap
    sim = DjiSimulator(m, initial_position_rad=start)
    if drop:
        sim.inject(SimFault.DROP)
    one_count = TWO_PI / 8192 / m.gear_ratio

    def check(rig: Rig) -> None:
        rig.run(0.001, [0.0])
        truth0 = sim.wheel_position_rad
        rig.drv.enable(rig.t)
        for speed in (10.0, -25.0, 4.0):  # many rotor turns forwards, then backwards
            rig.run(0.7, [speed])
            fb = rig.drv.feedback(0)
            assert fb is not None
            last_frame_truth = sim.wheel_position_rad
            if drop:  # the last frame may be the one before
                assert abs(fb.position_rad - (last_frame_truth - truth0)) < 2.0 * one_count + abs(
                    sim.wheel_velocity_rad_s * 0.001
                )
            else:
                assert abs(fb.position_rad - (last_frame_truth - truth0)) < one_count
        assert abs(sim.model.position_rad - start) > 20 * TWO_PI

    _rig(channel, [m], [sim], check)


def test_silence_goes_offline_with_zero_current(channel: str) -> None:
    m = motor(1)
    sim = DjiSimulator(m)

    def check(rig: Rig) -> None:
        rig.drv.enable(rig.t)
        rig.run(0.5, [10.0])
        assert sim.command_raw != 0
        sim.inject(SimFault.SILENT)
        rig.run(0.15, [10.0])
        assert rig.drv.state(0, rig.t) is DriveState.OFFLINE
        assert rig.drv.currents_a == (0.0,)
        assert rig.drv.integrals_a == (0.0,)  # integrator reset while offline
        sent = currents_in(rig.drv.command([10.0], rig.t))
        assert sent[1] == 0  # zero current goes out while offline
        sim.clear(SimFault.SILENT)
        rig.run(1.0, [10.0])
        assert rig.drv.state(0, rig.t) is DriveState.ENABLED
        assert sim.wheel_velocity_rad_s == pytest.approx(10.0, rel=0.01)

    _rig(channel, [m], [sim], check)


def test_over_temperature_fault_and_recover(channel: str) -> None:
    m = motor(3)
    sim = DjiSimulator(m)

    def check(rig: Rig) -> None:
        rig.drv.enable(rig.t)
        rig.run(0.5, [10.0])
        sim.inject(SimFault.FAULT)
        rig.run(0.05, [10.0])
        (status,) = rig.drv.status(rig.t)
        assert status.state is DriveState.FAULT
        assert status.faults == DriveFault.OVER_TEMPERATURE
        assert "110 degC" in status.detail
        assert sim.command_raw == 0 and rig.drv.currents_a == (0.0,)
        sim.clear(SimFault.FAULT)
        rig.run(0.05, [10.0])
        assert rig.drv.state(0, rig.t) is DriveState.DISABLED
        rig.drv.enable(rig.t)
        rig.run(1.0, [10.0])
        assert rig.drv.state(0, rig.t) is DriveState.ENABLED
        assert sim.wheel_velocity_rad_s == pytest.approx(10.0, rel=0.01)

    _rig(channel, [m], [sim], check)
