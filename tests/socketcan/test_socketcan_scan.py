"""The ``socketcan`` tier of ``wheelgate scan``: the simulated controllers of every protocol as a
process of their own (``wheelgate sim``) on a kernel CAN interface, the scan as another.

* Beside a running gateway (``wheelgate run``, a third process, which arms the motors and has
  set the CANopen node's heartbeat; the VESC sends status, as a gateway needs it to): every
  controller is found and described, the gateway's messages are named, ``candump`` shows that
  the scan sent reads only (one Get_Version, five SDO uploads, 255 PINGs), and the gateway runs
  on without a fault.
* A node that boots while the scan listens (an NMT reset, as at power-on): the CANopen node is
  found by its boot-up (at factory settings it sends no heartbeat) and its identity read.

The VM is about 14 times slower than the host: long timeouts, and the checks judge what was
found and what reached the bus, never how fast.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from typing import IO, TYPE_CHECKING, Any

import can
import pytest
import yaml

from gateway.runtime.client import ControlClient
from gateway.wire.candump import parse_line
from tests.cli.test_cli_scan import MIXED
from tests.conftest import REPO
from tests.socketcan_helpers import START_S, Lines, stop, tier_config

if TYPE_CHECKING:
    from pathlib import Path

    from gateway.core.types import Frame

pytestmark = [pytest.mark.socketcan, pytest.mark.timeout(1200)]

#: The simulators' step rate: a DJI ESC reports every step (250 Hz in the VM, as the end-to-end
#: tier's DJI robot), and four protocols share one emulated CPU with the gateway.
SIM_RATE_HZ = 250.0


def mixed_config(tmp_path: Path, vesc_status: bool = False) -> Path:
    """The mixed bus (one controller per protocol) fit for the tier: the controllers' own
    timeouts at 1 s, since the gateway's cycles in the VM are late by tens of ms at times.

    :param vesc_status: the VESC sends STATUS and STATUS_5 (which a gateway needs to drive it).
    """
    raw = json.loads(json.dumps(MIXED))
    for name in ("front_left", "front_right"):
        raw["motors"][name]["controller_timeout_s"] = 1.0
    if vesc_status:
        raw["motors"]["front_right"]["status_rate_hz"] = 50
    source = tmp_path / "mixed_source.yaml"
    source.write_text(yaml.safe_dump(raw, sort_keys=False))
    return tier_config(source, tmp_path / "mixed.yaml")


def wheelgate(vcan: str, *args: str) -> list[str]:
    return [sys.executable, "-m", "gateway", "--interface", "socketcan", "--channel", vcan,
            *args]


def rows_of(stdout: str) -> dict[tuple[str, Any], dict[str, Any]]:
    """The scan's JSON rows by (protocol, node); the gateway's messages by (protocol, name)."""
    rows = json.loads(stdout)
    return {(r["protocol"], r["node_id"] if r["node_id"] is not None else r["message"]): r
            for r in rows}


def check_controllers(rows: dict[tuple[str, Any], dict[str, Any]], vesc_seen_by: str,
                      canopen_seen_by: str) -> None:
    odrive, vesc = rows[("odrive", 1)], rows[("vesc", 10)]
    canopen, dji = rows[("canopen", 5)], rows[("dji", 2)]
    assert (odrive["seen_by"], odrive["firmware"], odrive["errors"]) == (
        "heartbeat", "0.0.0", "none")
    assert (vesc["seen_by"], vesc["hardware"]) == (vesc_seen_by, "VESC")
    assert canopen["seen_by"] == canopen_seen_by
    assert canopen["device_type"] == 0x00020192
    assert canopen["identity"] == {"vendor_id": 0, "product_code": 0x402,
                                   "revision": 0x00010000, "serial": 5}
    assert dji["seen_by"] == "feedback" and dji["readings"]["angle_count"] in range(8192)
    assert {r["wheel"] for r in (odrive, vesc, canopen, dji)} == {
        "front_left", "front_right", "rear_left", "rear_right"}


def scan_frames(record: Path) -> list[Frame]:
    """The frames on the bus that only a scan sends: RTR Get_Version to ODrive node 1 (the
    gateway asks with a DLC 0 data frame), SDO frames on 0x605 about 0x1000 or 0x1018 (the
    gateway configures other objects), and anything on the PING identifiers."""
    out = []
    for number, line in enumerate(record.read_text().splitlines(), start=1):
        f = parse_line(line, number).frame
        mux = f.data[1:3] if f.arbitration_id == 0x605 and not f.is_extended_id else b""
        if ((f.arbitration_id == 0x020 and f.is_remote_frame)
                or mux in (b"\x00\x10", b"\x18\x10")
                or (f.is_extended_id and 0x1100 <= f.arbitration_id <= 0x11FF)):
            out.append(f)
    return out


class Bench:
    """``candump -L``, ``wheelgate sim``, and ``wheelgate run`` once the simulators are up (a
    gateway started beside four simulators still importing would give up on them)."""

    def __init__(self, config: Path, vcan: str, sock: str, record: Path, logs: Path) -> None:
        self.sock = sock
        self.files: list[IO[bytes]] = [record.open("wb"), (logs / "sim.err").open("wb"),
                                       (logs / "run.err").open("wb")]
        self.logs = logs
        self.procs = [subprocess.Popen(["candump", "-L", vcan], stdout=self.files[0])]
        sim = subprocess.Popen(wheelgate(vcan, "sim", "-c", str(config), "--json", "--every",
                                         "0", "--rate", str(SIM_RATE_HZ)),
                               stdout=subprocess.PIPE, stderr=self.files[1], cwd=REPO)
        self.procs.append(sim)
        assert sim.stdout is not None
        out = Lines(sim.stdout)
        while out.next(START_S)["event"] != "ready":
            pass
        self.procs.append(subprocess.Popen(wheelgate(vcan, "run", "-c", str(config), "--socket",
                                                     sock),
                                           stdout=subprocess.DEVNULL, stderr=self.files[2],
                                           cwd=REPO))
        end = time.monotonic() + START_S
        while not os.path.exists(sock) or not self.armed():
            assert time.monotonic() < end, self.tails()
            time.sleep(0.5)

    def armed(self) -> bool:
        """Whether the gateway runs with every motor enabled (the CANopen node started)."""
        status = self.status()
        return status["state"] == "running" and all(m["state"] == "enabled"
                                                    for m in status["motors"])

    def status(self) -> dict[str, Any]:
        with ControlClient(self.sock, timeout_s=30.0) as client:
            reply: dict[str, Any] = client.request({"op": "status"})
        return reply

    def tails(self) -> str:
        return "\n".join(f"--- {name}:\n{(self.logs / name).read_text()[-3000:]}"
                         for name in ("sim.err", "run.err"))

    def close(self) -> None:
        for proc in reversed(self.procs):
            stop(proc)
            if proc.stdout is not None:
                proc.stdout.close()
        for f in self.files:
            f.close()


def test_the_scan_beside_a_running_gateway_reads_only(tmp_path: Path, vcan: str,
                                                      sock_dir: Path) -> None:
    config = mixed_config(tmp_path, vesc_status=True)
    record = tmp_path / "bus.log"
    bench = Bench(config, vcan, str(sock_dir / "s.sock"), record, tmp_path)
    try:
        done = subprocess.run(wheelgate(vcan, "scan", "-c", str(config), "--json",
                                        "--timeout", "20"),
                              capture_output=True, text=True, timeout=600, cwd=REPO,
                              check=False)
        assert done.returncode == 0, done.stderr
        time.sleep(2.0)  # the gateway's next status, after every answer
        status = bench.status()
        tails = bench.tails()
    finally:
        bench.close()
    rows = rows_of(done.stdout)
    check_controllers(rows, "status", "heartbeat")  # the gateway set 0x1017 on the node
    assert rows[("odrive", 1)]["state"] == "CLOSED_LOOP_CONTROL"
    assert rows[("canopen", 5)]["state"] == "operational"
    assert ("wheelgate", "WG_Status") in rows
    # The gateway's own CANopen heartbeat (node 127) and SYNC are its, not a node's.
    assert {("wheelgate", "CiA 402 HEARTBEAT"), ("wheelgate", "CiA 402 SYNC")} <= set(rows)
    assert [key for key in rows if key[0] == "canopen"] == [("canopen", 5)]
    assert status["state"] == "running", tails
    assert all(m["faults"] == [] for m in status["motors"]), status["motors"]
    frames = scan_frames(record)
    assert sorted((f.arbitration_id, f.is_remote_frame, f.data) for f in frames) == sorted(
        [(0x020, True, b""),
         (0x605, False, bytes.fromhex("4000100000000000")),
         *((0x605, False, bytes([0x40, 0x18, 0x10, sub, 0, 0, 0, 0])) for sub in (1, 2, 3, 4)),
         *((0x1100 + k, False, b"\xfe") for k in range(255))])


def test_a_node_that_boots_during_the_scan_is_found_by_its_boot_up(
        tmp_path: Path, vcan: str) -> None:
    config = mixed_config(tmp_path)
    log = tmp_path / "sim.err"
    # The simulators come up first (10-20 s in the VM); once the scan listens, an NMT reset
    # (CiA 301 7.2.8.3.1.5, as another master or a power cycle would) reboots the CANopen node,
    # which then sends its boot-up, as at power-on: at factory settings it sends nothing else.
    with log.open("wb") as sim_err:
        sim = subprocess.Popen(wheelgate(vcan, "sim", "-c", str(config), "--json",
                                         "--every", "0", "--rate", str(SIM_RATE_HZ)),
                               stdout=subprocess.PIPE, stderr=sim_err, cwd=REPO)
    assert sim.stdout is not None
    scan: subprocess.Popen[bytes] | None = None
    try:
        ready = Lines(sim.stdout)
        while ready.next(START_S)["event"] != "ready":
            pass
        scan = subprocess.Popen(wheelgate(vcan, "-v", "scan", "-c", str(config), "--json",
                                          "--timeout", "20"),
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=REPO)
        assert scan.stderr is not None and scan.stdout is not None
        err = Lines(scan.stderr)
        while "scan: listening on socketcan:" not in err.text(START_S):
            pass
        with can.Bus(interface="socketcan", channel=vcan) as master:
            master.send(can.Message(arbitration_id=0x000, data=[0x81, 5], is_extended_id=False))
        out, rest = scan.communicate(timeout=600)
    finally:
        stop(sim)
        sim.stdout.close()
        if scan is not None and scan.poll() is None:
            scan.kill()
            scan.wait()
    assert scan.returncode == 0, rest.decode(errors="replace") + log.read_text()
    rows = rows_of(out.decode())
    check_controllers(rows, "pong", "boot-up")
    assert rows[("odrive", 1)]["state"] == "IDLE"
    assert rows[("canopen", 5)]["state"] == "booted (pre-operational)"
    # Nothing unknown; the NMT reset this test sent is named as the gateway's own message
    # (a wheelgate with CiA 402 drives sends NMT commands itself).
    assert [k for k, r in rows.items() if r["protocol"] in ("unknown", "wheelgate")] == [
        ("wheelgate", "CiA 402 NMT")]
