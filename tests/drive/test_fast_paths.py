"""The per-cycle fast paths give the same results as the general code they shortcut.

Covers the performance changes of issue 6: precomputed pure-Python forward kinematics (against
numpy's least squares), odometry's one-allocation SE(2) step, the loop's inverse-kinematics
memo and the limits it skips while nothing changes, the drive set's status order, ``drain``
and ``to_message``, and the daemon's wait, which
must never ask epoll (whole milliseconds, rounded up) for more time than is left.  Also the
drivers' per-frame shortcuts: received frames built past ``Frame.__new__``, the CiA 402
statusword table and the ODrive error-word mapping on plain ints.
"""

from __future__ import annotations

import copy
import math
import random
from typing import TYPE_CHECKING, Any

import can
import pytest

import gateway.runtime.loop
from drivers.cia402.enums import STATUSWORD_MASK, state_from_statusword
from drivers.odrive.enums import AXIS_ERROR_05_FAULTS, AXIS_ERROR_FAULTS, Firmware, error_faults
from gateway.bus.can_bus import drain, to_frame, to_message
from gateway.config import load_config, parse_config
from gateway.core.control import Source
from gateway.core.errors import KinematicsError
from gateway.core.kinematics import apply_limits
from gateway.core.kinematics.odometry import Pose, _advance, compose, se2_exp
from gateway.core.types import DriveFault, Frame, GatewayState, Twist
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
    raw = {
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
    cfg = parse_config(raw, "<mixed>")
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
              Frame(0x123, bytes(8)), Frame(0x7FF, b"", False, True, 8), Frame(0x10, b"")]
    gw = Gateway(load_config(None, {"interface": "virtual", "channel": channel}))
    try:
        gw._tally(frames, True)
        gw._tally(frames[:2], False)
        assert gw.id_counts == {(0x123, False, True): 2, (0x1ABCDEF, True, True): 1,
                                (0x7FF, False, True): 1, (0x10, False, True): 1,
                                (0x123, False, False): 1, (0x1ABCDEF, True, False): 1}
        expected = sum(frame_bits(0 if f.is_remote_frame else f.dlc, f.is_extended_id)
                       for f in frames + frames[:2])
        assert gw.bits == expected
    finally:
        gw.close()
