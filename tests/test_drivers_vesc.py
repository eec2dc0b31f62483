"""Tests of the VESC codec, driver and simulator (drivers/vesc).

Golden vectors: section 2 "Worked examples (VESC ID 23 = 0x17)" of
/work/shared/specs/can-protocols.md, built from vedderb/bldc ``comm/comm_can.c`` at b9d287b3;
SET_CURRENT 51 A matches the example in the firmware's ``documentation/comm_can.md``.
"""

from __future__ import annotations

import contextlib
import dataclasses
import logging
import math
import re
from types import MappingProxyType
from typing import TYPE_CHECKING

import can
import pytest
from hypothesis import given
from hypothesis import strategies as st

from drivers.vesc import SimMode, VescDriver, VescSimulator
from drivers.vesc.codec import (
    COMMANDS,
    CanPacketId,
    HwType,
    VescCodec,
    VescCommand,
    VescPing,
    VescPong,
    VescStatus,
    VescStatus5,
    decode,
    decode_command,
    make_command,
    make_ping,
    make_pong,
    make_set_current,
    make_set_current_brake,
    make_set_rpm,
    make_status,
    make_status5,
    wrap_int32,
)
from gateway.bus import drain, send_frames
from gateway.errors import ConfigError, DecodeError, EncodeError
from gateway.registry import get_driver_class
from gateway.sim import SimFault
from gateway.simbus import SimulatedControllers
from gateway.types import DriveState, Frame, MotorConfig

if TYPE_CHECKING:
    from collections.abc import Callable, Iterator, Sequence

I32 = st.integers(-(2**31), 2**31 - 1)
PP = 7


def ext(eid: int, hexdata: str) -> Frame:
    return Frame(eid, bytes.fromhex(hexdata), is_extended_id=True)


def motor(
    node_id: int = 23,
    *,
    wheel: str = "left",
    gear_ratio: float = 1.0,
    invert: bool = False,
    max_rpm: float = 3000.0,
    **options: object,
) -> MotorConfig:
    opts: dict[str, object] = {"pole_pairs": PP, **options}
    return MotorConfig(
        wheel=wheel,
        driver="vesc",
        node_id=node_id,
        gear_ratio=gear_ratio,
        invert=invert,
        max_rpm=max_rpm,
        options=MappingProxyType(opts),
    )


def rpm_to_rad_s(rpm: float) -> float:
    return rpm * 2.0 * math.pi / 60.0


# ============================================================================ codec: golden


@pytest.mark.parametrize(
    ("frame", "cansend"),
    [
        (make_set_rpm(23, 700), "00000317#000002BC"),  # 100 rpm at 7 pole pairs
        (make_set_rpm(23, -700), "00000317#FFFFFD44"),
        (make_set_current(23, 51.0), "00000117#0000C738"),  # comm_can.md example
        (make_set_current_brake(23, 10.0), "00000217#00002710"),
        (make_ping(23, 1), "00001117#01"),
        (make_status(23, 700, 12.3, 0.5), "00000917#000002BC007B01F4"),
        (make_status5(23, 4200, 24.5), "00001B17#0000106800F50000"),  # 100 revs at 7 pp
    ],
)
def test_golden_frames(frame: Frame, cansend: str) -> None:
    assert frame.is_extended_id
    assert frame.to_cansend() == cansend


def test_golden_decode() -> None:
    assert decode(ext(0x917, "000002BC007B01F4")) == VescStatus(23, 700, 12.3, 0.5)
    assert decode(ext(0x1B17, "0000106800F50000")) == VescStatus5(23, 4200, 24.5)
    assert decode_command(ext(0x317, "FFFFFD44")) == VescCommand(23, CanPacketId.SET_RPM, -700)
    assert decode_command(ext(0x117, "0000C738")) == VescCommand(23, CanPacketId.SET_CURRENT, 51.0)
    assert decode_command(ext(0x1117, "01")) == VescPing(23, 1)


def test_pong_goes_to_the_pinger() -> None:
    # decode_msg(): PONG to (18 << 8) | data[0] of the PING, payload [responder, HW_TYPE].
    assert make_pong(1, 23) == ext(0x1201, "1700")
    assert decode(ext(0x1201, "1700")) == VescPong(23, 1, HwType.VESC)
    assert decode(ext(0x1201, "17")) == VescPong(23, 1, HwType.VESC)  # 1 byte: HW_TYPE_VESC
    assert decode(ext(0x1201, "1702")) == VescPong(23, 1, HwType.CUSTOM_MODULE)


def test_codec_encodes_set_rpm_in_mapping_order() -> None:
    codec = VescCodec()
    assert codec.encode_command({24: -700, 23: 700}) == (
        ext(0x318, "FFFFFD44"),
        ext(0x317, "000002BC"),
    )
    assert codec.decode(ext(0x917, "000002BC007B01F4")) == VescStatus(23, 700, 12.3, 0.5)


def test_wrap_int32() -> None:
    assert wrap_int32(2**31 - 1) == 2**31 - 1
    assert wrap_int32(2**31) == -(2**31)
    assert wrap_int32(-(2**31) - 1) == 2**31 - 1
    assert wrap_int32(-(2**31) - (2**31 - 1)) == 1  # 0x80000000 - 0x7FFFFFFF = +1 step


# ============================================================================ codec: round trips


@given(
    packet=st.sampled_from(sorted(COMMANDS)),
    node_id=st.integers(0, 255),
    fraction=st.floats(-1.0, 1.0),
)
def test_command_round_trip(packet: CanPacketId, node_id: int, fraction: float) -> None:
    field = COMMANDS[packet]
    value = fraction * (field.maximum if fraction > 0 else -field.minimum)
    got = decode_command(make_command(packet, node_id, value))
    assert isinstance(got, VescCommand)
    assert (got.node_id, got.packet) == (node_id, packet)
    assert abs(got.value - value) <= 0.5 / field.scale + abs(value) * 1e-15


@given(
    node_id=st.integers(0, 255),
    erpm=I32,
    current_a=st.floats(-3276.8, 3276.7),
    duty=st.floats(-32.768, 32.767),
)
def test_status_round_trip(node_id: int, erpm: int, current_a: float, duty: float) -> None:
    got = decode(make_status(node_id, erpm, current_a, duty))
    assert isinstance(got, VescStatus)
    assert (got.node_id, got.erpm) == (node_id, erpm)
    assert abs(got.current_a - current_a) <= 0.05 + 1e-9
    assert abs(got.duty - duty) <= 0.0005 + 1e-9


@given(node_id=st.integers(0, 255), tacho=I32, v_in=st.floats(-3276.8, 3276.7))
def test_status5_round_trip(node_id: int, tacho: int, v_in: float) -> None:
    got = decode(make_status5(node_id, tacho, v_in))
    assert isinstance(got, VescStatus5)
    assert (got.node_id, got.tachometer) == (node_id, tacho)
    assert abs(got.v_in_v - v_in) <= 0.05 + 1e-9


@given(to_id=st.integers(0, 255), node_id=st.integers(0, 255), hw=st.sampled_from(HwType))
def test_ping_pong_round_trip(to_id: int, node_id: int, hw: HwType) -> None:
    assert decode_command(make_ping(node_id, to_id)) == VescPing(node_id, to_id)
    assert decode(make_pong(to_id, node_id, hw)) == VescPong(node_id, to_id, hw)


# ============================================================================ codec: errors


def test_encode_error_message_names_entity_range_and_value() -> None:
    with pytest.raises(EncodeError) as err:
        make_set_rpm(23, math.nan)
    assert str(err.value) == (
        "Expected speed for VESC 23 between -2147483648 and 2147483647 eRPM, but got nan."
    )


@pytest.mark.parametrize(
    "call",
    [
        lambda: make_set_rpm(23, math.inf),
        lambda: make_set_rpm(23, -math.inf),
        lambda: make_set_rpm(23, 2.0**31),
        lambda: make_set_rpm(23, -(2.0**31) - 1),
        lambda: make_set_current(23, 2147484.0),
        lambda: make_set_current_brake(23, math.nan),
        lambda: make_set_rpm(256, 0.0),
        lambda: make_set_rpm(-1, 0.0),
        lambda: make_command(CanPacketId.SET_DUTY, 23, 0.5),  # not in the field table
        lambda: make_ping(23, 256),
        lambda: make_status(23, 0, 3300.0, 0.0),
        lambda: make_status(23, 2**31, 0.0, 0.0),
        lambda: make_status5(23, 0, math.nan),
        lambda: make_pong(300, 23),
    ],
)
def test_encode_rejects(call: Callable[[], Frame]) -> None:
    with pytest.raises(EncodeError):
        call()


@pytest.mark.parametrize(
    "frame",
    [
        ext(0x917, "000002BC007B01"),  # STATUS, DLC 7
        ext(0x917, ""),
        ext(0x1B17, "0000106800F5000000"),  # STATUS_5, DLC 9
        Frame(0x917, is_extended_id=True, is_remote_frame=True, dlc=8),  # no RTR in VESC
        Frame(0x1B17, is_extended_id=True, is_remote_frame=True, dlc=8),
        ext(0x1201, ""),  # PONG without payload
        ext(0x1201, "170000"),
    ],
)
def test_decode_rejects_malformed(frame: Frame) -> None:
    with pytest.raises(DecodeError):
        decode(frame)


@pytest.mark.parametrize(
    "frame",
    [
        ext(0x117, "00000000C738"),  # the inconsistent 6-byte SET_CURRENT form
        ext(0x317, "02BC"),
        Frame(0x317, is_extended_id=True, is_remote_frame=True, dlc=4),
        ext(0x1117, ""),
    ],
)
def test_decode_command_rejects_malformed(frame: Frame) -> None:
    with pytest.raises(DecodeError):
        decode_command(frame)


@pytest.mark.parametrize(
    ("parse", "frame"),
    [
        (decode, Frame(0x917, bytes(8))),  # standard IDs are never VESC frames
        (decode, ext(0x10917, "000002BC007B01F4")),  # bits above 15: packet 0x109 unknown
        (decode, ext(0x1017, "0000000000000000")),  # STATUS_4: not decoded
        (decode, ext(0x317, "000002BC")),  # a command, host to device
        (decode_command, Frame(0x317, bytes.fromhex("000002BC"))),
        (decode_command, ext(0x917, "000002BC007B01F4")),  # status, device to host
        (decode_command, ext(0x017, "00007A12")),  # SET_DUTY: not spoken here
    ],
)
def test_decode_ignores_foreign_frames(parse: Callable[[Frame], object], frame: Frame) -> None:
    assert parse(frame) is None


# ============================================================================ driver: config


def test_registry_entry() -> None:
    assert get_driver_class("vesc") is VescDriver


def test_validate_options_fills_defaults() -> None:
    got = VescDriver.validate_options({"pole_pairs": 7}, "robot.yaml: wheels[0].motor")
    defaults = {"command_period_s": 0.02, "timeout_s": 0.5, "liveness_s": 0.25}
    assert got == {"pole_pairs": 7, **defaults}
    got = VescDriver.validate_options({"pole_pairs": 7, "command_period_s": 0.249}, "w")
    assert got["command_period_s"] == 0.249  # just below timeout_s / 2


@pytest.mark.parametrize(
    ("raw", "message"),
    [
        ({}, "w.pole_pairs: required key is missing"),
        ({"pole_pairs": 0}, "w.pole_pairs: expected at least 1"),
        ({"pole_pairs": 7.0}, "w.pole_pairs: expected int"),
        ({"pole_pairs": 7, "poles": 14}, "w.poles: unknown key"),
        ({"pole_pairs": 7, "timeout_s": 0}, "w.timeout_s: expected at least"),
        (
            {"pole_pairs": 7, "command_period_s": 0.25},  # exactly timeout_s / 2
            "w.command_period_s: expected less than timeout_s / 2 = 0.25 s",
        ),
        ({"pole_pairs": 7, "timeout_s": 1.0, "command_period_s": 0.6}, "timeout_s / 2 = 0.5"),
    ],
)
def test_validate_options_rejects(raw: dict[str, object], message: str) -> None:
    with pytest.raises(ConfigError, match=re.escape(message)):
        VescDriver.validate_options(raw, "w")


@pytest.mark.parametrize(
    "motors",
    [
        [motor(255)],  # broadcast
        [motor(-1)],
        [motor(23), motor(23, wheel="right")],
        [motor(23, command_period_s=0.3)],
        [MotorConfig(wheel="left", driver="vesc", node_id=23)],  # no pole_pairs
    ],
)
def test_constructor_rejects(motors: list[MotorConfig]) -> None:
    with pytest.raises(ConfigError):
        VescDriver(motors)


# ============================================================================ driver: units


def test_command_converts_wheel_speed_to_erpm() -> None:
    # 100 rpm at the motor, 7 pole pairs -> 700 eRPM (spec worked example).
    drv = VescDriver([motor(23), motor(24, wheel="right", gear_ratio=2.0, invert=True)])
    drv.enable(0.0)
    speeds = [rpm_to_rad_s(100.0), rpm_to_rad_s(50.0)]
    assert drv.command(speeds, 0.01) == [ext(0x317, "000002BC"), ext(0x318, "FFFFFD44")]
    # round(), not int(): 0.6 eRPM is 1, -0.6 is -1.
    tiny = rpm_to_rad_s(0.6 / PP)
    assert drv.command([tiny, 0.0], 0.02)[0] == make_set_rpm(23, 1)
    assert drv.command([-tiny, 0.0], 0.03)[0] == make_set_rpm(23, -1)


def test_command_limits() -> None:
    drv = VescDriver([motor(23, max_rpm=3000.0)])
    with pytest.raises(EncodeError) as err:
        drv.command([400.0], 0.0)
    assert str(err.value) == (
        'Expected velocity for node 23 ("left") between -314.2 and 314.2 rad/s, but got 400.0.'
    )
    for bad in (math.nan, math.inf, -400.0):
        with pytest.raises(EncodeError):
            drv.command([bad], 0.0)  # checked even while disabled
    with pytest.raises(EncodeError, match="Expected 1 wheel speeds"):
        drv.command([1.0, 2.0], 0.0)
    assert drv.command([rpm_to_rad_s(3000.0)], 0.0) == []  # the limit itself is fine


def test_enable_disable_frames_and_keepalive() -> None:
    drv = VescDriver([motor(23), motor(24, wheel="right", command_period_s=0.05)])
    assert drv.keepalive_period_s == 0.02
    assert drv.command([1.0, 1.0], 0.0) == []  # disabled: nothing goes out
    assert drv.poll(0.0) == []
    assert drv.enable(1.0) == [make_set_rpm(23, 0), make_set_rpm(24, 0)]
    sent = drv.command([rpm_to_rad_s(100.0), 0.0], 1.0)
    assert sent == [make_set_rpm(23, 700), make_set_rpm(24, 0)]
    assert drv.poll(1.019) == []
    assert drv.poll(1.020) == [make_set_rpm(23, 700)]  # per motor period
    assert drv.poll(1.039) == []
    assert drv.poll(1.050) == [make_set_rpm(23, 700), make_set_rpm(24, 0)]
    # SET_CURRENT 0 releases the motor; then the stream stops.
    assert drv.disable(1.06) == [ext(0x117, "00000000"), ext(0x118, "00000000")]
    assert drv.poll(2.0) == []


def status_pair(node_id: int, erpm: int, tacho: int, t: float) -> list[Frame]:
    return [
        make_status(node_id, erpm, 1.5, 0.1).stamped(t),
        make_status5(node_id, tacho, 24.0).stamped(t),
    ]


def feed(drv: VescDriver, frames: Sequence[Frame]) -> list[bool]:
    return [drv.on_frame(f) for f in frames]


def test_feedback_units_and_sign() -> None:
    drv = VescDriver([motor(23, gear_ratio=2.0, invert=True)])
    assert feed(drv, status_pair(23, 700, 1000, 0.5)) == [True, True]
    fb = drv.feedback(0)
    assert fb is not None
    assert fb.velocity_rad_s == pytest.approx(-rpm_to_rad_s(100.0) / 2.0)
    assert fb.position_rad == 0.0  # counted from the first sample
    assert fb.timestamp_s == 0.5
    feed(drv, status_pair(23, 700, 1000 + 6 * PP * 10, 0.6))  # +10 motor turns
    fb = drv.feedback(0)
    assert fb is not None
    assert fb.position_rad == pytest.approx(-10 * 2 * math.pi / 2.0)
    status5 = drv.last_status5(0)
    status = drv.last_status(0)
    assert status5 is not None and status5.v_in_v == 24.0
    assert status is not None and status.current_a == 1.5


@pytest.mark.parametrize(
    ("first", "second", "steps"),
    [
        (0x7FFFFFFF, -0x80000000, 1),  # int32 0x7FFFFFFF -> 0x80000000 is +1 step
        (-0x80000000, 0x7FFFFFFF, -1),
        (0x7FFFFFF0, -0x7FFFFFF0, 32),
        (5, -5, -10),
    ],
)
def test_tachometer_unwraps_int32(first: int, second: int, steps: int) -> None:
    drv = VescDriver([motor(23)])
    feed(drv, status_pair(23, 0, first, 0.0))
    feed(drv, status_pair(23, 0, second, 0.02))
    fb = drv.feedback(0)
    assert fb is not None
    assert fb.position_rad == drv.wheel_rad_for(0, steps)
    assert fb.position_rad == pytest.approx(steps * 2 * math.pi / (6 * PP))


@given(start=I32, deltas=st.lists(st.integers(-(2**24), 2**24), max_size=40))
def test_tachometer_unwrap_is_exact(start: int, deltas: list[int]) -> None:
    drv = VescDriver([motor(23)])
    feed(drv, status_pair(23, 0, start, 0.0))
    tacho = start
    for k, d in enumerate(deltas):
        tacho = wrap_int32(tacho + d)
        feed(drv, status_pair(23, 0, tacho, 0.01 * (k + 1)))
    fb = drv.feedback(0)
    assert fb is not None
    assert fb.position_rad == drv.wheel_rad_for(0, sum(deltas))


def test_on_frame_claims_only_own_frames_and_counts_malformed() -> None:
    drv = VescDriver([motor(23)])
    assert drv.on_frame(ext(0x917, "000002BC007B01")) is True  # own, malformed
    assert "for STATUS of VESC 23, but got 7" in drv.last_rejection["malformed"]
    assert drv.on_frame(Frame(0x1B17, is_extended_id=True, is_remote_frame=True, dlc=8))
    assert sum(drv.rejected.values()) == 2
    assert drv.on_frame(ext(0x918, "000002BC007B01")) is False  # malformed, not ours
    assert drv.on_frame(ext(0x918, "000002BC007B01F4")) is False  # another VESC
    assert drv.on_frame(Frame(0x917, bytes(8))) is False  # standard ID
    assert drv.on_frame(ext(0x317, "000002BC")) is False  # a command
    assert drv.on_frame(ext(0x1017, bytes(8).hex())) is True  # STATUS_4: ours, unused
    assert drv.on_frame(ext(0x1201, "1700")) is True  # PONG from 23
    assert sum(drv.rejected.values()) == 2
    assert drv.feedback(0) is None


# ============================================================================ driver: state


@pytest.mark.parametrize(
    ("status_s", "status5_s", "enabled_at", "expected"),
    [  # times of the last STATUS, STATUS_5 and enable(); state asked at t = 1.0
        (None, None, None, DriveState.OFFLINE),  # nothing yet
        (0.9, None, None, DriveState.OFFLINE),  # STATUS only: no odometry
        (None, 0.9, 0.5, DriveState.OFFLINE),  # STATUS_5 only
        (0.9, 0.70, None, DriveState.OFFLINE),  # STATUS_5 stale (> 0.25 s)
        (0.70, 0.9, 0.5, DriveState.OFFLINE),  # STATUS stale
        (0.9, 0.9, None, DriveState.DISABLED),
        (0.9, 0.9, 0.95, DriveState.ENABLING),  # no status since enable
        (0.96, 0.9, 0.95, DriveState.ENABLING),  # one stream only since enable
        (0.96, 0.97, 0.95, DriveState.ENABLED),
        (0.95, 0.95, 0.95, DriveState.ENABLED),
    ],
)
def test_state_derivation(
    status_s: float | None, status5_s: float | None, enabled_at: float | None, expected: DriveState
) -> None:
    drv = VescDriver([motor(23)])
    if enabled_at is not None:
        drv.enable(enabled_at)
    if status_s is not None:
        drv.on_frame(make_status(23, 0, 0.0, 0.0).stamped(status_s))
    if status5_s is not None:
        drv.on_frame(make_status5(23, 0, 24.0).stamped(status5_s))
    assert drv.state(0, 1.0) == expected
    assert drv.status(1.0)[0].state == expected


def test_state_walk_through_every_reachable_state() -> None:
    drv = VescDriver([motor(23)])
    seen = [drv.state(0, 0.0)]
    feed(drv, status_pair(23, 0, 0, 0.1))
    seen.append(drv.state(0, 0.1))
    drv.enable(0.15)
    seen.append(drv.state(0, 0.15))
    feed(drv, status_pair(23, 0, 0, 0.2))
    seen.append(drv.state(0, 0.2))
    seen.append(drv.state(0, 0.46))  # silence
    feed(drv, status_pair(23, 0, 0, 0.5))
    seen.append(drv.state(0, 0.5))
    drv.disable(0.55)
    seen.append(drv.state(0, 0.55))
    names = [state.name for state in seen]
    assert names == "OFFLINE DISABLED ENABLING ENABLED OFFLINE ENABLED DISABLED".split()
    assert DriveState.FAULT not in seen  # no fault codes in VESC status frames


def test_missing_status_frames_log_a_hint_once(caplog: pytest.LogCaptureFixture) -> None:
    drv = VescDriver([motor(23)])
    drv.enable(0.0)
    with caplog.at_level(logging.WARNING, logger="drivers.vesc.driver"):
        drv.poll(0.5)
        assert not caplog.records
        drv.on_frame(make_status(23, 0, 0.0, 0.0).stamped(0.6))
        drv.poll(1.1)
        drv.poll(1.2)
    assert len(caplog.records) == 1
    assert "no STATUS_5 frames" in caplog.records[0].getMessage()
    assert "can_status_msgs_r1" in caplog.records[0].getMessage()


# ============================================================================ simulator alone


def mode_of(sim: VescSimulator) -> SimMode:
    """The simulator's mode (a call, so mypy does not narrow it between steps)."""
    return sim.mode


def sim_for(**kwargs: object) -> VescSimulator:
    return VescSimulator(motor(23), **kwargs)  # type: ignore[arg-type]


def test_sim_needs_pole_pairs() -> None:
    with pytest.raises(ConfigError, match="pole_pairs"):
        VescSimulator(MotorConfig(wheel="left", driver="vesc", node_id=23))
    assert isinstance(VescDriver.make_simulator(motor(23)), VescSimulator)


def test_sim_answers_ping() -> None:
    sim = sim_for()
    assert sim.handle(make_ping(23, 1), 0.0) == [ext(0x1201, "1700")]
    assert sim.handle(make_ping(255, 9), 0.0) == [ext(0x1209, "FF00")]  # firmware echoes 255
    assert sim.handle(make_ping(24, 1), 0.0) == []


def test_sim_status_rate_and_layout() -> None:
    sim = sim_for(status_rate_hz=50.0, initial_tacho=-5, v_in_v=36.0)
    frames = [f for k in range(1000) for f in sim.tick(k * 0.001)]
    decoded = [decode(f) for f in frames]
    assert sum(isinstance(d, VescStatus) for d in decoded) == 50
    assert sum(isinstance(d, VescStatus5) for d in decoded) == 50
    assert decoded[1] == VescStatus5(23, -5, 36.0)


def run_sim(sim: VescSimulator, start: float, stop: float, dt: float = 0.001) -> float:
    for k in range(round((stop - start) / dt)):
        sim.tick(start + (k + 1) * dt)
    return stop


def test_sim_releases_motor_after_its_timeout() -> None:
    sim = sim_for(timeout_s=0.5)
    sim.handle(make_set_rpm(23, 700), 0.0)
    assert mode_of(sim) == SimMode.SPEED
    run_sim(sim, 0.0, 0.5)
    assert sim.model.armed
    run_sim(sim, 0.5, 0.51)
    assert mode_of(sim) == SimMode.RELEASED
    assert not sim.model.armed


def test_sim_timeout_defaults_to_motor_option() -> None:
    assert VescSimulator(motor(23, timeout_s=1.0)).timeout_s == 1.0


@pytest.mark.parametrize(
    ("frame", "mode"),
    [
        (make_set_current(23, 0.0), SimMode.RELEASED),
        (make_set_current(23, 0.04), SimMode.RELEASED),  # below cc_min_current
        (make_set_current(23, 5.0), SimMode.CURRENT),
        (make_set_current_brake(23, 5.0), SimMode.BRAKE),
        (make_set_current_brake(23, 0.0), SimMode.RELEASED),
        (make_set_rpm(255, 700), SimMode.SPEED),  # broadcast
    ],
)
def test_sim_command_modes(frame: Frame, mode: SimMode) -> None:
    sim = sim_for()
    sim.handle(make_set_rpm(23, -350), 0.0)
    run_sim(sim, 0.0, 0.2)
    sim.handle(frame, 0.2)
    assert mode_of(sim) == mode
    assert sim.model.armed == (mode != SimMode.RELEASED)


def test_sim_current_mode_accelerates_and_reports_current() -> None:
    sim = sim_for()
    sim.tick(0.0)
    sim.handle(make_set_current(23, 4.0), 0.0)
    run_sim(sim, 0.0, 0.1)
    assert sim.model.velocity_rad_s == pytest.approx(4.0 * 50.0 * 0.1, rel=1e-6)
    status = [decode(f) for f in sim.tick(0.2)]
    assert any(isinstance(s, VescStatus) and s.current_a == 4.0 for s in status)


def test_sim_ignores_malformed_and_foreign_commands() -> None:
    sim = sim_for()
    assert sim.handle(ext(0x117, "00000000C738"), 0.0) == []
    assert sim.handle(ext(0x318, "000002BC"), 0.0) == []
    assert sim.rejected == 1
    assert mode_of(sim) == SimMode.RELEASED


def test_sim_fault_ignores_commands_then_clears_itself() -> None:
    sim = sim_for(fault_stop_s=0.5, timeout_s=1.0)
    sim.handle(make_set_rpm(23, 700), 0.0)
    run_sim(sim, 0.0, 0.1)
    sim.inject(SimFault.FAULT)
    assert mode_of(sim) == SimMode.RELEASED
    t = 0.1
    for _ in range(4):
        sim.handle(make_set_rpm(23, 700), t)
        assert mode_of(sim) == SimMode.RELEASED  # ignored
        t = run_sim(sim, t, t + 0.1)
    assert sim.faults & SimFault.FAULT
    t = run_sim(sim, t, t + 0.11)
    assert not sim.faults & SimFault.FAULT  # cleared itself after fault_stop_s
    assert mode_of(sim) == SimMode.RELEASED  # until the next command
    sim.handle(make_set_rpm(23, 700), t)
    assert mode_of(sim) == SimMode.SPEED


def test_sim_tachometer_counts_whole_60_degree_steps() -> None:
    sim = sim_for(initial_tacho=100)
    step = 2 * math.pi / (6 * PP)  # motor rad per step
    for fraction, tacho in [(0.99, 100), (1.0, 101), (2.5, 102), (-0.01, 99), (-1.5, 98)]:
        sim.model.position_rad = fraction * step
        assert sim.tachometer == tacho, fraction


def test_sim_tachometer_wraps() -> None:
    sim = sim_for(initial_tacho=2**31 - 3)
    assert sim.tachometer == 2**31 - 3
    sim.handle(make_set_rpm(23, 700), 0.0)
    run_sim(sim, 0.0, 0.1)
    assert sim.tachometer < 0  # wrapped through 0x80000000
    revs = sim.model.position_rad / (2 * math.pi)
    assert wrap_int32(sim.tachometer - (2**31 - 3)) == math.floor(revs * 6 * PP)


# ============================================================================ on the virtual bus


def step_rad(m: MotorConfig) -> float:
    """One tachometer step as wheel angle (rad)."""
    return 2 * math.pi / (6 * PP) / m.gear_ratio


@dataclasses.dataclass
class Rig:
    """A driver and simulators on a virtual bus, stepped in simulated time (no threads)."""

    gw: can.BusABC
    ctl: SimulatedControllers
    drv: VescDriver
    sims: list[VescSimulator]
    dt: float = 0.002
    step: int = 0

    @property
    def t(self) -> float:
        return self.step * self.dt

    def send(self, frames: list[Frame]) -> None:
        send_frames(self.gw, frames)

    def run(self, seconds: float, speeds: Sequence[float] | None, *, poll: bool = True) -> None:
        """Run ``seconds``; ``speeds=None`` skips command() (a loop that only polls)."""
        for _ in range(round(seconds / self.dt)):
            self.step += 1
            t = self.t
            self.ctl.step(t)
            for f in drain(self.gw):
                self.drv.on_frame(f.stamped(t))
            out = self.drv.poll(t) if poll else []
            if speeds is not None:
                out += self.drv.command(speeds, t)
            self.send(out)

    def states(self) -> list[DriveState]:
        return [self.drv.state(i, self.t) for i in range(len(self.sims))]

    def truth(self) -> list[float]:
        return [sim.wheel_position_rad for sim in self.sims]

    def velocities(self) -> list[float]:
        fbs = [self.drv.feedback(i) for i in range(len(self.sims))]
        return [math.nan if fb is None else fb.velocity_rad_s for fb in fbs]

    def odometry_error_steps(self, start: Sequence[float]) -> list[float]:
        """|driver position - ground-truth travel| per wheel, in tachometer steps."""
        out = []
        for i, (sim, m) in enumerate(zip(self.sims, self.drv.motors, strict=True)):
            fb = self.drv.feedback(i)
            err = math.inf if fb is None else fb.position_rad - (sim.wheel_position_rad - start[i])
            out.append(abs(err) / step_rad(m))
        return out


@contextlib.contextmanager
def rig(channel: str, motors: list[MotorConfig], sims: list[VescSimulator]) -> Iterator[Rig]:
    gw = can.Bus(interface="virtual", channel=channel)
    try:
        with SimulatedControllers(sims, channel) as ctl:
            yield Rig(gw, ctl, VescDriver(motors), sims)
    finally:
        gw.shutdown()


def two_wheels() -> tuple[list[MotorConfig], list[VescSimulator]]:
    left = motor(23, wheel="left")
    right = motor(24, wheel="right", gear_ratio=2.0, invert=True)
    # Both counters start next to the int32 wrap, on the side they will run towards.
    sims = [
        VescSimulator(left, initial_tacho=2**31 - 20),
        VescSimulator(right, initial_tacho=-(2**31) + 20),
    ]
    return [left, right], sims


def test_drive_and_odometry_across_the_wrap(channel: str) -> None:
    motors, sims = two_wheels()
    with rig(channel, motors, sims) as r:
        r.run(0.1, None)
        assert r.states() == [DriveState.DISABLED] * 2
        start = r.truth()
        r.send(r.drv.enable(r.t))
        assert r.states() == [DriveState.ENABLING] * 2
        r.run(1.0, [6.0, 6.0])
        assert r.states() == [DriveState.ENABLED] * 2
        assert r.velocities() == pytest.approx([6.0, 6.0], abs=0.01)
        assert [s.wheel_velocity_rad_s for s in sims] == pytest.approx([6.0, 6.0], abs=0.01)
        assert sims[0].tachometer < 0 < sims[1].tachometer  # both wrapped
        r.run(0.5, [0.0, 0.0])
        travel = [now - then for now, then in zip(r.truth(), start, strict=True)]
        assert travel == pytest.approx([6.0, 6.0], rel=0.05)
        assert max(r.odometry_error_steps(start)) <= 1.0


def test_lost_status5_stream_goes_offline_and_odometry_catches_up(channel: str) -> None:
    motors, sims = two_wheels()
    with rig(channel, motors, sims) as r:
        r.run(0.05, None)
        start = r.truth()
        r.send(r.drv.enable(r.t))
        r.run(0.2, [-4.0, 4.0])
        # DROP loses every second frame; the device sends STATUS then STATUS_5 each period,
        # so only STATUS gets through: position is stale and the driver must say so.
        sims[0].inject(SimFault.DROP)
        r.run(0.4, [-4.0, 4.0])
        assert r.states() == [DriveState.OFFLINE, DriveState.ENABLED]
        assert r.velocities() == pytest.approx([-4.0, 4.0], abs=0.01)  # STATUS still arrives
        sims[0].clear(SimFault.DROP)
        r.run(0.3, [0.0, 0.0])
        assert r.states() == [DriveState.ENABLED] * 2
        assert r.truth()[1] - start[1] == pytest.approx(4.0 * 0.6, rel=0.1)
        assert max(r.odometry_error_steps(start)) <= 1.0


def test_silence_goes_offline_and_recovers(channel: str) -> None:
    motors, sims = two_wheels()
    with rig(channel, motors, sims) as r:
        r.run(0.05, None)
        start = r.truth()
        r.send(r.drv.enable(r.t))
        r.run(0.3, [3.0, 3.0])
        sims[0].inject(SimFault.SILENT)
        r.run(0.2, [3.0, 3.0])
        assert r.states() == [DriveState.ENABLED] * 2  # within liveness_s
        r.run(0.1, [3.0, 3.0])
        assert r.states() == [DriveState.OFFLINE, DriveState.ENABLED]
        assert r.drv.status(r.t)[0].state == DriveState.OFFLINE
        r.run(0.3, [3.0, 3.0])
        # The silent device heard nothing either, so its own timeout released the motor.
        assert mode_of(sims[0]) == SimMode.RELEASED
        sims[0].clear(SimFault.SILENT)
        r.run(0.5, [3.0, 3.0])
        assert r.states() == [DriveState.ENABLED] * 2
        assert mode_of(sims[0]) == SimMode.SPEED
        r.run(0.4, [0.0, 0.0])
        assert max(r.odometry_error_steps(start)) <= 1.0


def test_fault_releases_motor_and_clears_itself(channel: str) -> None:
    motors, sims = two_wheels()
    with rig(channel, motors, sims) as r:
        r.send(r.drv.enable(r.t))
        r.run(0.4, [5.0, 5.0])
        sims[0].inject(SimFault.FAULT)
        r.run(0.3, [5.0, 5.0])
        # The motor coasts although commanded: the status frames carry no fault code, so the
        # driver cannot tell (documented limitation) and still says ENABLED.
        assert not sims[0].model.armed
        assert r.velocities()[0] < 4.0
        assert r.states() == [DriveState.ENABLED] * 2
        r.run(0.6, [5.0, 5.0])  # fault_stop_s = 0.5 s has passed: the stream drives again
        assert not sims[0].faults & SimFault.FAULT
        assert r.velocities() == pytest.approx([5.0, 5.0], abs=0.01)


def test_keepalive_and_device_timeout(channel: str) -> None:
    left = motor(23, timeout_s=0.5)
    sim = VescSimulator(left)
    with rig(channel, [left], [sim]) as r:
        r.send(r.drv.enable(r.t))
        r.send(r.drv.command([5.0], r.t))
        r.run(1.5, None)  # command() never again; poll() resends the last command
        assert mode_of(sim) == SimMode.SPEED
        assert sim.wheel_velocity_rad_s == pytest.approx(5.0, abs=0.01)
        r.run(0.6, None, poll=False)  # the gateway stalls: the VESC releases the motor
        assert mode_of(sim) == SimMode.RELEASED
        r.run(0.1, None)  # polling again resumes the stream
        assert mode_of(sim) == SimMode.SPEED
        r.send(r.drv.disable(r.t))
        r.run(1.0, None)
        assert mode_of(sim) == SimMode.RELEASED  # SET_CURRENT 0, and no stream after it
        assert sim.wheel_velocity_rad_s == pytest.approx(0.0, abs=1e-3)
        assert r.states() == [DriveState.DISABLED]
