"""Bad usage or input is exit status 2 and says what was expected; `status --json` answers in
JSON even when no daemon runs."""

from __future__ import annotations

import json
from typing import TYPE_CHECKING

import yaml

from gateway.cli import main
from tests.conftest import REPO

if TYPE_CHECKING:
    from pathlib import Path

    from click.testing import CliRunner


def test_an_unknown_interface_lists_the_valid_ones(runner: CliRunner, tmp_path: Path) -> None:
    result = runner.invoke(main, ["--interface", "socketcna", "check"])
    assert result.exit_code == 2, result.output
    assert "expected a python-can interface, one of " in result.output
    assert "socketcan" in result.output and "got 'socketcna'" in result.output
    raw = yaml.safe_load((REPO / "gateway" / "data" / "default.yaml").read_text())
    raw["bus"]["interface"] = "vcan"
    raw["limits"]["max_linear_m_s"] = -1
    path = tmp_path / "robot.yaml"
    path.write_text(yaml.safe_dump(raw))
    result = runner.invoke(main, ["check", "-c", str(path)])
    assert result.exit_code == 2, result.output
    # among the file's other problems, in one run, and not as a typing error
    problems = result.stderr.removeprefix("Error: ").splitlines()
    assert [p.split(": ")[1] for p in problems] == ["limits.max_linear_m_s", "bus.interface"]
    assert "got 'vcan'" in problems[1] and "Usage:" not in result.stderr


def test_fk_with_too_few_wheels_names_the_missing_ones(runner: CliRunner) -> None:
    result = runner.invoke(main, ["fk", "--wheel", "front_left=1", "--wheel", "rear_left=1"])
    assert result.exit_code == 2, result.output
    assert "not given: front_right, rear_right" in result.output


def test_status_json_without_a_daemon_is_a_json_error(runner: CliRunner, tmp_path: Path) -> None:
    result = runner.invoke(main, ["status", "--json", "--socket", str(tmp_path / "none.sock")])
    assert result.exit_code == 1
    reply = json.loads(result.stdout)
    assert reply["ok"] is False and reply["error"]["code"] == "no_gateway"
    assert "no gateway is listening on" in reply["error"]["message"]
