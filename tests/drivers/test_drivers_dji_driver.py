"""Tests of the DJI C620 / C610 driver: configuration, commands, frames in, and its states."""

from __future__ import annotations

import math
import subprocess
import sys

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

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
)
from drivers.dji.codec import (
    encode_feedback,
)
from drivers.dji.protection import ACK_KEY
from gateway.core.errors import ConfigError, EncodeError
from gateway.core.types import DriveFault, DriveState, Frame, MotorConfig
from gateway.drive.claims import FrameClaim
from gateway.drive.registry import get_driver_class
from tests.conftest import REPO
from tests.drivers.dji_helpers import TWO_PI, currents_in, motor


def feedback_frame(
    esc_id: int, angle: int, rpm: int = 0, current: int = 0, temp: int = 35, t: float = 0.0
) -> Frame:
    frame = encode_feedback(DjiFeedback(esc_id, angle, rpm, current, temp))
    return frame.stamped(t)


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
