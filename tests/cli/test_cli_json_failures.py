"""``ik``, ``fk`` and ``sim`` with ``--json``: every outcome is JSON on stdout, a failure in
the README's shape (``{"ok": false, "error": {"code", "message", ...}}``, as ``scan``,
``status`` and ``spin`` answer), with the exit code the same failure has without ``--json``,
and nothing on stderr but notes."""

from __future__ import annotations

import json
from typing import TYPE_CHECKING, Any

import pytest

from gateway.cli import main
from gateway.sim.truth import SimTruth
from tests.conftest import CONFIG_DIR

if TYPE_CHECKING:
    from pathlib import Path

    from click.testing import CliRunner, Result

TB3 = str(CONFIG_DIR / "turtlebot3_burger.yaml")


def failure(result: Result) -> dict[str, Any]:
    """The error object of a ``--json`` failure, checked for the shape."""
    assert result.stdout.count("\n") == 1, result.output
    doc = json.loads(result.stdout)
    assert doc["ok"] is False and set(doc) == {"ok", "error"}, doc
    error: dict[str, Any] = doc["error"]
    assert isinstance(error["code"], str) and isinstance(error["message"], str), doc
    return error


@pytest.fixture
def bad(tmp_path: Path) -> str:
    """A configuration ``check`` refuses (a track of -1 m)."""
    path = tmp_path / "bad.yaml"
    path.write_text((CONFIG_DIR / "turtlebot3_burger.yaml").read_text("utf-8").replace(
        "track: 0.160", "track: -1"))
    return str(path)


@pytest.mark.parametrize("args", [
    ["ik", "--vx", "0.1"],
    ["fk", "--wheel", "left=1", "--wheel", "right=1"],
    ["sim", "--every", "0"],
])
def test_a_configuration_it_cannot_load(runner: CliRunner, bad: str, args: list[str]) -> None:
    plain = runner.invoke(main, [args[0], "-c", bad, *args[1:]])
    said = f"{bad}: geometry.track: expected at least 0.001 m, got -1.0"
    assert (plain.exit_code, plain.stdout, plain.stderr) == (2, "", f"Error: {said}\n")
    result = runner.invoke(main, [args[0], "-c", bad, *args[1:], "--json"])
    assert (result.exit_code, result.stderr) == (2, "")
    assert failure(result) == {"code": "bad_config", "message": said}


def test_an_infeasible_twist_is_the_sockets_error_object_and_exits_3(runner: CliRunner) -> None:
    result = runner.invoke(main, ["ik", "-c", TB3, "--vx", "0.1", "--vy", "0.1", "--json"])
    assert (result.exit_code, result.stderr) == (3, "")
    error = failure(result)
    assert error["code"] == "infeasible_twist"
    assert error["message"].startswith("Twist (vx=0.1 m/s, vy=0.1 m/s, wz=0 rad/s) is infeasible")
    assert (error["wheel"], error["constraint"], error["residual_m_s"]) == (
        "left", "sliding", pytest.approx(0.1))
    assert error["twist"] == {"vx_m_s": 0.1, "vy_m_s": 0.1, "wz_rad_s": 0.0}
    assert error["nearest"]["vx_m_s"] == pytest.approx(0.1)


@pytest.mark.parametrize(("args", "message"), [
    (["ik", "--vx", "nan"], "Invalid value for --vx: expected a finite number, got nan"),
    (["fk", "--wheel", "nope=1"], "Invalid value for --wheel: Unknown wheel 'nope'"),
    (["fk", "--wheel", "left=1"], "Invalid value for --wheel: expected enough wheel speeds"),
    (["sim", "--rate", "nan"], "Invalid value for --rate"),
])
def test_bad_usage(runner: CliRunner, args: list[str], message: str) -> None:
    result = runner.invoke(main, [args[0], "-c", TB3, *args[1:], "--json"])
    assert (result.exit_code, result.stderr) == (2, "")
    error = failure(result)
    assert error["code"] == "bad_usage" and error["message"].startswith(message), error


def test_success_says_ok_too(runner: CliRunner) -> None:
    for args in (["ik", "--vx", "0.1"], ["fk", "--wheel", "left=1", "--wheel", "right=1"]):
        result = runner.invoke(main, [args[0], "-c", TB3, *args[1:], "--json"])
        assert result.exit_code == 0 and json.loads(result.stdout)["ok"] is True, result.output


def test_sim_a_bus_it_cannot_open(runner: CliRunner) -> None:
    result = runner.invoke(main, ["--interface", "socketcan", "--channel", "wgnosuchcan0",
                                  "sim", "--json"])
    assert (result.exit_code, result.stderr) == (1, "")
    error = failure(result)
    assert error["code"] == "bus_unavailable"
    assert error["message"].startswith("wheelgate sim: Cannot open CAN bus socketcan:wgnosuchcan0")


@pytest.mark.filterwarnings("ignore::pytest.PytestUnhandledThreadExceptionWarning")
def test_sim_its_simulator_thread_dying_ends_the_stream_with_the_error(
        runner: CliRunner, channel: str, monkeypatch: pytest.MonkeyPatch) -> None:
    def broken(self: SimTruth, now_s: float) -> None:
        raise ZeroDivisionError("deliberately broken truth")

    monkeypatch.setattr(SimTruth, "update", broken)
    result = runner.invoke(main, ["--interface", "virtual", "--channel", channel, "sim",
                                  "--every", "0", "--json"])
    assert result.exit_code == 1, result.output
    lines = [json.loads(line) for line in result.stdout.splitlines()]
    assert [d.get("event") for d in lines[:-1]] == ["device"] * 4 + ["ready"]  # the default
    last = lines[-1]
    assert last["ok"] is False and last["error"]["code"] == "error"
    assert "the simulator thread stopped: ZeroDivisionError('deliberately broken truth')" in (
        last["error"]["message"])
    assert "Error:" not in result.stderr
