"""Benchmark: the control loop while local clients abuse the control socket.

Method: for each load, a fresh ``wheelgate run --sim`` daemon (the embedded default robot:
4-wheel mecanum, four simulated ODrives in a thread of the daemon's process, the loop at its
default 200 Hz, normal scheduling) is started in a subprocess with a private socket and state
directory, left to run 2 s, then loaded from this process for the load's duration:

* ``status flood``: one client writes 64 KiB of pipelined ``{"op":"status"}`` lines (4,096
  requests) at once, reading its replies in a thread as they come; the load lasts until the
  last reply arrived (at most 60 s);
* ``twist flood``: one client writes 50,000 pipelined twists (2 MB) at once, reading its
  replies in a thread; the load lasts until the last reply arrived (at most 60 s): the whole
  request budget, every cycle, in the cheapest kind of request;
* ``idle connections``: 1,024 connections that never send a byte are opened (one by one,
  so the daemon accepts them as they come), then a new connection sends ``estop`` and waits
  for its reply (at most 5 s); the idle ones are held for the load's duration;
* ``mute subscribers``: 200 connections subscribe to every topic and never read; the load
  lasts until the daemon has dropped them all (its ``slow_disconnects``, asked once a second;
  at most 60 s);
* ``long lines``: one client sends 30 lines of 60 KB each (with a valid request after them)
  and reads its replies until the valid one's.

Measured, from the daemon's own ``status`` just before and just after the load (a request on
a connection of its own; its ``timing`` and ``counters``) and from ``/proc/PID/statm`` sampled
every 20 ms: the deadlines the loop missed during the load (skipped after an overrun; the
worst lateness of a cycle start in the last 4,096 cycles beside it), the cycles it ran and the
CAN frames it sent per second of the load (a stalled loop sends none), and the daemon's RSS
before the load, at its peak during it and after; then what the load's clients got (replies,
errors, e-stop, drops).  ``--idle`` first runs a window of the same length with no load: the
misses the machine causes on its own.

Run: ``python tools/bench_socket_flood.py [--seconds S] [--idle] [--only NAME ...]`` (default
10 s per load; ``--only`` takes ``status``, ``twists``, ``idle``, ``subscribers``, ``lines``).
The VM's two cores are shared with this process (the load's clients): that is part of what is
measured.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import resource
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from typing import Any

PAGE = os.sysconf("SC_PAGE_SIZE")
STATUS_LINE = b'{"op":"status"}\n'
FLOOD_BYTES = 64 * 1024
IDLE_CONNECTIONS = 1024
SUBSCRIBERS = 200
LONG_LINES = 30
LONG_LINE_BYTES = 60_000
TWISTS = 50_000


def rss_bytes(pid: int) -> int:
    """The resident set of process ``pid``."""
    with open(f"/proc/{pid}/statm", encoding="ascii") as f:
        return int(f.read().split()[1]) * PAGE


def connect(path: str, timeout_s: float = 5.0) -> socket.socket:
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    sock.settimeout(timeout_s)
    sock.connect(path)
    return sock


def read_line(sock: socket.socket, buf: bytearray) -> bytes:
    """The next line on ``sock`` (``buf`` holds what came after it); b"" at end of file."""
    while (newline := buf.find(b"\n")) < 0:
        chunk = sock.recv(65536)
        if not chunk:
            return b""
        buf += chunk
    line = bytes(buf[:newline])
    del buf[: newline + 1]
    return line


def request(path: str, op: str, timeout_s: float = 10.0) -> dict[str, Any]:
    """One request on a connection of its own."""
    with connect(path, timeout_s) as sock:
        sock.sendall(json.dumps({"op": op}).encode() + b"\n")
        line = read_line(sock, bytearray())
    if not line:
        raise ConnectionError(f"{path}: the daemon closed the connection before replying")
    reply: dict[str, Any] = json.loads(line)
    return reply


@dataclass
class Snapshot:
    """The daemon's figures at one moment."""

    t: float
    cycles: int
    missed: int
    frames_sent: int
    lateness_max_us: float
    socket: dict[str, Any]
    state: str

    @classmethod
    def take(cls, path: str) -> Snapshot:
        status = request(path, "status")
        return cls(time.monotonic(), status["timing"]["cycles"], status["timing"]["missed"],
                   status["counters"]["frames_sent"], status["timing"]["lateness_max_us"],
                   status["socket"], status["state"])


class Sampler(threading.Thread):
    """Samples the daemon's RSS every 20 ms."""

    def __init__(self, pid: int) -> None:
        super().__init__(name="rss-sampler", daemon=True)
        self.pid = pid
        self.peak = rss_bytes(pid)
        self.stop = threading.Event()

    def run(self) -> None:
        while not self.stop.wait(0.02):
            with contextlib.suppress(OSError):
                self.peak = max(self.peak, rss_bytes(self.pid))


class DaemonProcess:
    """``wheelgate run --sim`` in a subprocess with a private socket and state directory."""

    def __init__(self) -> None:
        self.folder = tempfile.mkdtemp(prefix="wgflood", dir="/tmp")
        self.path = f"{self.folder}/s.sock"
        env = {**os.environ, "STATE_DIRECTORY": self.folder}
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "gateway", "run", "--sim", "--socket", self.path],
            env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
        )
        deadline = time.monotonic() + 20.0
        while True:
            if self.proc.poll() is not None:
                log = self.proc.stderr.read().decode() if self.proc.stderr else ""
                raise RuntimeError(f"the daemon exited with {self.proc.returncode}: {log}")
            try:
                if request(self.path, "status", 1.0)["state"] == "running":
                    break
            except OSError:
                pass
            if time.monotonic() > deadline:
                raise RuntimeError("the daemon did not reach RUNNING within 20 s")
            time.sleep(0.1)

    def stop(self) -> str:
        """Stop the daemon; its log (stderr)."""
        self.proc.send_signal(signal.SIGTERM)
        try:
            _, err = self.proc.communicate(timeout=20)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            _, err = self.proc.communicate()
        shutil.rmtree(self.folder, ignore_errors=True)
        return err.decode(errors="replace")


@dataclass
class Outcome:
    """What one load did to the daemon and what its clients got."""

    name: str
    seconds: float = 0.0
    before: Snapshot | None = None
    after: Snapshot | None = None
    rss_before: int = 0
    rss_peak: int = 0
    rss_after: int = 0
    notes: list[str] = field(default_factory=list)


# -- the loads ---------------------------------------------------------------------------------


def pipeline(path: str, payload: bytes, count: int, seconds: float) -> tuple[int, int, float]:
    """Send ``count`` request lines at once on one connection while a thread reads the replies.

    :return: ``(replies, replies with "ok": true, seconds until the last reply or the wait's
        end)``.
    """
    replies = ok = 0
    with connect(path) as sock:
        def reader() -> None:
            nonlocal replies, ok
            buf = bytearray()
            sock.settimeout(max(seconds, 60.0) + 5.0)
            with contextlib.suppress(OSError):
                while replies < count:
                    line = read_line(sock, buf)
                    if not line:
                        break
                    ok += json.loads(line).get("ok") is True
                    replies += 1

        thread = threading.Thread(target=reader, daemon=True)
        start = time.monotonic()
        thread.start()
        sock.sendall(payload)
        thread.join(max(seconds, 60.0))
        took = time.monotonic() - start
    return replies, ok, took


def status_flood(path: str, seconds: float, out: Outcome) -> None:
    count = FLOOD_BYTES // len(STATUS_LINE)
    replies, ok, took = pipeline(path, STATUS_LINE * count, count, seconds)
    out.notes.append(f"{replies} of {count} replies in {took:.2f} s"
                     + ("" if ok == replies else " (some not ok)"))


def twist_flood(path: str, seconds: float, out: Outcome) -> None:
    count = TWISTS
    payload = b"".join(b'{"op":"twist","vx":0.1,"wz":0.2,"id":%d}\n' % k
                       for k in range(count))
    replies, ok, took = pipeline(path, payload, count, seconds)
    out.notes.append(f"{replies} of {count} replies ({ok} ok) in {took:.2f} s: "
                     f"{replies / took:.0f} a second")


def idle_connections(path: str, seconds: float, out: Outcome) -> None:
    held: list[socket.socket] = []
    try:
        for _ in range(IDLE_CONNECTIONS):
            held.append(connect(path))
        time.sleep(0.5)  # let the daemon accept the last of them
        start = time.monotonic()
        try:
            reply = request(path, "estop", 5.0)
            result = f"estop reply ok={reply.get('ok')} state={reply.get('state')}"
        except OSError as err:
            result = f"estop failed: {err!r}"
        took = time.monotonic() - start
        out.notes.append(f"{result} after {took * 1000:.1f} ms with {len(held)} held")
        time.sleep(max(0.0, seconds - took - 0.5))
    finally:
        for sock in held:
            sock.close()


def mute_subscribers(path: str, seconds: float, out: Outcome) -> None:
    held: list[socket.socket] = []
    line = b'{"op":"subscribe","topics":["odometry","status","error"]}\n'
    try:
        dropped0 = request(path, "status")["socket"]["slow_disconnects"]
        start = time.monotonic()
        for _ in range(SUBSCRIBERS):
            sock = connect(path)
            sock.sendall(line)
            held.append(sock)
        dropped = 0
        while dropped < SUBSCRIBERS and time.monotonic() - start < max(seconds, 60.0):
            time.sleep(1.0)
            dropped = request(path, "status")["socket"]["slow_disconnects"] - dropped0
        out.notes.append(f"{dropped} dropped by the daemon after {time.monotonic() - start:.1f} s")
        gone = 0
        for sock in held:
            sock.setblocking(False)
            try:
                while sock.recv(1 << 20):
                    pass
                gone += 1  # end of file: dropped
            except BlockingIOError:
                pass
            except ConnectionResetError:
                gone += 1
        out.notes.append(f"{gone} of {SUBSCRIBERS} subscribers saw end of file")
    finally:
        for sock in held:
            sock.close()


def long_lines(path: str, seconds: float, out: Outcome) -> None:
    errors = 0
    last: dict[str, Any] = {}
    with connect(path, seconds + 5.0) as sock:
        start = time.monotonic()
        payload = (b'{"op":"stop","pad":"' + b"x" * (LONG_LINE_BYTES - 24) + b'"}\n') * LONG_LINES
        sender = threading.Thread(target=sock.sendall,
                                  args=(payload + b'{"op":"stop","id":"last"}\n',), daemon=True)
        sender.start()
        buf = bytearray()
        with contextlib.suppress(OSError):
            while (line := read_line(sock, buf)):
                last = json.loads(line)
                if last.get("id") == "last":
                    break
                errors += "too long" in str(last.get("error", {}).get("message", ""))
        sender.join(5.0)
        took = time.monotonic() - start
    out.notes.append(f"{errors} too-long errors, final request answered ok={last.get('ok')} "
                     f"in {took:.2f} s")


def idle_window(path: str, seconds: float, out: Outcome) -> None:
    time.sleep(seconds)


LOADS = {
    "idle-window": idle_window,
    "status": status_flood,
    "twists": twist_flood,
    "idle": idle_connections,
    "subscribers": mute_subscribers,
    "lines": long_lines,
}
TITLES = {
    "idle-window": "no load (the machine alone)",
    "status": "64 KiB of pipelined status, one client",
    "twists": "50,000 pipelined twists, one client",
    "idle": "1,024 idle connections, then estop",
    "subscribers": "200 subscribers that never read",
    "lines": "30 lines of 60 KB",
}


def run_load(name: str, seconds: float) -> Outcome:
    out = Outcome(TITLES[name])
    daemon = DaemonProcess()
    try:
        time.sleep(2.0)
        pid = daemon.proc.pid
        out.before = Snapshot.take(daemon.path)
        out.rss_before = rss_bytes(pid)
        sampler = Sampler(pid)
        sampler.start()
        start = time.monotonic()
        LOADS[name](daemon.path, seconds, out)
        out.seconds = time.monotonic() - start
        sampler.stop.set()
        sampler.join()
        out.rss_peak = sampler.peak
        out.after = Snapshot.take(daemon.path)
        out.rss_after = rss_bytes(pid)
    finally:
        log = daemon.stop()
    out.notes += [f"daemon: {line[-200:]}" for line in log.splitlines()
                  if ("WARNING" in line or "ERROR" in line) and "SIGTERM" not in line]
    return out


def report(out: Outcome) -> None:
    b, a = out.before, out.after
    assert b is not None and a is not None
    span = a.t - b.t
    mib = 1 << 20
    print(f"\n{out.name}  (load {out.seconds:.1f} s; status to status {span:.1f} s)")
    missed = a.missed - b.missed
    print(f"  missed deadlines: {missed} of {a.cycles - b.cycles + missed} (worst lateness in "
          f"the last 4096 cycles: {a.lateness_max_us / 1000:.1f} ms)")
    print(f"  cycles/s: {(a.cycles - b.cycles) / span:.0f}; CAN frames sent/s: "
          f"{(a.frames_sent - b.frames_sent) / span:.0f}")
    print(f"  RSS: {out.rss_before / mib:.1f} MiB before, {out.rss_peak / mib:.1f} peak "
          f"(+{(out.rss_peak - out.rss_before) / mib:.1f}), {out.rss_after / mib:.1f} after")
    counters = {k: v for k, v in a.socket.items() if k != "path" and v != b.socket.get(k)}
    print(f"  socket counters changed: {counters}; state {a.state}")
    for note in out.notes:
        print(f"  {note}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--idle", action="store_true", help="also a window with no load")
    parser.add_argument("--only", nargs="+", choices=[k for k in LOADS if k != "idle-window"])
    args = parser.parse_args()
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    if soft < 4096 and (hard == resource.RLIM_INFINITY or hard >= 4096):
        resource.setrlimit(resource.RLIMIT_NOFILE, (4096, hard))
    names = args.only or [k for k in LOADS if k != "idle-window"]
    if args.idle:
        names = ["idle-window", *names]
    print(f"python {sys.version.split()[0]}, {os.cpu_count()} CPUs; {args.seconds:g} s per load")
    for name in names:
        report(run_load(name, args.seconds))


if __name__ == "__main__":
    main()
