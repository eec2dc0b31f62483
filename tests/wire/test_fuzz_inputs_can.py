"""Fuzzing of the gateway's CAN twist input.

``WG_Twist_Cmd`` on a running gateway with its simulators, on simulated time: random payloads,
lengths, remote frames, reserved flag bits, extreme values.  Never raises; every malformed frame
is counted (``bad_can_twists``) and answered with a ``WG_Error`` ``BAD_COMMAND``; every valid
one is counted as a twist or a duplicate; and the wheels stay at zero unless a valid, feasible,
non-zero twist without flags arrived.
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
import struct
from typing import TYPE_CHECKING

import pytest
from hypothesis import given
from hypothesis import strategies as st

from gateway.bus.can_bus import drain, send_frames
from gateway.core.errors import DecodeError
from gateway.core.types import ErrorCode, Frame, GatewayState, Twist
from gateway.wire.can import TwistFlags
from tests.conftest import CONFIG_DIR
from tests.wire.fuzz_input_helpers import FUZZ, running

if TYPE_CHECKING:
    from tests.e2e_helpers import Rig

#: ``WG_Twist_Cmd`` as ``config/wheelgate.dbc`` lays it out: vx, vy (mm/s), wz (mrad/s),
#: counter, flags.
TWIST_LAYOUT = struct.Struct("<hhhBB")
TWIST_FLAG_BITS = 0x07
I16 = st.integers(-(2**15), 2**15 - 1)
I16_EXTREMES = st.sampled_from([-(2**15), -(2**15) + 1, -1, 0, 1, 2**15 - 1])


# =============================================================================== CAN twists


@st.composite
def bad_twist_payloads(draw: st.DrawFn) -> tuple[bytes, bool, int]:
    """(data, remote, dlc) of a malformed ``WG_Twist_Cmd``."""
    kind = draw(st.sampled_from(["remote", "length", "flags"]))
    if kind == "remote":
        return b"", True, draw(st.integers(0, 8))
    if kind == "length":
        data = draw(st.binary(max_size=7))
        return data, False, len(data)
    head = draw(st.binary(min_size=7, max_size=7))
    flags = draw(st.integers(0, 255).filter(lambda f: f & ~TWIST_FLAG_BITS))
    return head + bytes([flags]), False, 8


@st.composite
def any_twist_payloads(draw: st.DrawFn) -> tuple[bytes, bool, int]:
    """(data, remote, dlc) of any ``WG_Twist_Cmd``: malformed, random, or well formed with
    extreme or small values, any counter, and flags mostly clear."""
    kind = draw(st.sampled_from(["bad", "random", "valid", "valid"]))
    if kind == "bad":
        return draw(bad_twist_payloads())
    if kind == "random":
        return draw(st.binary(min_size=8, max_size=8)), False, 8
    values = draw(st.lists(I16_EXTREMES | I16 | st.integers(-400, 400), min_size=3, max_size=3))
    if draw(st.booleans()):
        values[1] = 0  # no sideways speed: feasible for car-like and differential robots too
    flags = draw(st.sampled_from([0, 0, 0, 1, 2, 4, 3, 7]))
    data = TWIST_LAYOUT.pack(*values, draw(st.integers(0, 255)), flags)
    return data, False, 8


def twist_frame(rig: Rig, payload: tuple[bytes, bool, int]) -> Frame:
    data, remote, dlc = payload
    ids = rig.gw.wg.ids
    return Frame(ids.twist, data, ids.extended, remote, dlc)


def bad_command_errors(rig: Rig) -> int:
    """``WG_Error`` frames with code ``BAD_COMMAND`` the pilot has received since last asked."""
    count = 0
    for frame in drain(rig.pilot):
        with contextlib.suppress(DecodeError):
            report = rig.gw.wg.decode_error(frame)
            count += report is not None and report.code is ErrorCode.BAD_COMMAND
    return count


def assert_wheels_within_limits(rig: Rig) -> None:
    for w, m in zip(rig.gw.prev.wheel_rad_s, rig.config.motors, strict=True):
        assert math.isfinite(w)
        if m is not None:
            assert abs(w) <= m.max_wheel_rad_s * (1 + 1e-9)


@FUZZ
@given(payloads=st.lists(bad_twist_payloads(), min_size=1, max_size=12))
def test_malformed_can_twists_are_counted_answered_and_never_move(
    payloads: list[tuple[bytes, bool, int]],
) -> None:
    with running(CONFIG_DIR / "turtlebot3_burger.yaml") as rig:
        counts = dataclasses.replace(rig.gw.counts)
        bad_command_errors(rig)
        speeds: list[tuple[float, ...]] = []
        for payload in payloads:
            send_frames(rig.pilot, [twist_frame(rig, payload)])
            rig.advance(rig.period, lambda r: speeds.append(r.gw.prev.wheel_rad_s))
        rig.advance(0.05, lambda r: speeds.append(r.gw.prev.wheel_rad_s))
        assert rig.gw.counts.bad_can_twists == counts.bad_can_twists + len(payloads)
        assert rig.gw.counts.can_twists == counts.can_twists
        assert bad_command_errors(rig) == len(payloads)
        assert rig.gw.state is GatewayState.RUNNING
        assert all(w == 0.0 for s in speeds for w in s)


@pytest.mark.parametrize("robot", ["turtlebot3_burger.yaml", "ackermann.yaml"])
@FUZZ
@given(payloads=st.lists(any_twist_payloads(), min_size=1, max_size=12))
def test_the_robot_moves_only_on_a_valid_feasible_twist(
    robot: str, payloads: list[tuple[bytes, bool, int]]
) -> None:
    with running(CONFIG_DIR / robot) as rig:
        counts = dataclasses.replace(rig.gw.counts)
        bad_command_errors(rig)
        model, wg = rig.config.model, rig.gw.wg
        bad = valid = 0
        may_move = False
        speeds: list[tuple[float, ...]] = []
        for payload in payloads:
            frame = twist_frame(rig, payload)
            try:
                cmd = wg.decode_twist(frame)
            except DecodeError:
                bad += 1
            else:
                assert cmd is not None
                valid += 1
                may_move |= (
                    cmd.flags is TwistFlags.NONE
                    and cmd.twist != Twist()
                    and model.feasible(cmd.twist, rig.gw.prev.steer_rad)
                )
            send_frames(rig.pilot, [frame])
            rig.advance(rig.period, lambda r: speeds.append(r.gw.prev.wheel_rad_s))
            assert_wheels_within_limits(rig)
        rig.advance(0.05, lambda r: speeds.append(r.gw.prev.wheel_rad_s))
        now = rig.gw.counts
        assert now.bad_can_twists - counts.bad_can_twists == bad
        assert (now.can_twists - counts.can_twists
                + now.can_duplicates - counts.can_duplicates) == valid
        assert bad_command_errors(rig) == bad
        if not may_move:
            assert all(w == 0.0 for s in speeds for w in s), "moved without a feasible twist"
