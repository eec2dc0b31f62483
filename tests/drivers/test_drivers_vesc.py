"""Tests of the VESC driver (drivers/vesc/driver.py); the codec in ``test_vesc_codec``, the
simulator in ``test_drivers_vesc_sim``.

Worked examples: VESC ID 23 = 0x17, 7 pole pairs, so 100 rpm at the motor is 700 eRPM
(vedderb/bldc ``documentation/comm_can.md``: SET_RPM and STATUS carry electrical RPM).
"""

from __future__ import annotations

import logging
import math
import re
from typing import TYPE_CHECKING

import pytest
from hypothesis import given
from hypothesis import strategies as st

from drivers.vesc import VescDriver
from drivers.vesc.appconf import make_get_appconf
from drivers.vesc.codec import (
    make_set_rpm,
    make_status,
    make_status5,
    wrap_int32,
)
from gateway.core.errors import ConfigError, EncodeError
from gateway.core.types import DriveState, Frame, MotorConfig
from gateway.drive.registry import get_driver_class
from tests import factories
from tests.drivers.test_vesc_codec import I32, ext
from tests.drivers.test_vesc_helpers import answer_reads, enabled

if TYPE_CHECKING:
    from collections.abc import Sequence

__all__ = ["PP", "ext", "motor"]

PP = 7


def motor(
    node_id: int = 23,
    *,
    wheel: str = "left",
    gear_ratio: float = 1.0,
    invert: bool = False,
    max_rpm: float = 3000.0,
    validate: bool = True,
    **options: object,
) -> MotorConfig:
    """A VESC motor block of the factory (:func:`tests.factories.motor`), ``PP`` pole pairs."""
    return factories.motor(
        "vesc", node_id, wheel, gear_ratio=gear_ratio, invert=invert, max_rpm=max_rpm,
        validate=validate, options={"pole_pairs": PP, **options},
    )


def rpm_to_rad_s(rpm: float) -> float:
    return rpm * 2.0 * math.pi / 60.0


# ============================================================================ driver: config


def test_registry_entry() -> None:
    assert get_driver_class("vesc") is VescDriver


def test_validate_options_fills_defaults() -> None:
    got = VescDriver.validate_options({"pole_pairs": 7}, "robot.yaml: wheels[0].motor")
    defaults = {
        "command_period_s": 0.02,
        "controller_timeout_s": 0.0,  # not stated
        "status_rate_hz": 0.0,  # not stated
        "min_erpm": 900.0,  # the factory's s_pid_min_erpm
        "liveness_s": 0.25,
    }
    assert got == {"pole_pairs": 7, **defaults}
    got = VescDriver.validate_options({"pole_pairs": 7, "command_period_s": 0.499}, "w")
    assert got["command_period_s"] == 0.499  # just below half the factory 1 s
    got = VescDriver.validate_options({"pole_pairs": 7, "status_rate_hz": 8}, "w")
    assert got["status_rate_hz"] == 8.0  # two periods: exactly the 0.25 s liveness


@pytest.mark.parametrize(
    ("raw", "message"),
    [
        ({}, "w.pole_pairs: required key is missing"),
        ({"pole_pairs": 0}, "w.pole_pairs: expected at least 1"),
        ({"pole_pairs": 7.0}, "w.pole_pairs: expected int"),
        ({"pole_pairs": 7, "poles": 14}, "w.poles: unknown key"),
        (
            {"pole_pairs": 7, "timeout_s": 0.5},
            "w.timeout_s: renamed controller_timeout_s (the timeout set in VESC Tool",
        ),
        ({"pole_pairs": 7, "controller_timeout_s": -1}, "w.controller_timeout_s: expected at"),
        (
            {"pole_pairs": 7, "command_period_s": 0.5},  # exactly half the factory 1 s
            "w.command_period_s: expected less than half the VESC's timeout (the factory 1 s, "
            "as controller_timeout_s is not stated) = 0.5 s",
        ),
        (
            {"pole_pairs": 7, "controller_timeout_s": 0.5, "command_period_s": 0.25},
            "(controller_timeout_s 0.5 s) = 0.25 s",
        ),
        (
            {"pole_pairs": 7, "status_rate_hz": 5},
            "w.liveness_s: expected at least two status periods at status_rate_hz 5 (0.4 s)",
        ),
        ({"pole_pairs": 7, "status_rate_hz": 20000}, "w.status_rate_hz: expected at most"),
        ({"pole_pairs": 7, "min_erpm": -1}, "w.min_erpm: expected at least 0"),
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
        [motor(23, validate=False, command_period_s=0.5)],
        [motor(23, validate=False, controller_timeout_s=0.2, command_period_s=0.1)],
        [factories.motor("vesc", 23, validate=False)],  # no pole_pairs
    ],
)
def test_constructor_rejects(motors: list[MotorConfig]) -> None:
    with pytest.raises(ConfigError):
        VescDriver(motors)


def test_each_vesc_keeps_its_own_liveness() -> None:
    drv = VescDriver([motor(23, liveness_s=0.25), motor(24, wheel="right", liveness_s=0.5)])
    assert drv.live.limits == [0.25, 0.5]


# ============================================================================ driver: units


def test_command_converts_wheel_speed_to_erpm() -> None:
    # 100 rpm at the motor, 7 pole pairs -> 700 eRPM (spec worked example).
    drv = VescDriver([motor(23), motor(24, wheel="right", gear_ratio=2.0, invert=True)])
    enabled(drv, 0.0)
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
    assert str(err.value) == (  # the base's check (gateway.drive.setpoints)
        'Expected a wheel speed for VESC node 23 ("left") between -314.159 and 314.159 rad/s '
        "(max_rpm 3000), but got 400.0."
    )
    for bad in (math.nan, math.inf, -400.0):
        with pytest.raises(EncodeError):
            drv.command([bad], 0.0)  # checked even while disabled
    with pytest.raises(EncodeError, match=r"Expected 1 setpoints for the VESC motors \(left\)"):
        drv.command([1.0, 2.0], 0.0)
    assert drv.command([rpm_to_rad_s(3000.0)], 0.0) == []  # the limit itself is fine


def test_enable_disable_frames_and_keepalive() -> None:
    drv = VescDriver([motor(23), motor(24, wheel="right", command_period_s=0.05)])
    assert drv.keepalive_period_s == 0.02
    assert drv.command([1.0, 1.0], 0.0) == []  # disabled: nothing goes out
    assert drv.poll(0.0) == []
    assert enabled(drv, 1.0) == [make_set_rpm(23, 0), make_set_rpm(24, 0)]
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
        enabled(drv, enabled_at)
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
    seen.append(drv.state(0, 0.15))  # reading the timeout back
    answer_reads(drv, [make_get_appconf(23)], 0.15)
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
    enabled(drv, 0.0)
    with caplog.at_level(logging.WARNING, logger="drivers.vesc.driver"):
        drv.poll(0.5)
        assert not caplog.records
        drv.on_frame(make_status(23, 0, 0.0, 0.0).stamped(0.6))
        drv.poll(1.1)
        drv.poll(1.2)
    assert len(caplog.records) == 1
    assert "no STATUS_5 received" in caplog.records[0].getMessage()
    assert "Can Messages Rate 1" in caplog.records[0].getMessage()


def test_liveness_streams_are_status_and_status5() -> None:
    """Each stream is heard at its own frame's time, in either order; the feedback is stamped
    with its position's time (STATUS_5's: a STATUS refreshes the speed only), and its age in a
    report is the older stream's."""
    drv = VescDriver([motor(23)])
    assert drv.live.silent(0, 0.0) == ["STATUS", "STATUS_5"]
    steps = [  # frame, time; then the streams' times and the feedback's stamp
        (make_status(23, 0, 0.0, 0.0), 0.1, [0.1, None], None),
        (make_status5(23, 0, 24.0), 0.1, [0.1, 0.1], 0.1),
        (make_status(23, 0, 0.0, 0.0), 0.2, [0.2, 0.1], 0.1),
        (make_status5(23, 0, 24.0), 0.3, [0.2, 0.3], 0.3),
        (make_status(23, 0, 0.0, 0.0), 0.35, [0.35, 0.3], 0.3),
        (make_status5(23, 0, 24.0), 0.34, [0.35, 0.34], 0.34),  # stamped before the STATUS
        (make_status5(23, 0, 24.0), 0.5, [0.35, 0.5], 0.5),
        (make_status(23, 0, 0.0, 0.0), 0.45, [0.45, 0.5], 0.5),
    ]
    for frame, t, times, stamp in steps:
        assert drv.on_frame(frame.stamped(t))
        assert drv.live.times[0] == times, t
        fb = drv.feedback(0)
        assert (fb and fb.timestamp_s) == stamp, t
    assert drv.live.silent(0, 0.74) == ["STATUS"]
    assert drv.state(0, 0.74) is DriveState.OFFLINE
    assert drv.status(0.74)[0].feedback_age_s == pytest.approx(0.29)


def test_claims_and_message_names() -> None:
    drv = VescDriver([motor(23), motor(24, wheel="right")])
    claims = drv.claims()
    taken = [(c.can_id, c.motor) for c in claims if c.receive and c.motor is not None]
    assert taken == [
        (packet << 8 | node, i) for i, node in enumerate((23, 24))
        for packet in (9, 14, 15, 16, 27, 58)
    ]
    pongs, *replies = (c for c in claims if c.motor is None)
    assert (pongs.can_id, pongs.mask, pongs.extended, pongs.receive) == (
        0x1200, 0x1FFFFF00, True, True
    )
    # The buffer protocol's frames to the gateway's ID 254 (the COMM_GET_APPCONF replies).
    assert [(c.can_id, c.mask, c.receive) for c in replies] == [
        (packet << 8 | 0xFE, 0x1FFFFFFF, True) for packet in (5, 6, 7, 8)]
    sent = {(c.can_id, c.motor) for c in claims if not c.receive}
    assert sent == {(0x117, 0), (0x317, 0), (0x118, 1), (0x318, 1), (0x817, 0), (0x818, 1)}
    frames = [make_get_appconf(23), make_get_appconf(24), *enabled(drv, 0.0),
              *drv.command([1.0, 1.0], 0.0), *drv.disable(0.1)]
    assert all(any(c.matches(f.arbitration_id, True) for c in claims) for f in frames)
    assert all(c.extended for c in claims)
    names = {arb: drv.message_name(arb, True) for arb in (0x917, 0x1B17, 0x1018, 0x1201, 0x317,
                                                          0x117, 0x3A17)}
    assert names == {0x917: "STATUS", 0x1B17: "STATUS_5", 0x1018: "STATUS_4", 0x1201: "PONG",
                     0x317: "SET_RPM", 0x117: "SET_CURRENT", 0x3A17: "STATUS_6"}
    assert drv.message_name(0x3D17, True) == "packet 61"  # not in CanPacketId
    assert drv.message_name(0x5FE, True) == "FILL_RX_BUFFER"  # the buffer protocol's
    assert drv.message_name(0x117, False) is None  # an 11-bit frame is never VESC's
