"""The ``socketcan`` tier's harness: ``wheelgate sim`` and ``wheelgate run`` as two processes
on a kernel CAN interface, recorded with ``candump``, driven through the control socket and
through CAN twist frames.

The tier runs in CI inside an emulated VM about 14 times slower than the host, so the test
configurations lower the loop rate and lengthen every liveness and enable timeout; the checks
judge what reached the bus and the simulated wheels, never how fast.
"""

from __future__ import annotations

import json
import math
import os
import select
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import IO, Any

import yaml

from gateway.runtime.client import ClientError, ControlClient

#: Generous bounds for the emulated VM: process start (imports take ~10 s there), enabling.
START_S = 180.0
#: Where the tier runs in the emulated VM (the VM script sets VCANVM=1).
IN_VM = os.environ.get("VCANVM") == "1"
#: The simulators' step rate: 1 kHz on a host, 250 Hz in the VM, where a simulator process
#: stepping at 1 kHz takes a whole emulated CPU and slows the gateway beside it.  The step rate
#: only quantizes when a device sends (each sends at its own configured rates: the logs the
#: end-to-end tier records are the same size at either rate); a DJI ESC reports every step.
SIM_RATE_HZ = 250.0 if IN_VM else 1000.0


def tier_config(source: Path, dest: Path, rate_hz: float = 100.0,
                liveness_s: float = 3.0, driver: str = "", max_rpm: float = 0.0) -> Path:
    """A shipped configuration made fit for the tier: a lower loop rate, long liveness and
    enable timeouts, a longer command timeout, no tracking-error check (it judges speed under
    a CPU 14 times slower), written to ``dest``.

    :param liveness_s: the motors' liveness timeout.  A speed loop closed on the host (DJI)
        integrates over at most this long between two feedback frames: keep it short there.
    :param max_rpm: faster drive motors than the shipped ones (0: as shipped), the robot's
        speed limits raised in proportion: a test that drives a path takes less time.
    """
    raw: dict[str, Any] = yaml.safe_load(source.read_text())
    gateway = raw.setdefault("gateway", {})
    gateway.update(rate_hz=rate_hz, enable_timeout_s=60.0, cmd_timeout_s=1.5,
                   tracking_time_s=0.0, odom_rate_hz=20.0, status_rate_hz=5.0)
    for block in ("motor_defaults", "steering_defaults"):
        if block in raw or (block == "steering_defaults" and "steering" in raw):
            raw.setdefault(block, {})["liveness_s"] = liveness_s
    if "motor_defaults" not in raw:
        raw["motor_defaults"] = {"liveness_s": liveness_s}
    # The controllers' own timeouts (a watchdog the gateway sets, or a stated one): 1 s, since
    # the gateway's cycles in the VM are late by tens of milliseconds at times.  (DJI ESCs have
    # none.)
    blocks = [raw.get("motor_defaults"), raw.get("steering_defaults"),
              *(raw.get("steering") or {}).values()]
    for block in blocks:
        if isinstance(block, dict) and "controller_timeout_s" in block:
            block["controller_timeout_s"] = max(float(block["controller_timeout_s"]), 1.0)
    if max_rpm:
        factor = max_rpm / float(raw["motor_defaults"]["max_rpm"])
        raw["motor_defaults"]["max_rpm"] = max_rpm
        for key in ("max_linear_m_s", "max_angular_rad_s"):
            if key in raw.get("limits", {}):
                raw["limits"][key] *= factor
    if driver:  # the drive motors on another protocol than the shipped one
        defaults = raw["motor_defaults"]
        for key in ("firmware", "watchdog_endpoints", "flat_endpoints", "controller_timeout_s"):
            defaults.pop(key, None)  # the shipped protocol's own keys
        defaults["driver"] = driver
        defaults["controller_timeout_s"] = 1.0
    every = [b for b in (raw.get("motor_defaults"), raw.get("steering_defaults"),
                         *(raw.get("motors") or {}).values(),
                         *(raw.get("steering") or {}).values()) if isinstance(b, dict)]
    for keys in every:
        # CiA 402: the enable sequence's wait for each answer, 0.5 s by default, is shorter
        # than a stall of the VM's simulator process under load.
        if keys.get("driver") == "cia402":
            keys["response_timeout_s"] = 5.0
        # A DBC file is named relative to the configuration: keep pointing at the shipped one.
        if isinstance(keys.get("dbc"), str):
            keys["dbc"] = str((source.parent / keys["dbc"]).resolve())
    dest.write_text(yaml.safe_dump(raw, sort_keys=False))
    return dest


class Lines:
    """Lines of a child's stdout (JSON or text), read without blocking past a timeout."""

    def __init__(self, stream: IO[bytes]) -> None:
        self.fd = stream.fileno()
        self.buf = b""

    def text(self, timeout_s: float) -> str:
        end = time.monotonic() + timeout_s
        while b"\n" not in self.buf:
            left = end - time.monotonic()
            ready, _, _ = select.select([self.fd], [], [], max(left, 0.0))
            if not ready:
                raise AssertionError(f"no line within {timeout_s} s")
            chunk = os.read(self.fd, 65536)
            if not chunk:
                raise AssertionError("the process closed its output")
            self.buf += chunk
        line, self.buf = self.buf.split(b"\n", 1)
        return line.decode()

    def next(self, timeout_s: float) -> dict[str, Any]:
        parsed: dict[str, Any] = json.loads(self.text(timeout_s))
        return parsed


#: candump's socket receive buffer, bytes.
CANDUMP_BUFFER = 8 << 20


class Session:
    """``wheelgate sim`` and ``wheelgate run`` on ``vcan``, and optionally ``candump -L``.

    :param config: the tier configuration.
    :param vcan: the kernel CAN interface.
    :param sock: the control socket (on a tmpfs: not on the VM's shared folder).
    :param record: where ``candump -L`` writes the session, if wanted.
    :param sim_rate_hz: the simulators' step rate.
    """

    def __init__(self, config: Path, vcan: str, sock: str, record: Path | None = None,
                 sim_rate_hz: float = 1000.0) -> None:
        self.config, self.vcan, self.sock = config, vcan, sock
        # Every process's stderr goes to a file: a pipe nobody reads would block a process that
        # logs more than the pipe holds (a gateway warning about a slow bus, say).
        self.logs = {name: Path(f"{sock}.{name}.err") for name in ("candump", "sim", "run")}
        root = [sys.executable, "-m", "gateway", "--interface", "socketcan", "--channel", vcan]
        self.procs: dict[str, subprocess.Popen[bytes]] = {}
        self._files: list[IO[bytes]] = []
        if record is not None:
            out = record.open("wb")
            self._files.append(out)
            # A receive buffer of 8 MiB (candump -r; as root the kernel's limit does not
            # apply): a candump the loaded VM starves for a second would otherwise lose a
            # node's frames from the default buffer (about 200 frames: CI run 87 lost 1 s of
            # one CiA 402 drive's positions, and the replay drifted by 0.4 m).
            self.procs["candump"] = subprocess.Popen(
                ["candump", "-L", "-r", str(CANDUMP_BUFFER), vcan], stdout=out,
                stderr=self._err("candump"))
        self.procs["sim"] = subprocess.Popen(
            [*root, "sim", "-c", str(config), "--json", "--every", "0", "--rate",
             str(sim_rate_hz)],
            stdout=subprocess.PIPE, stderr=self._err("sim"))
        self.procs["run"] = subprocess.Popen(
            [*root, "run", "-c", str(config), "--socket", sock],
            stdout=subprocess.DEVNULL, stderr=self._err("run"))
        stdout = self.procs["sim"].stdout
        assert stdout is not None
        self.sim_out = Lines(stdout)

    def __enter__(self) -> Session:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _err(self, name: str) -> IO[bytes]:
        f = self.logs[name].open("wb")
        self._files.append(f)
        return f

    def tails(self) -> str:
        """The tail of every process's stderr (for failure messages)."""
        out = []
        for name, proc in self.procs.items():
            text = self.logs[name].read_bytes().decode(errors="replace")[-3000:]
            out.append(f"--- {name} (exit {proc.poll()}):\n{text}")
        return "\n".join(out)

    def wait_ready(self) -> None:
        """Until the simulators announced themselves and the gateway is RUNNING."""
        end = time.monotonic() + START_S
        while (line := self.sim_out.next(START_S))["event"] != "ready":
            pass
        assert line["devices"] > 0
        while not os.path.exists(self.sock):
            assert time.monotonic() < end and self.procs["run"].poll() is None, self.tails()
            time.sleep(0.2)
        while True:
            try:
                state = self.request({"op": "status"})["state"]
            except ClientError:  # the file exists from bind(), the daemon not yet listening
                state = "not listening yet"
            if state == "running":
                break
            assert time.monotonic() < end and self.procs["run"].poll() is None, \
                f"gateway state {state}\n{self.tails()}"
            time.sleep(0.2)

    def request(self, req: dict[str, Any]) -> dict[str, Any]:
        with ControlClient(self.sock, timeout_s=30.0) as client:
            reply: dict[str, Any] = client.request(req)
        return reply

    def truth(self) -> dict[str, Any]:
        """The simulators' true state (SIGUSR1 -> a state line)."""
        self.procs["sim"].send_signal(signal.SIGUSR1)
        while (line := self.sim_out.next(60.0))["event"] != "state":
            pass
        return line

    def odometry(self) -> dict[str, Any]:
        status = self.request({"op": "status"})
        odo: dict[str, Any] = status["odometry"]
        return odo

    def close(self) -> None:
        """Stop the gateway, then the simulators and candump (killed if they linger)."""
        for name in ("run", "sim", "candump"):
            proc = self.procs.get(name)
            if proc is not None:
                stop(proc)
        for proc in self.procs.values():
            for stream in (proc.stdout, proc.stderr):
                if stream is not None:
                    stream.close()
        for f in self._files:
            f.close()


def stop(proc: subprocess.Popen[bytes], timeout_s: float = 60.0) -> None:
    """SIGTERM a process that still runs and wait for it; killed if it lingers."""
    if proc.poll() is not None:
        return
    proc.send_signal(signal.SIGTERM)
    try:
        proc.wait(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()


def pose_error(odo: dict[str, Any], truth: dict[str, Any]) -> float:
    """The distance between the gateway's pose and the true one, m (heading as arc at 1 m)."""
    pose = truth["pose"]
    return math.hypot(odo["x"] - pose["x"], odo["y"] - pose["y"]) + abs(
        math.remainder(odo["theta"] - pose["theta"], math.tau))
