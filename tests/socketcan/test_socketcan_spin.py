"""The ``socketcan`` tier of ``wheelgate spin``: the simulated controllers as a process of their
own (``wheelgate sim``, started with the robot's *true* configuration), spin as another, given
a configuration with a mistake in it, on a kernel CAN interface.

The encoder cannot see a wrong ``invert`` or ``gear_ratio`` (wheelgate converts the command and
the feedback through both), so spin asks the operator what the wheel did; here the test is the
operator, and answers from the true shaft angles ``wheelgate sim`` reports.
"""

from __future__ import annotations

import json
import math
import signal
import subprocess
import sys
import time
from typing import TYPE_CHECKING, Any

import pytest
import yaml

from tests.conftest import CONFIG_DIR, REPO
from tests.socketcan_helpers import SIM_RATE_HZ, START_S, Lines, tier_config

if TYPE_CHECKING:
    from pathlib import Path

pytestmark = [pytest.mark.socketcan, pytest.mark.timeout(900)]

#: What spin asks once the wheel has turned.
QUESTION = "What did {name} do?"


class Sim:
    """``wheelgate sim`` on ``vcan`` with the true configuration."""

    def __init__(self, config: Path, vcan: str, log: Path) -> None:
        self._err = log.open("wb")
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "gateway", "--interface", "socketcan", "--channel", vcan,
             "sim", "-c", str(config), "--json", "--every", "0", "--rate", str(SIM_RATE_HZ)],
            stdout=subprocess.PIPE, stderr=self._err, cwd=REPO)
        assert self.proc.stdout is not None
        self.out = Lines(self.proc.stdout)
        while self.out.next(START_S)["event"] != "ready":
            pass

    def device(self, name: str) -> dict[str, Any]:
        """A device's true state now (SIGUSR1 -> a state line)."""
        self.proc.send_signal(signal.SIGUSR1)
        while (line := self.out.next(60.0))["event"] != "state":
            pass
        found: dict[str, Any] = next(d for d in line["devices"] if d["name"] == name)
        return found

    def close(self) -> None:
        self.proc.send_signal(signal.SIGTERM)
        try:
            self.proc.wait(timeout=60)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        assert self.proc.stdout is not None
        self.proc.stdout.close()
        self._err.close()


def spin_as_operator(sim: Sim, config: Path, vcan: str, name: str, log: Path
                     ) -> tuple[int, dict[str, Any], float]:
    """Run spin on ``name``; when it asks, answer the turns the true wheel made.

    :return: spin's exit status, its JSON verdict, and the true turn (rad).
    """
    before = sim.device(name)["wheel_rad"]
    with log.open("wb") as err:
        proc = subprocess.Popen(
            [sys.executable, "-m", "gateway", "--interface", "socketcan", "--channel", vcan,
             "spin", "-c", str(config), name, "--duration", "3", "--json"],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=err, cwd=REPO)
        try:
            end = time.monotonic() + 2 * START_S
            while QUESTION.format(name=name) not in log.read_text(errors="replace"):
                assert proc.poll() is None, log.read_text(errors="replace")
                assert time.monotonic() < end, log.read_text(errors="replace")
                time.sleep(0.5)
            turned = sim.device(name)["wheel_rad"] - before
            out, _ = proc.communicate(f"{turned / math.tau:.4f}\n".encode(), timeout=START_S)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
    text = out.decode().strip()
    assert text, log.read_text(errors="replace")
    return proc.returncode, json.loads(text.splitlines()[-1]), turned


def variant(source: Path, dest: Path, sock: Path, **keys: dict[str, Any]) -> Path:
    """The tier configuration with motor keys replaced, and a socket nobody listens on."""
    raw = yaml.safe_load(source.read_text())
    raw.setdefault("gateway", {})["socket"] = str(sock)
    for wheel, block in keys.items():
        raw["motors"][wheel].update(block)
    dest.write_text(yaml.safe_dump(raw, sort_keys=False))
    return dest


def test_spin_advises_invert_and_gear_ratio_against_a_separate_simulator(
        vcan: str, tmp_path: Path, sock_dir: Path) -> None:
    # The true robot: right is inverted, both wheels direct (gear_ratio 1).
    true = tier_config(CONFIG_DIR / "turtlebot3_burger.yaml", tmp_path / "true.yaml")
    nobody = sock_dir / "nobody.sock"
    sim = Sim(true, vcan, tmp_path / "sim.err")
    try:
        wrong_invert = variant(true, tmp_path / "invert.yaml", nobody,
                               right={"invert": False})
        code, doc, turned = spin_as_operator(sim, wrong_invert, vcan, "right",
                                             tmp_path / "spin1.err")
        log = (tmp_path / "spin1.err").read_text()
        assert code == 4, log
        assert turned < -1.0  # the true wheel turned backwards
        assert doc["measured"]["ratio"] == pytest.approx(1.0, abs=0.15)  # the encoder agreed
        assert [f["check"] for f in doc["findings"]] == ["invert"], doc
        assert doc["findings"][0]["advice"].endswith("set invert: true on right")
        assert "stop sent (zero and disarm)" in log
        assert sim.device("right")["armed"] is False  # the stop reached the controller

        wrong_gear = variant(true, tmp_path / "gear.yaml", nobody, left={"gear_ratio": 4.0})
        code, doc, turned = spin_as_operator(sim, wrong_gear, vcan, "left",
                                             tmp_path / "spin2.err")
        assert code == 4, (tmp_path / "spin2.err").read_text()
        assert [f["check"] for f in doc["findings"]] == ["gear_ratio"], doc
        assert "check gear_ratio on left: 4 would be about 1" in doc["findings"][0]["advice"]

        right = variant(true, tmp_path / "right.yaml", nobody)
        code, doc, turned = spin_as_operator(sim, right, vcan, "right", tmp_path / "spin3.err")
        assert code == 0, (tmp_path / "spin3.err").read_text()
        assert doc["ok"] and doc["findings"] == [] and turned > 1.0
    finally:
        sim.close()
