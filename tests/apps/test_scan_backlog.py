"""``wheelgate scan`` on a slow host (:func:`gateway.apps.scan.scanner.scan_bus`): an answer that
came in time but waited in the receive queue is judged by its arrival, not by when the scan got
round to reading it.  (Seen in the socketcan tier: beside a running gateway in the emulated VM,
the ODrive's Get_Version answer was read after the 2 s scan's answer window, and its firmware
went unreported.)"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING, Any

import can
import yaml

from gateway.apps.scan.report import report_json
from gateway.apps.scan.scanner import scan_bus
from gateway.apps.scan.session import ScanTiming
from gateway.config import load_config
from gateway.drive.driveset import DriveSet
from gateway.sim.bus import SimulatedControllers
from gateway.sim.registry import simulators_for
from tests.cli.test_cli_scan import MIXED

if TYPE_CHECKING:
    from pathlib import Path

#: How long the host stalls right after the scan sends the ODrive's Get_Version (s): longer
#: than the answer window of a 2 s scan (0.25 s).
STALL_S = 0.5


class Stalling:
    """A virtual bus whose reader loses the CPU for ``STALL_S`` right after it asks the ODrive
    for its version: the answer, and the other controllers' traffic, wait in the receive queue
    meanwhile, as in a kernel socket's while the emulated VM runs something else."""

    def __init__(self, channel: str) -> None:
        self.bus = can.Bus(interface="virtual", channel=channel)

    def send(self, msg: can.Message) -> None:
        self.bus.send(msg)
        if msg.arbitration_id == 0x020 and msg.is_remote_frame:
            time.sleep(STALL_S)

    def recv(self, timeout: float | None = None) -> can.Message | None:
        return self.bus.recv(timeout)


def test_an_answer_read_late_but_arrived_in_time_counts(tmp_path: Path, channel: str) -> None:
    raw: dict[str, Any] = dict(MIXED, bus={**MIXED["bus"], "channel": channel})
    path = tmp_path / "mixed.yaml"
    path.write_text(yaml.safe_dump(raw))
    config = load_config(path)
    ctl = SimulatedControllers(simulators_for(DriveSet(config).all_motors()), channel)
    reader = Stalling(channel)
    ctl.start()
    try:
        timing = ScanTiming.for_timeout(2.0)
        assert timing.answer_s < STALL_S
        bus: Any = reader
        report = scan_bus(bus, timing, f"virtual:{channel}")
    finally:
        ctl.shutdown()
        reader.bus.shutdown()
    rows = {(r["protocol"], r["node_id"]): r for r in report_json(report)}
    # The ODrive answered at once; the scan read the answer half a second later.
    assert rows[("odrive", 1)]["firmware"] == "0.0.0"
