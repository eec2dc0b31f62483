"""The per-cycle fast paths give the same results as the general code they shortcut.

Covers the performance changes of issue 6: precomputed pure-Python forward kinematics (against
numpy's least squares), odometry's one-allocation SE(2) step, the loop's inverse-kinematics
memo and the limits it skips while nothing changes, the drive set's status order, ``drain``
and ``to_message``, and the daemon's wait, which
must never ask epoll (whole milliseconds, rounded up) for more time than is left.  Also the
drivers' per-frame shortcuts: received frames built past ``Frame.__new__``, the CiA 402
statusword table and the ODrive error-word mapping on plain ints.  And those of issue 15: the
supervisor's solve of an accepted twist reused by the loop (one solve per new twist), the
drive set's per-cycle states and feedback (no status objects), the tracking check's skip while
nothing changes, the supervisor's reused decisions and the bus edge's frame tallies counted in C.
"""

from __future__ import annotations

import copy
import dataclasses
import math
import random
from typing import TYPE_CHECKING, Any

import can
import pytest
from hypothesis import given
from hypothesis import strategies as st

import gateway.runtime.loop
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
from gateway.config import load_config, parse_config
from gateway.core.control import Accepted, Source, StatusBoard, Supervisor
from gateway.core.errors import KinematicsError
from gateway.core.kinematics import apply_limits
from gateway.core.kinematics.odometry import Pose, _advance, compose, se2_exp
from gateway.core.settings import LoopConfig
from gateway.core.tracking import TrackingLimits, TrackingMonitor
from gateway.core.types import (
    DriveFault,
    DriveState,
    Frame,
    GatewayState,
    MotorStatus,
    Twist,
    WheelFeedback,
    frame_of,
)
from gateway.drive.driveset import DriveSet
from gateway.runtime.daemon import Daemon
from gateway.runtime.loop import Gateway
from gateway.runtime.sdnotify import SystemdNotifier
from gateway.wire.busload import frame_bits
from tests.conftest import CONFIG_DIR, SIM_ODRIVE_ENDPOINTS
from tests.e2e_helpers import Rig, virtual_config

if TYPE_CHECKING:
    from pathlib import Path

    from gateway.core.kinematics import IkResult, RobotModel

CONFIGS = [None, *sorted(CONFIG_DIR.glob("*.yaml"))]


def _close(a: float, b: float) -> bool:
    return abs(a - b) <= 1e-12 * max(1.0, abs(a), abs(b))


@pytest.mark.parametrize("path", CONFIGS, ids=lambda p: "default" if p is None else p.stem)
def test_fk_fast_path_matches_numpy(path: Path | None) -> None:
    model = load_config(path).model
    rng = random.Random(1)
    fast = 0
    for trial in range(60):
        speeds: list[float | None] = [rng.uniform(-30.0, 30.0) for _ in range(model.n)]
        if trial % 3 == 0:
            speeds[rng.randrange(model.n)] = None
        steer = model.neutral_steer
        try:
            ref = model._fk.solve(speeds, steer)
        except KinematicsError:  # too few wheels measured: both paths refuse
            with pytest.raises(KinematicsError):
                model.fk(speeds, steer)
            continue
        got = model.fk(speeds, steer)
        fast += model._fk.plan(speeds) is not None
        assert _close(got.twist.vx_m_s, ref.twist.vx_m_s)
        assert _close(got.twist.vy_m_s, ref.twist.vy_m_s)
        assert _close(got.twist.wz_rad_s, ref.twist.wz_rad_s)
        assert _close(got.residual_m_s, ref.residual_m_s)
        assert all(_close(a, b) for a, b in zip(got.wheel_residual_m_s,
                                                ref.wheel_residual_m_s, strict=True))
        vx, vy, wz, rms = model.fk_twist(speeds, steer)
        assert (vx, vy, wz, rms) == (got.twist.vx_m_s, got.twist.vy_m_s, got.twist.wz_rad_s,
                                     got.residual_m_s)
    steered = any(w.steered for w in model.wheels)
    assert (fast == 0) == steered  # the fast path is taken exactly for unsteered robots


def test_advance_is_compose_of_exp() -> None:
    rng = random.Random(2)
    for _ in range(500):
        pose = Pose(rng.uniform(-5, 5), rng.uniform(-5, 5), rng.uniform(-math.pi, math.pi))
        d = (rng.uniform(-0.1, 0.1), rng.uniform(-0.1, 0.1),
             rng.choice([0.0, 1e-6, rng.uniform(-0.5, 0.5)]))
        assert _advance(pose, *d) == compose(pose, se2_exp(*d))


def test_ik_memo_follows_the_target_object(channel: str) -> None:
    cfg = load_config(None, {"interface": "virtual", "channel": channel})
    gw = Gateway(cfg)
    try:
        target = Twist(0.3, 0.1, 0.2)
        first = gw._solve(target)
        assert first == cfg.model.try_ik(target, gw.prev.steer_rad)
        assert gw._solve(target) is first  # same object: no second solve
        other = gw._solve(Twist(0.3, 0.1, 0.2))  # equal but new: solved again
        assert other == first and other is not first
    finally:
        gw.close()
    cfg = load_config(CONFIG_DIR / "differential_tub.yaml",
                      {"interface": "virtual", "channel": channel})
    gw = Gateway(cfg)
    try:
        assert gw._solve(Twist(0.0, 0.5, 0.0)) == cfg.model.ik(Twist())  # infeasible -> zero
    finally:
        gw.close()


class _AlwaysLimited(Gateway):
    """A gateway that runs the limits every cycle (the general path): its solves are new
    objects, never the command of the cycle before."""

    def _solve(self, twist: Twist) -> IkResult:
        return copy.copy(super()._solve(twist))


@pytest.mark.parametrize("robot", ["mecanum.yaml", "swerve.yaml", "ackermann.yaml"])
def test_limits_skipped_only_when_they_would_change_nothing(
        channel: str, robot: str, monkeypatch: pytest.MonkeyPatch) -> None:
    rigs = [Rig(virtual_config(CONFIG_DIR / robot, f"{channel}-{k}")) for k in range(2)]
    rigs[1].gw.__class__ = _AlwaysLimited
    fast_model = rigs[0].gw.model
    calls = {"fast": 0}
    real = apply_limits

    def counting(model: RobotModel, *args: Any) -> Any:
        calls["fast"] += model is fast_model
        return real(model, *args)

    monkeypatch.setattr(gateway.runtime.loop, "apply_limits", counting)
    rng = random.Random(3)
    try:
        for rig in rigs:
            rig.enable()
        cycles = calls["fast"] = 0
        for k in range(20):
            if k % 7 == 6:  # an e-stop, which jumps to zero past the limits, and back
                for rig in rigs:
                    rig.gw.supervisor.estop()
                for _ in range(3):
                    lockstep(rigs)
                for rig in rigs:
                    rig.gw.supervisor.enable(rig.t)
                while rigs[0].gw.state is not GatewayState.RUNNING:
                    lockstep(rigs)
            twist = Twist(rng.uniform(-0.6, 0.6), 0.0, rng.uniform(-0.8, 0.8))
            hold = rng.choice((1, 3, 25, 80))  # ramps that finish, and ones cut short
            for rig in rigs:
                rig.gw.twist(twist, rig.t, Source.INTERNAL)
            for _ in range(hold):
                lockstep(rigs)
                cycles += 1
        assert all(rig.gw.state is GatewayState.RUNNING for rig in rigs)
        assert calls["fast"] <= 0.75 * cycles  # the shortcut was taken (runs are deterministic)
    finally:
        for rig in rigs:
            rig.close()


def lockstep(rigs: list[Rig]) -> None:
    """One cycle of both rigs; the same commands and limit reports come out."""
    for rig in rigs:
        rig.advance(rig.period)
    fast, slow = (rig.gw for rig in rigs)
    assert fast.state is slow.state
    assert fast.prev == slow.prev
    assert fast.limit_report == slow.limit_report


def test_drive_set_status_in_model_order_across_drivers() -> None:
    cfg = parse_config(_MIXED, "<mixed>")
    drives = DriveSet(cfg)
    names = [s.name for s in drives.status(0.0)]
    assert names == [w.name for w in cfg.model.wheels]
    speeds = [1.0, 2.0, 3.0, 4.0]
    assert len(drives.preview(speeds)) == 4


def test_drain_and_to_message(channel: str) -> None:
    tx = can.Bus(interface="virtual", channel=channel)
    rx = can.Bus(interface="virtual", channel=channel)
    try:
        assert drain(rx) == []
        frames = [Frame(0x123, b"\x01\x02"), Frame(0x1ABCDEF, b"", True, True, 4)]
        for f in frames:
            msg = to_message(f)
            assert (msg.arbitration_id, bytes(msg.data), msg.is_extended_id,
                    msg.is_remote_frame, msg.dlc) == tuple(f[:5])
            tx.send(msg)
        assert drain(rx, limit=0) == []  # nothing taken
        assert drain(rx, timestamp_s=7.0) == frames
        assert drain(rx) == []
    finally:
        tx.shutdown()
        rx.shutdown()


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


class _FakeServer:
    """Records poll timeouts and stands in for the control server."""

    def __init__(self, clock: list[float]) -> None:
        self.clock = clock
        self.timeouts: list[float] = []

    def poll(self, timeout_s: float) -> list[object]:
        self.timeouts.append(timeout_s)
        self.clock[0] += math.ceil(timeout_s * 1e3) * 1e-3  # what epoll does
        return []


def test_wait_never_oversleeps_the_deadline(channel: str, sock_path: str) -> None:
    cfg = load_config(None, {"interface": "virtual", "channel": channel})
    daemon = Daemon(cfg, socket_path=sock_path, notifier=SystemdNotifier(None))
    real_server = daemon.server
    try:
        now = [100.0]
        sched = daemon.scheduler

        def clock() -> float:
            now[0] += 1e-6  # every reading takes a microsecond, so the spin ends
            return now[0]

        sched._clock = clock

        def sleep(seconds: float) -> None:
            now[0] += seconds

        sched._sleep = sleep
        fake = _FakeServer(now)
        daemon.server = fake  # type: ignore[assignment]
        daemon._server_fd = None
        sched.start(now[0])
        for offset in (0.0, 0.0003, 0.0021, 0.0049):
            now[0] = sched.next_deadline_s() - sched.period_s + offset
            deadline = sched.next_deadline_s()
            daemon._wait()
            assert sched.timer.missed == 0
            assert deadline <= now[0] <= deadline + 1e-5
        assert fake.timeouts[-1] == 0.0  # the pass at the deadline
        # Only whole milliseconds minus a half, which epoll rounds up to the whole ones.
        assert all(t == 0.0 or abs(t * 1e3 - math.floor(t * 1e3) - 0.5) < 1e-6
                   for t in fake.timeouts)
        assert any(t > 0.0 for t in fake.timeouts)
    finally:
        daemon.server = real_server
        daemon.close()


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


@pytest.mark.parametrize("robot", ["mecanum.yaml", "swerve.yaml"])
def test_one_inverse_kinematics_solve_per_new_twist(
        channel: str, robot: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """The supervisor's feasibility check of an accepted twist is the solve the loop uses: a
    new twist costs one solve, the cycle that follows it none; on a robot without steered
    wheels no cycle after it solves again (steered wheels turning through the steering-rate
    limit start each cycle from new angles, a new solve each)."""
    cfg = virtual_config(CONFIG_DIR / robot, channel)
    # No acceleration limit: the limits then solve nothing themselves.
    cfg = dataclasses.replace(cfg, limits=dataclasses.replace(
        cfg.limits, max_wheel_accel_rad_s2=math.inf))
    with Rig(cfg) as rig:
        rig.enable()
        model = rig.gw.model
        calls = [0]
        real = type(model)._solve

        def counting(self: RobotModel, *args: Any) -> Any:
            calls[0] += self is model
            return real(self, *args)

        monkeypatch.setattr(type(model), "_solve", counting)
        for twist in (Twist(0.3, 0.0, 0.0), Twist(0.3, 0.2, 0.1), Twist(0.0, 0.0, 0.4)):
            calls[0] = 0
            result = rig.gw.twist(twist, rig.t, Source.INTERNAL)
            assert isinstance(result, Accepted) and result.ik is not None
            assert calls[0] == 1
            rig.advance(rig.period)
            assert calls[0] == 1
            assert rig.gw.prev.twist == twist
            rig.advance(30 * rig.period)
            if robot == "mecanum.yaml":
                assert calls[0] == 1
        assert rig.gw.state is GatewayState.RUNNING


def test_ik_of_an_accepted_twist_is_the_loops_own_solve(channel: str) -> None:
    """The solve the supervisor hands over equals the loop's own for that twist."""
    for robot in ("mecanum.yaml", "swerve.yaml", "ackermann.yaml"):
        with Rig(virtual_config(CONFIG_DIR / robot, f"{channel}-{robot}")) as rig:
            rig.enable()
            rng = random.Random(4)
            for _ in range(15):
                twist = Twist(rng.uniform(-0.5, 0.5), rng.uniform(-0.3, 0.3),
                              rng.uniform(-0.6, 0.6))
                steer = rig.gw.prev.steer_rad
                result = rig.gw.twist(twist, rig.t, Source.INTERNAL)
                if isinstance(result, Accepted) and result.ik is not None:
                    assert rig.gw._solve(twist) is result.ik
                    assert result.ik == rig.gw.model.try_ik(twist, steer)
                rig.advance(rng.choice((1, 5)) * rig.period)


def test_drive_set_states_and_feedback_match_the_statuses(channel: str) -> None:
    """The per-cycle accessors give what the statuses would, motor for motor."""
    for robot in ("mecanum.yaml", "swerve.yaml", "ackermann.yaml", "differential_tub.yaml"):
        with Rig(virtual_config(CONFIG_DIR / robot, f"{channel}-{robot}")) as rig:
            drives = rig.gw.drives
            checks = 0
            for k in range(30):
                if k == 5:
                    rig.gw.supervisor.enable(rig.t)
                rig.advance(rig.period)
                statuses = drives.status(rig.t)
                assert drives.states(rig.t) == [s.state for s in statuses]
                got = drives.motor_feedback()
                assert all(a is b.feedback for a, b in zip(got, statuses, strict=True))
                assert drives.feedback_by_wheel() == drives._slot_feedback()[:rig.gw.model.n]
                checks += sum(f is not None for f in got)
            assert checks > 0
    cfg = parse_config(_MIXED, "<mixed>")
    drives = DriveSet(cfg)
    assert drives._status_order is not None
    assert drives.states(0.0) == [s.state for s in drives.status(0.0)]
    assert drives.motor_feedback() == [s.feedback for s in drives.status(0.0)]


def _monitor_state(mon: TrackingMonitor) -> tuple[object, ...]:
    return (list(mon._count), mon._last_s, list(mon._peak), list(mon._peak_before),
            mon._period_start_s, mon.worst_ratio)


@pytest.mark.parametrize("seed", range(6))
def test_tracking_skip_matches_the_full_check(seed: int) -> None:
    """``check`` (which skips while nothing changes) and the wheel-by-wheel path agree on every
    fault and every piece of state, over commands and feedback that change now and then."""
    rng = random.Random(seed)
    limits = TrackingLimits(tolerance_rad_s=1.0, tolerance_ratio=0.2, time_s=0.2)
    fast, full = TrackingMonitor(limits), TrackingMonitor(limits)
    bands: list[tuple[float, float] | None] = [None, (0.5, 2.0), None] if seed % 2 else []
    fast.dead_bands = full.dead_bands = bands
    n = 3
    command = tuple(rng.uniform(-5, 5) for _ in range(n))
    feedback: list[WheelFeedback | None] = [None] * n
    full_checks = [0]
    check_all = fast._check_all

    def counting(*args: Any) -> Any:
        full_checks[0] += 1
        return check_all(*args)

    fast._check_all = counting  # type: ignore[method-assign,assignment]
    t, steps = 0.0, 3000
    for step in range(steps):
        t += 0.001
        roll = rng.random()
        if roll < 0.004:
            command = tuple(rng.choice((0.0, 1.0, -1.5, rng.uniform(-8, 8))) for _ in range(n))
        elif roll < 0.02:
            command = (*command[:-1], command[-1])  # equal, not the same object
        if rng.random() < 0.1:
            i = rng.randrange(n)
            # Mostly inside the window, so that the check has quiet spells to skip (a wheel
            # that leaves it keeps a count for a while after it is back).
            off = rng.choice((0.0, 0.1, -0.3, 0.5))
            if rng.random() < 0.004:
                off = rng.choice((3.0, -9.0, math.nan))
            band = bands[i] if i < len(bands) else None
            # A controller stops its motor on a command in its dead band.
            speed = 0.0 if band and band[0] < abs(command[i]) < band[1] else command[i]
            feedback[i] = WheelFeedback(0.0, speed + off, t)
        if step % 700 == 699:
            fast.reset()
            full.reset()
        fb = list(feedback)
        a = fast.check(command, fb, t)
        b = full._check_all(command, fb, t)
        assert a == b
        assert _monitor_state(fast) == _monitor_state(full)
    assert full_checks[0] < 0.7 * steps  # the skip was taken


def test_supervisor_decisions_are_reused_only_while_equal() -> None:
    model = load_config(None).model
    sup = Supervisor(model, LoopConfig(cmd_timeout_s=0.5))
    sup.enable(0.0)
    assert sup.decide(0.0) is sup.decide(0.1)  # ENABLING: one constant decision
    enabled = [MotorStatus(w.name, k + 1, DriveState.ENABLED, DriveFault.NONE, "", 0.0, None)
               for k, w in enumerate(model.wheels)]
    sup.motors(StatusBoard(enabled), 0.0)
    assert sup.state is GatewayState.RUNNING
    decisions = []
    for k, twist in enumerate((Twist(0.1, 0, 0), Twist(0.1, 0, 0), Twist(0.2, 0, 0))):
        sup.twist(twist, k * 0.1)
        first, again = sup.decide(k * 0.1), sup.decide(k * 0.1 + 0.01)
        assert first is again and first.twist is twist and not first.cmd_timeout
        assert (first.ramp, first.armed) == (True, True)
        decisions.append(first)
    assert decisions[0] is not decisions[1]  # equal twists, new objects: new decisions
    timed_out = sup.decide(5.0)
    assert timed_out.cmd_timeout and timed_out.twist == Twist()
    assert sup.decide(5.1) is timed_out


_MIXED: dict[str, object] = {
    "name": "mixed", "drive": "mecanum",
    "geometry": {"wheel_radius": 0.05, "wheelbase": 0.4, "track": 0.36},
    "motor_defaults": {"gear_ratio": 10.0, "max_rpm": 3000},
    "motors": {
        "front_left": {"driver": "vesc", "node_id": 1, "pole_pairs": 7},
        "front_right": {"driver": "odrive", "node_id": 2,
                        "watchdog_endpoints": SIM_ODRIVE_ENDPOINTS},
        "rear_left": {"driver": "vesc", "node_id": 3, "pole_pairs": 7},
        "rear_right": {"driver": "odrive", "node_id": 4,
                       "watchdog_endpoints": SIM_ODRIVE_ENDPOINTS},
    },
    "bus": {"interface": "virtual", "channel": "unused"},
}


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
