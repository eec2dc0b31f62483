"""No floating-point noise in human output (issue 17): the inputs that printed ``e-17`` or
``-0.00`` print round numbers now, and ``--json`` keeps the full precision."""

from __future__ import annotations

import json
import re
from typing import TYPE_CHECKING, Any, ClassVar

import pytest

from gateway.apps.replay.mcap_report import pose_text
from gateway.cli import main
from gateway.cli.commands import status as status_command
from gateway.cli.commands.twist import following
from gateway.core.kinematics.odometry import OdometryState, Pose
from gateway.core.types import Twist
from gateway.wire.socket.status import status_to_json
from tests.conftest import CONFIG_DIR
from tests.wire.status_samples import sample_status

if TYPE_CHECKING:
    from click.testing import CliRunner

MECANUM = str(CONFIG_DIR / "mecanum.yaml")
CASTOR = str(CONFIG_DIR / "differential_castor.yaml")
#: What the noise looked like: an exponent, or a minus sign before a zero.
NOISE = re.compile(r"\de[-+]?\d|-0(?:\.0+)?(?![\d.])")
#: Least-squares leftovers where zero is meant.
TINY = -2.7755575615628914e-17


def quiet(text: str) -> str:
    """``text``, failing on any noisy number in it."""
    found = NOISE.findall(text)
    assert not found, f"noise {found} in:\n{text}"
    return text


def test_the_noise_pattern_finds_what_was_printed() -> None:
    for noisy in ("vy=-2.776e-17 m/s", "-0.0000     -0.00", "swivel -0.0000 rad/s", "+1.388e-17",
                  "residual -0 m/s"):
        assert NOISE.search(noisy), noisy
    for clean in ("vy=0 m/s", "-0.038", "-1206.43", "+0.0000 rad", "-0.5 m/s", "0.00"):
        assert not NOISE.search(clean), clean


@pytest.mark.parametrize("args", [
    ["-c", MECANUM, "--vx", "0.5", "--vy", "0.5", "--wz", "0"],  # two wheels at -0.0000 rad/s
    ["-c", str(CONFIG_DIR / "omni3.yaml"), "--vx", "-0.5"],  # one wheel at -0.0000 rad/s
    ["-c", CASTOR, "--wz", "1"],  # castor -0.0000 rad/s, -0.00 rpm
    ["-c", CASTOR, "--vx", "0.5"],  # castor swivel -0.0000 rad/s
])
def test_ik_text(runner: CliRunner, args: list[str]) -> None:
    result = runner.invoke(main, ["ik", *args])
    assert result.exit_code == 0, result.output
    quiet(result.stdout)


def test_ik_castor_at_rest_reads_zero(runner: CliRunner) -> None:
    result = runner.invoke(main, ["ik", "-c", CASTOR, "--wz", "1"])
    castor = next(ln for ln in result.stdout.splitlines() if ln.lstrip().startswith("castor"))
    assert castor.split()[1:3] == ["0.0000", "0.00"]
    doc = json.loads(runner.invoke(main, ["ik", "-c", CASTOR, "--wz", "1", "--json"]).stdout)
    speed = next(w for w in doc["wheels"] if w["name"] == "castor")["speed_rad_s"]
    assert speed != 0.0 and abs(speed) < 1e-12  # the JSON keeps what the solve gave


def test_infeasible_twist_message_and_json(runner: CliRunner) -> None:
    args = ["ik", "-c", CASTOR, "--vx", "0.1", "--vy", "0.1", "--wz", "0.3"]
    result = runner.invoke(main, args)
    assert result.exit_code == 3
    assert "nearest feasible twist is (vx=0.1 m/s, vy=0 m/s, wz=0.3 rad/s)" in result.stderr
    quiet(result.stderr)
    doc = json.loads(runner.invoke(main, [*args, "--json"]).stdout)
    assert doc["error"]["nearest"]["vy_m_s"] == pytest.approx(TINY, abs=1e-18)
    assert doc["error"]["nearest"]["vy_m_s"] != 0.0


def test_fk_text_and_json(runner: CliRunner) -> None:
    wheels = [f"--wheel={w}=1" for w in ("front_left", "front_right", "rear_left", "rear_right")]
    result = runner.invoke(main, ["fk", "-c", MECANUM, *wheels])
    assert result.exit_code == 0, result.output
    lines = quiet(result.stdout).splitlines()
    assert lines[0] == "twist: (vx=0.076 m/s, vy=0 m/s, wz=0 rad/s)"
    assert lines[1].startswith("residual: 0 m/s")
    assert lines[2] == "  front_left   measured +1.0000 rad/s, residual +0 m/s"
    doc = json.loads(runner.invoke(main, ["fk", "-c", MECANUM, *wheels, "--json"]).stdout)
    assert 0.0 < doc["residual_m_s"] < 1e-15  # full precision
    assert 0.0 < abs(doc["twist"]["wz_rad_s"]) < 1e-15


class _Client:
    """A daemon that answers ``status`` with :attr:`reply`."""

    reply: ClassVar[dict[str, Any]] = {}

    def __init__(self, path: str, timeout_s: float = 2.0) -> None:
        pass

    def __enter__(self) -> _Client:
        return self

    def __exit__(self, *exc: object) -> None:
        pass

    def request(self, payload: dict[str, object]) -> dict[str, Any]:
        return self.reply


def test_status_text_and_json(runner: CliRunner, monkeypatch: pytest.MonkeyPatch) -> None:
    noisy = sample_status(odometry=OdometryState(Pose(-1e-17, TINY, -0.00001),
                                                 Twist(-0.0001, TINY, -1e-17), 0.0, 0.5, 1.0))
    monkeypatch.setattr(status_command, "ControlClient", _Client)
    _Client.reply = {"ok": True, "id": 1, **status_to_json(noisy)}
    result = runner.invoke(main, ["status", "--socket", "/s"])
    assert result.exit_code == 0, result.output
    odometry = next(ln for ln in result.stdout.splitlines() if ln.startswith("odometry:"))
    assert quiet(odometry).startswith(
        "odometry: x=0.0000 m y=0.0000 m theta=0.0000 rad v=(0.000, 0.000, 0.000)")
    doc = json.loads(runner.invoke(main, ["status", "--socket", "/s", "--json"]).stdout)
    assert doc["odometry"]["y"] == TINY and doc["odometry"]["vx"] == -0.0001


def test_twist_reply_and_odom_pose() -> None:
    reply = {"ok": True, "applied": {"vx_m_s": 0.1, "vy_m_s": TINY, "wz_rad_s": -1e-17},
             "projected": True}
    assert following(reply, {"vx_m_s": 0.1, "vy_m_s": 0.1, "wz_rad_s": 0.0}) == (
        "ok: following vx 0.1 m/s, vy 0 m/s, wz 0 rad/s (the nearest feasible twist to the "
        "one asked)")
    assert pose_text(Pose(1.25, TINY, -1e-17)) == (
        "x +1.2500 m, y +0.0000 m, theta +0.0000 rad (+0.00 deg)")
