"""``-c NAME``: from a directory without that file, a bare name of a shipped example
(``wheelgate init --list``), with or without ``.yaml``, loads the example where it is installed,
said once on stderr; a file that exists always wins, and a path is never looked up."""

from __future__ import annotations

import json
from typing import TYPE_CHECKING

import click
import pytest

from gateway.apps.init import shipped
from gateway.cli import main
from gateway.cli.commands._common import config_file
from tests.conftest import CONFIG_DIR

if TYPE_CHECKING:
    from pathlib import Path

    from click.testing import CliRunner

SAID = "-c turtlebot3_burger.yaml: no such file here; using the shipped example"


@pytest.fixture
def empty(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """An empty working directory."""
    monkeypatch.chdir(tmp_path)
    return tmp_path


@pytest.mark.parametrize("args", [
    ["check"],
    ["ik", "--vx", "0.1"],
    ["frames", "--vx", "0.1"],
    ["fk", "--wheel", "left=1", "--wheel", "right=1"],
    ["--interface", "virtual", "--channel", "wg-name", "scan", "--timeout", "0.3", "--json"],
])
def test_every_command_taking_c_finds_a_shipped_example_by_name(
        runner: CliRunner, empty: Path, args: list[str]) -> None:
    at = args.index("check") if "check" in args else next(
        i for i, a in enumerate(args) if a in ("ik", "frames", "fk", "scan"))
    argv = [*args[:at + 1], "-c", "turtlebot3_burger.yaml", *args[at + 1:]]
    result = runner.invoke(main, argv)
    assert result.exit_code == 0, result.output
    assert result.stderr.count(SAID) == 1
    assert str(CONFIG_DIR / "turtlebot3_burger.yaml") in result.stderr
    if "scan" in args:
        assert json.loads(result.stdout) == []


def test_the_name_without_yaml_works_too(runner: CliRunner, empty: Path) -> None:
    result = runner.invoke(main, ["check", "-c", "example_dbc"])
    assert result.exit_code == 0, result.output
    assert "robot:    example_dbc" in result.stdout
    assert "-c example_dbc: no such file here; using the shipped example 'example_dbc'" in (
        result.stderr)


def test_a_file_that_exists_wins(runner: CliRunner, empty: Path) -> None:
    text = (CONFIG_DIR / "turtlebot3_burger.yaml").read_text("utf-8")
    (empty / "turtlebot3_burger.yaml").write_text(
        text.replace("name: turtlebot3_burger", "name: mine"), "utf-8")
    for given in ("turtlebot3_burger.yaml", "turtlebot3_burger"):  # with or without .yaml
        result = runner.invoke(main, ["check", "-c", given])
        assert result.exit_code == 0, result.output
        assert "robot:    mine" in result.stdout
        assert "shipped example" not in result.stderr


@pytest.mark.parametrize("given", ["./turtlebot3_burger.yaml", "sub/turtlebot3_burger.yaml",
                                   "no_such_robot.yaml"])
def test_a_path_or_an_unknown_name_is_read_as_given(runner: CliRunner, empty: Path,
                                                    given: str) -> None:
    result = runner.invoke(main, ["check", "-c", given])
    assert result.exit_code == 2
    assert f"{given}: cannot read the file" in result.stderr
    assert "shipped example" not in result.stderr


def test_it_is_said_once_however_often_the_command_loads_it(
        empty: Path, capsys: pytest.CaptureFixture[str]) -> None:
    ctx = click.Context(click.Command("x"))
    with ctx:
        first = config_file(ctx, "turtlebot3_burger.yaml")
        again = config_file(ctx, "turtlebot3_burger.yaml")
    assert first == again == str(shipped.example_file("turtlebot3_burger"))
    assert capsys.readouterr().err.count(SAID) == 1
    assert config_file(ctx, None) is None
