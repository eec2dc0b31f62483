"""The ``socketcan`` tier for ``wheelgate init --from-scan``: simulated controllers as a process
of their own on a kernel CAN interface, ``wheelgate scan --json`` finds them, ``wheelgate init``
gives their node IDs to the example's wheels, and ``wheelgate check`` accepts the file.

The simulators run with node IDs other than the example's, out of order, so the file's node IDs
can only have come from the scan: the lowest goes to the first wheel, and drive motors come
before steering actuators.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
import time
from typing import TYPE_CHECKING, Any

import can
import pytest
import yaml
from click.testing import CliRunner

from gateway.cli import main
from tests.conftest import CONFIG_DIR
from tests.socketcan_helpers import SIM_RATE_HZ, START_S, Lines, tier_config

if TYPE_CHECKING:
    from pathlib import Path

pytestmark = [pytest.mark.socketcan, pytest.mark.timeout(900)]

#: Seconds the scan listens and asks: generous, the emulated VM is about 14 times slower.
SCAN_S = 20.0

#: Per case: the example, the node IDs the simulators take (by block, in file order), the
#: node IDs init must give them (the same blocks), the simulators' step rate.  One case, for
#: the tier's time in the emulated VM (about 100 s a case): a drive motor and a steering
#: actuator found by boot-up, their nodes in the other order than the blocks' (CANopen); the
#: ODrive, VESC and DJI scans over a kernel bus are test_socketcan_scan.py's, the mapping of
#: every driver's nodes the fast tests' (tests/apps/test_init_scan.py).
CASES: dict[str, dict[str, Any]] = {
    # CANopen nodes show themselves by boot-up (heartbeats start only when the gateway sets
    # them): the test resets them (NMT) while the scan listens, as a power cycle would.
    "cia402": {"example": "tricycle", "sim": {"motors.front": 9, "steering.front": 4},
               "init": {"motors.front": 4, "steering.front": 9}},
}


def gateway(vcan: str, *args: str) -> list[str]:
    return [sys.executable, "-m", "gateway", "--interface", "socketcan", "--channel", vcan, *args]


def node_ids(raw: dict[str, Any], blocks: dict[str, int]) -> dict[str, int]:
    """The node IDs of the blocks named ``motors.<wheel>`` / ``steering.<name>``."""
    return {key: raw[key.split(".")[0]][key.split(".")[1]]["node_id"] for key in blocks}


def with_nodes(path: Path, blocks: dict[str, int]) -> None:
    raw = yaml.safe_load(path.read_text())
    for key, node_id in blocks.items():
        section, name = key.split(".")
        raw[section][name]["node_id"] = node_id
    path.write_text(yaml.safe_dump(raw, sort_keys=False))


def reset_canopen_nodes(vcan: str, scan: subprocess.Popen[str], until: float) -> None:
    """NMT reset communication to every node, every second while the scan runs: each node
    answers with a boot-up (its output is a few kilobytes at the end: no pipe fills)."""
    with can.Bus(interface="socketcan", channel=vcan) as bus:
        while scan.poll() is None and time.monotonic() < until:
            bus.send(can.Message(arbitration_id=0x000, data=[0x82, 0], is_extended_id=False))
            time.sleep(1.0)


@pytest.mark.parametrize("case", sorted(CASES))
def test_init_from_a_scan_of_the_bus_writes_a_file_check_accepts(
        case: str, vcan: str, tmp_path: Path) -> None:
    spec = CASES[case]
    config = tier_config(CONFIG_DIR / f"{spec['example']}.yaml", tmp_path / "sim.yaml")
    with_nodes(config, spec["sim"])
    sim = subprocess.Popen(
        gateway(vcan, "sim", "-c", str(config), "--json", "--every", "0", "--rate",
                str(SIM_RATE_HZ)),
        stdout=subprocess.PIPE, stderr=subprocess.DEVNULL)
    try:
        assert sim.stdout is not None
        out = Lines(sim.stdout)
        while out.next(START_S)["event"] != "ready":
            pass
        scan = subprocess.Popen(gateway(vcan, "scan", "--json", "--timeout", str(SCAN_S)),
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        if case == "cia402":  # while the scan runs (its start-up takes seconds in the VM)
            reset_canopen_nodes(vcan, scan, time.monotonic() + START_S + SCAN_S)
        found, err = scan.communicate(timeout=START_S + SCAN_S)
        assert scan.returncode == 0, err
    finally:
        sim.terminate()
        sim.wait(timeout=60)
        if sim.stdout is not None:
            sim.stdout.close()
    rows = json.loads(found)
    assert {(r["driver"], r["node_id"]) for r in rows if r["node_id"] is not None} >= {
        (case, n) for n in spec["sim"].values()}, found
    saved = tmp_path / "scan.json"
    saved.write_text(found)
    robot = tmp_path / "robot.yaml"
    # init and check read and write files only: they run in this process (a process start
    # costs about ten seconds of imports in the emulated VM).
    init = CliRunner().invoke(main, ["init", "--drive", spec["example"], "--from-scan",
                                     str(saved), "-o", str(robot)])
    assert init.exit_code == 0, init.output
    for key, node_id in spec["init"].items():
        assert re.search(rf"^  {re.escape(key)} +{case} node {node_id}$", init.stdout,
                         re.MULTILINE), init.stdout
    assert node_ids(yaml.safe_load(robot.read_text()), spec["init"]) == spec["init"]
    check = CliRunner().invoke(main, ["check", "-c", str(robot)])
    assert check.exit_code == 0, check.output
    assert check.stdout.splitlines()[-1].startswith("ok")
