"""``wheelgate status`` reads the reply into the status model: its text from the model's
fields, ``--json`` the reply's own JSON, and a precise error for a malformed reply."""

from __future__ import annotations

import copy
import dataclasses
import json
from typing import TYPE_CHECKING, Any, ClassVar

import pytest

import gateway.cli.commands.status as status_command
from gateway.cli import main
from gateway.cli.commands.status import status_lines
from gateway.core.status import MotorReport
from gateway.core.types import DriveFault, DriveState
from tests.wire.status_samples import sample_status
from tests.wire.test_status_format import SAMPLE_JSON

if TYPE_CHECKING:
    from click.testing import CliRunner

SAMPLE_LINES = [
    "robot: tb3  state: running  config: /etc/wheelgate/robot.yaml",
    "odometry: x=1.0000 m y=-0.5000 m theta=0.2500 rad v=(0.100, 0.000, 0.250) slip=0.0010 m/s "
    "distance=2.500 m",
    "  left         node 1    enabled   age    2.0 ms  stop configured 0.25 s (confirmed) "
    "no faults ",
    "  right        node 2    fault     age         -  stop none                      "
    "over_temperature, encoder MOTOR_OVERTEMP",
    "tracking: worst error 0.25 of the window (1 rad/s + 20 % of the command, 0.5 s)",
    "timing: 2000 cycles, 1 missed (late starts: on CPU 1, runnable 0, asleep 0); lateness "
    "p50/p99/max 12/80/120 us; cost p50/p99/max 150/400/700 us; longest gap between bursts "
    "8.5 ms",
    "counters: VescDriver.below minimum ERPM=3, cycles=2000, faults=1, frames_received=3900, "
    "frames_sent=4000",
    "bus: virtual:wheelgate controller active; 2 error frames (no_ack=2), last: no ACK",
    "last error: motor 'right' (odrive node 2) faulted",
]


def test_the_text_is_read_from_the_model() -> None:
    assert status_lines(sample_status()) == SAMPLE_LINES


def test_the_text_of_a_quiet_steering_robot() -> None:
    status = sample_status(reason="e-stop requested", last_error=None, config=None)
    tracking = status.tracking
    assert tracking is not None
    actuator = MotorReport("front steering", 5, DriveState.ENABLED, DriveFault.NONE, "", 0.001,
                           0.1, 0.0, None)
    status = dataclasses.replace(
        status, motors=(*status.motors, actuator), timing=dataclasses.replace(
            status.timing, late_on_cpu=0, burst_gap_max_ms=None),
        tracking=dataclasses.replace(tracking, steer_worst_ratio=0.5))
    lines = status_lines(status)
    assert lines[0] == "robot: tb3  state: running (e-stop requested)"  # no config: not said
    assert lines[4] == ("  front steering node 5    enabled   age    1.0 ms  "
                        + " " * 30 + " no faults ")
    # steer_worst_ratio is the worst angle error over the tolerance: 0.5 * 0.2 rad.
    assert lines[5].endswith("0.5 s); steering off by up to 0.10 rad (tolerance 0.2 rad)")
    assert lines[6].endswith("cost p50/p99/max 150/400/700 us")
    assert not any(line.startswith("last error") for line in lines)


class FakeClient:
    """Answers every request with :attr:`reply`."""

    reply: ClassVar[dict[str, Any]] = {}

    def __init__(self, path: str, timeout_s: float = 2.0) -> None:
        self.path = path

    def __enter__(self) -> FakeClient:
        return self

    def __exit__(self, *exc: object) -> None:
        pass

    def request(self, payload: dict[str, object]) -> dict[str, Any]:
        assert payload == {"op": "status"}
        return copy.deepcopy(self.reply)


@pytest.fixture
def fake(monkeypatch: pytest.MonkeyPatch) -> type[FakeClient]:
    monkeypatch.setattr(status_command, "ControlClient", FakeClient)
    return FakeClient


def test_text_and_json_from_a_reply(runner: CliRunner, fake: type[FakeClient]) -> None:
    fake.reply = {"ok": True, "id": 1, **SAMPLE_JSON}
    result = runner.invoke(main, ["status", "--socket", "/s"])
    assert result.exit_code == 0, result.output
    assert result.stdout.splitlines() == SAMPLE_LINES
    result = runner.invoke(main, ["status", "--socket", "/s", "--json"])
    assert result.exit_code == 0, result.output
    assert result.stdout == json.dumps(SAMPLE_JSON) + "\n"  # the payload, key order included


def test_a_reply_of_an_older_daemon(runner: CliRunner, fake: type[FakeClient]) -> None:
    doc = copy.deepcopy(SAMPLE_JSON)
    del doc["tracking"]
    del doc["timing"]["burst_gap_max_ms"]
    for key in ("healthy", "error_state", "error_frames", "last_error_frame"):
        del doc["bus"][key]
    fake.reply = {"ok": True, "id": 1, **doc}
    result = runner.invoke(main, ["status", "--socket", "/s"])
    assert result.exit_code == 0, result.output
    assert result.stdout.splitlines() == [
        line.replace("; longest gap between bursts 8.5 ms", "")
        for line in SAMPLE_LINES if not line.startswith(("tracking:", "bus:"))]
    # --json prints what the model holds: the keys the daemon did not send stay out
    result = runner.invoke(main, ["status", "--socket", "/s", "--json"])
    assert json.loads(result.stdout) == doc


def test_a_malformed_reply_names_the_key(runner: CliRunner, fake: type[FakeClient]) -> None:
    doc = copy.deepcopy(SAMPLE_JSON)
    doc["motors"][1]["state"] = "melted"
    fake.reply = {"ok": True, "id": 1, **doc}
    result = runner.invoke(main, ["status", "--socket", "/s", "--json"])
    assert result.exit_code == 1
    assert result.stdout == ""
    assert ('status.motors[1].state: expected one of "offline", "disabled", "enabling", '
            '"enabled", "fault", got "melted"') in result.stderr


def test_a_refusal_is_an_error(runner: CliRunner, fake: type[FakeClient]) -> None:
    fake.reply = {"ok": False, "id": 1, "error": {"code": "bad_command", "message": "no"}}
    result = runner.invoke(main, ["status", "--socket", "/s"])
    assert result.exit_code == 1
    assert "no" in result.stderr
