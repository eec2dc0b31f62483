"""Benchmark: what the Zenoh bridge costs the loop, and how fast the deadman stops the robot.

Method.

1. Loop side (in-process, no network): the embedded robot's gateway, enabled against its
   simulators on simulated time; then, N times, what the daemon adds per odometry report with
   a bridge configured: :meth:`gateway.runtime.remote.Remote.post` (build the
   :class:`~gateway.runtime.mailbox.Snapshot` of four wheels, post it to the mailbox); the
   mailbox is emptied by a worker thread as in the daemon.  Wall time per post, median of 5
   repeats of N, beside one cycle of the same run (``Gateway.cycle`` and the two simulator
   steps after it; the ratio is the machine-independent figure).  At the default 50 Hz
   odometry rate and 1 kHz loop this runs once every 20 cycles.
2. Deadman (processes on the loopback): ``wheelgate run --sim`` with a ``bridge:`` block (lease
   ``--lease`` s), an observer session subscribed to the gateway's error key, and a commander
   process that holds a liveliness token and publishes a twist every 50 ms; the commander is
   killed (SIGKILL) or frozen (SIGSTOP) and the time from the signal to the gateway's
   "commander ... disappeared" error at the observer is taken (the robot's target is zero from
   that cycle on); ``--repeats`` times each, median and max.  ``cmd_timeout_s`` is 30 s, so
   nothing else can stop the robot that soon.

Run: ``python tools/bench_bridge.py [--posts N] [--repeats R] [--lease S]`` (needs
``wheelgate[zenoh]`` for part 2).
"""

from __future__ import annotations

import argparse
import os
import signal
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import yaml

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "tools"))

from bridge_peer import free_port, session  # noqa: E402

from gateway.config import load_config  # noqa: E402
from gateway.core.events import OdometryEvent  # noqa: E402
from gateway.core.supervision import Source  # noqa: E402
from gateway.core.types import Twist  # noqa: E402
from gateway.runtime.loop import Gateway  # noqa: E402
from gateway.runtime.mailbox import Mailbox  # noqa: E402
from gateway.runtime.remote import Remote  # noqa: E402
from gateway.sim.bus import SimulatedControllers  # noqa: E402
from gateway.sim.registry import simulators_for  # noqa: E402


def loop_side(posts: int) -> None:
    cfg = load_config(None, {"interface": "virtual", "channel": "bench-bridge"})
    gw = Gateway(cfg, stamp_with_cycle_time=True)
    ctl = SimulatedControllers(simulators_for(gw.drives.all_motors()), cfg.bus.channel)
    period = 1.0 / cfg.loop.rate_hz
    t = 0.0

    def cycles(n: int) -> None:
        nonlocal t
        for _ in range(n):
            gw.cycle(t)
            ctl.step(t + period / 2)
            ctl.step(t + period)
            t += period

    try:
        gw.supervisor.enable(t)
        cycles(int(2.0 / period))
        gw.twist(Twist(0.3, 0.1, 0.2), t, Source.SOCKET)
        cycles(int(0.5 / period))
        remote = Remote.__new__(Remote)  # the daemon's Remote, with one mailbox and no network
        remote.gateway = gw
        box: Mailbox[object] = Mailbox()
        remote._mailboxes = [box]
        stop = threading.Event()

        def drain() -> None:
            while not stop.is_set():
                box.take(0.05)

        worker = threading.Thread(target=drain)
        worker.start()
        event = OdometryEvent(gw.odometry.state)
        post_us, cycle_us = [], []
        for _ in range(5):
            t0 = time.perf_counter()
            for _ in range(posts):
                remote.post((event,), 0.0)
            post_us.append((time.perf_counter() - t0) / posts * 1e6)
            t0 = time.perf_counter()
            cycles(posts)
            cycle_us.append((time.perf_counter() - t0) / posts * 1e6)
        stop.set()
        worker.join()
    finally:
        ctl.shutdown()
        gw.close()
    p, c = statistics.median(post_us), statistics.median(cycle_us)
    print(f"loop side: Remote.post {p:.1f} us per odometry report (median of 5 x {posts}); "
          f"one cycle with its two simulator steps {c:.1f} us; ratio {p / c:.3f}; at "
          f"50 Hz odometry in a 1 kHz loop: {p / c / 20:.4f} of the loop's time")


def deadman(repeats: int, lease_s: float) -> None:
    try:
        import zenoh  # noqa: F401, PLC0415 - part 2 needs it
    except ImportError:
        print("deadman: skipped, eclipse-zenoh not installed (pip install 'wheelgate[zenoh]')")
        return
    port = free_port()
    folder = Path(tempfile.mkdtemp(prefix="wgbb", dir="/tmp"))
    raw = yaml.safe_load((REPO / "gateway" / "data" / "default.yaml").read_text())
    raw["gateway"] = {"socket": str(folder / "s.sock"), "cmd_timeout_s": 30.0}
    raw["bridge"] = {"zenoh": {"listen": [f"tcp/127.0.0.1:{port}"], "lease_s": lease_s},
                     "namespace": "bench"}
    (folder / "robot.yaml").write_text(yaml.safe_dump(raw))
    gw = subprocess.Popen([sys.executable, "-m", "gateway", "run", "--sim", "-c",
                           str(folder / "robot.yaml")], cwd=REPO,
                          stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    connect = f"tcp/127.0.0.1:{port}"
    try:
        time.sleep(3.0)
        obs = session(connect, lease_s)
        seen: list[tuple[float, bytes]] = []
        sub = obs.declare_subscriber("wheelgate/bench/error",
                                     lambda s: seen.append((time.monotonic(),
                                                            s.payload.to_bytes())))
        results: dict[str, list[float]] = {"SIGKILL": [], "SIGSTOP": []}
        for k in range(repeats):
            for sig in (signal.SIGKILL, signal.SIGSTOP):
                name = f"c{k}{sig.name.lower()}"
                cmd = subprocess.Popen(
                    [sys.executable, str(REPO / "tools" / "bridge_peer.py"), "commander",
                     "--connect", connect, "--ns", "bench", "--name", name, "--vx", "0.2",
                     "--lease", str(lease_s)], cwd=REPO, stdout=subprocess.PIPE)
                assert cmd.stdout is not None
                cmd.stdout.readline()
                time.sleep(1.0)
                t0 = time.monotonic()
                os.kill(cmd.pid, sig)
                end = t0 + lease_s + 10
                got = None
                while got is None and time.monotonic() < end:
                    got = next((t for t, p in seen if t >= t0 and name.encode() in p), None)
                    time.sleep(0.001)
                if sig is signal.SIGSTOP:
                    os.kill(cmd.pid, signal.SIGCONT)
                os.kill(cmd.pid, signal.SIGKILL)
                cmd.wait()
                results[sig.name].append(float("nan") if got is None else (got - t0) * 1e3)
        sub.undeclare()
        obs.close()
    finally:
        gw.send_signal(signal.SIGTERM)
        gw.wait(20)
    for name, ms in results.items():
        print(f"deadman after {name}: median {statistics.median(ms):.1f} ms, max {max(ms):.1f} ms"
              f" over {len(ms)} (lease {lease_s:g} s; cmd_timeout_s 30 s)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--posts", type=int, default=2000)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--lease", type=float, default=1.0)
    args = parser.parse_args()
    print(" ".join(__doc__.split("\n\n")[2:5]).replace("\n", " "), flush=True)
    loop_side(args.posts)
    deadman(args.repeats, args.lease)


if __name__ == "__main__":
    main()
