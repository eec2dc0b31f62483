"""Benchmark: replaying a long candump log through the drivers and the odometry.

Method: a synthetic log of a 4-wheel ODrive robot (the embedded demo mecanum, firmware 0.6) is
written to a temporary file: every wheel's Get_Encoder_Estimates at 1 kHz (4 kHz in all, each
frame with its own time stamp, staggered by 0.25 ms as ``candump`` would stamp them) plus each
axis' heartbeat at 10 Hz.  The robot's twist changes smoothly (forward and back, sideways,
turning both ways); it is held for each millisecond, so the exact final pose is the product of
the milliseconds' SE(2) exponentials.  The wheel angles are integrated exactly and sent as
float32 motor turns, as the firmware does.

The log is then replayed from the file (reading, parsing, the drivers, the odometry: what
``wheelgate odom`` does apart from printing) with several least intervals between odometry
updates; for each, the wall time (``time.perf_counter``, one run after a warm-up), frames per
second, the factor over real time (log duration / replay time) and the final pose's distance
from the exact one.  Two baselines show where the time goes: reading and parsing the lines
alone, and parsing plus the drivers without odometry.

Run: ``python tools/bench_replay.py [FRAMES]`` (default 1,000,000 encoder frames = 250 s of
log; target: at least 10x real time at the default interval).
"""

from __future__ import annotations

import math
import os
import statistics
import sys
import tempfile
import time

from drivers.odrive.codec import OdriveCodec
from drivers.odrive.enums import AxisState
from drivers.odrive.messages import Heartbeat
from gateway.apps.replay.replay import Replay
from gateway.config import load_config
from gateway.core.kinematics import wrap_angle
from gateway.core.kinematics.odometry import Pose, compose, se2_exp
from gateway.core.types import Twist
from gateway.drive.driveset import DriveSet
from gateway.wire.candump import read_lines

#: Encoder rate per wheel, Hz.
ENCODER_HZ = 1000
#: Heartbeat rate per axis, Hz.
HEARTBEAT_HZ = 10
#: Runs per measurement.
REPEATS = 3
#: Least update intervals to measure, s (``None``: the default, the config's control period).
INTERVALS = (0.0, 0.001, None, 0.02)


def twist_at(t: float) -> Twist:
    """The robot's twist at time ``t`` (s): smooth, every kind of motion a mecanum base makes
    (forward and back, sideways, turning both ways)."""
    return Twist(0.6 * math.sin(0.21 * t) + 0.2, 0.4 * math.cos(0.13 * t),
                 1.2 * math.sin(0.37 * t))


def write_log(path: str, frames: int) -> tuple[float, Pose, float]:
    """Write the synthetic log.

    Every wheel is sampled at each millisecond; over the millisecond after a sample the twist
    is the one at the sample (so the exact pose is the product of the millisecond steps'
    exponentials), and the four wheels' frames leave 0.25 ms apart.

    :return: its duration (s), the exact final pose and the exact path length (m).
    """
    config = load_config(None)
    model = config.model
    motors = [m for m in config.motors if m is not None]
    codec = OdriveCodec.from_options(motors[0].options)
    n = len(motors)
    period = 1.0 / ENCODER_HZ
    samples = frames // n
    wheel_rad = [0.0] * n
    pose = Pose()
    distance = 0.0
    t0 = 1_700_000_000.0
    hb_every = ENCODER_HZ // HEARTBEAT_HZ
    signs = [(-1.0 if m.invert else 1.0) * m.gear_ratio / math.tau for m in motors]
    with open(path, "w", encoding="ascii") as out:
        write = out.write
        for k in range(samples):
            t = k * period
            twist = twist_at(t)
            speeds = model.ik(twist).wheel_rad_s
            for i, m in enumerate(motors):
                f = codec.make_encoder_estimates(
                    m.node_id, wheel_rad[i] * signs[i], speeds[i] * signs[i]
                )
                stamp = t0 + t + i * period / n
                write(f"({stamp:.6f}) can0 {f.arbitration_id:03X}#{f.data.hex().upper()} R\n")
                if k % hb_every == 0:
                    hb = codec.make_heartbeat(
                        Heartbeat(m.node_id, 0, AxisState.CLOSED_LOOP_CONTROL, False)
                    )
                    write(f"({stamp:.6f}) can0 {hb.arbitration_id:03X}#{hb.data.hex().upper()} R\n")
            if k < samples - 1:
                for i in range(n):
                    wheel_rad[i] += speeds[i] * period
                pose = compose(pose, se2_exp(twist.vx_m_s * period, twist.vy_m_s * period,
                                             twist.wz_rad_s * period))
                distance += math.hypot(twist.vx_m_s, twist.vy_m_s) * period
    return samples * period, pose, distance


def time_parse(path: str) -> float:
    t0 = time.perf_counter()
    with open(path, encoding="ascii") as f:
        for _ in read_lines(f, []):
            pass
    return time.perf_counter() - t0


def time_drivers(path: str) -> float:
    (driver, _), = DriveSet(load_config(None)).groups  # one protocol: as Replay calls it
    on_frame = driver.on_frame
    t0 = time.perf_counter()
    with open(path, encoding="ascii") as f:
        for entry in read_lines(f, []):
            on_frame(entry.frame)
    return time.perf_counter() - t0


def time_replay(path: str, interval: float | None) -> tuple[float, Replay]:
    replay = Replay(load_config(None), interval)
    t0 = time.perf_counter()
    with open(path, encoding="ascii") as f:
        for _ in replay.feed_lines(f):
            pass
    return time.perf_counter() - t0, replay


def best(runs: list[float]) -> str:
    """Best and median of the runs, s."""
    return f"best {min(runs):.2f} s, median {statistics.median(runs):.2f} s"


def main() -> None:
    frames = int(sys.argv[1]) if len(sys.argv) > 1 else 1_000_000
    repeats = int(sys.argv[2]) if len(sys.argv) > 2 else REPEATS
    folder = tempfile.mkdtemp(prefix="wg-bench-replay-")
    path = os.path.join(folder, "synthetic.log")
    try:
        t0 = time.perf_counter()
        duration, exact, exact_m = write_log(path, frames)
        size = os.path.getsize(path)
        with open(path, encoding="ascii") as f:
            entries = sum(1 for _ in f)
        print(f"log: {frames:,} encoder frames + {entries - frames:,} heartbeats, "
              f"{duration:.1f} s of log, {size / 1e6:.1f} MB, written in "
              f"{time.perf_counter() - t0:.1f} s")
        print(f"exact final pose: x={exact.x_m:.4f} m y={exact.y_m:.4f} m "
              f"theta={exact.theta_rad:.4f} rad; {repeats} runs each, best and median")
        time_parse(path)  # warm-up (page cache)
        runs = [time_parse(path) for _ in range(repeats)]
        print(f"read + parse only: {best(runs)}; {min(runs) / entries * 1e6:.2f} us/line")
        runs = [time_drivers(path) for _ in range(repeats)]
        print(f"read + parse + drivers: {best(runs)}; {min(runs) / entries * 1e6:.2f} us/line")
        print()
        print("| least interval | updates | wall time (best / median) | frames/s (best) "
              "| x real time (best / median) | final pose error; distance |")
        print("|---|---|---|---|---|---|")
        for interval in INTERVALS:
            results = [time_replay(path, interval) for _ in range(repeats)]
            walls = [w for w, _ in results]
            s = results[0][1].summary()
            err = math.hypot(s.pose.x_m - exact.x_m, s.pose.y_m - exact.y_m)
            yaw = abs(wrap_angle(s.pose.theta_rad - exact.theta_rad))
            used = results[0][1].min_interval_s
            label = f"{used * 1e3:g} ms" + (" (default)" if interval is None else "")
            fast, mid = min(walls), statistics.median(walls)
            print(f"| {label} | {s.updates:,} | {fast:.2f} s / {mid:.2f} s "
                  f"| {s.entries / fast / 1e3:.0f} k | {s.duration_s / fast:.1f}x / "
                  f"{s.duration_s / mid:.1f}x | {err * 1e6:.1f} um, {yaw * 1e6:.2f} urad; "
                  f"{s.distance_m:.4f} m (exact {exact_m:.4f} m) |")
    finally:
        if os.path.exists(path):
            os.remove(path)
        os.rmdir(folder)


if __name__ == "__main__":
    main()
