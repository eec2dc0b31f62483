"""``wheelgate init --unit``: the shipped systemd unit, with ``ExecStart=`` naming the
``wheelgate`` that runs (beside its Python, else on ``PATH``), quoted as systemd reads a
command line; the rest of the unit as shipped."""

from __future__ import annotations

import sys
from typing import TYPE_CHECKING

import pytest

from gateway.apps.init import shipped
from gateway.apps.init.unit import SHIPPED_PROGRAM, quoted, unit_text
from gateway.cli import main
from gateway.cli.commands import init as init_command

if TYPE_CHECKING:
    from pathlib import Path

    from click.testing import CliRunner

SHIPPED = shipped.read_text(shipped.UNIT)


def exec_start(text: str) -> str:
    (line,) = [x for x in text.splitlines() if x.startswith("ExecStart=")]
    return line


def test_exec_start_names_the_program_and_says_so() -> None:
    text = unit_text(SHIPPED, "/home/robot/venv/bin/wheelgate")
    assert exec_start(text) == ("ExecStart=/home/robot/venv/bin/wheelgate run -c "
                                "/etc/wheelgate/robot.yaml --socket /run/wheelgate/wheelgate.sock")
    assert f"# unit names {SHIPPED_PROGRAM}." in text
    # Nothing else changed: the two comment lines are the only new ones.
    before, after = SHIPPED.splitlines(), text.splitlines()
    assert [x for x in after if x not in before] == [
        "# The wheelgate that wrote this unit (wheelgate init --unit); the shipped",
        f"# unit names {SHIPPED_PROGRAM}.", exec_start(text)]
    assert unit_text(SHIPPED, None) == SHIPPED == unit_text(SHIPPED, SHIPPED_PROGRAM)


def test_a_path_systemd_would_split_is_quoted() -> None:
    assert quoted("/home/a b/bin/wheelgate") == '"/home/a b/bin/wheelgate"'
    assert quoted("/srv/100%/wheelgate") == "/srv/100%%/wheelgate"
    assert exec_start(unit_text(SHIPPED, "/home/a b/bin/wheelgate")).startswith(
        'ExecStart="/home/a b/bin/wheelgate" run -c ')
    with pytest.raises(ValueError, match="expected an absolute path of wheelgate"):
        unit_text(SHIPPED, "wheelgate")


def test_the_running_wheelgate_is_the_one_beside_this_python_else_on_path(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    venv = tmp_path / "venv" / "bin"
    venv.mkdir(parents=True)
    monkeypatch.setattr(sys, "executable", str(venv / "python"))
    other = tmp_path / "other"
    other.mkdir()
    (other / "wheelgate").write_text("#!/bin/sh\n")
    (other / "wheelgate").chmod(0o755)
    monkeypatch.setenv("PATH", str(other))
    assert init_command.running_wheelgate() == str(other / "wheelgate")  # none beside
    (venv / "wheelgate").write_text("#!/bin/sh\n")
    assert init_command.running_wheelgate() == str(venv / "wheelgate")
    monkeypatch.setenv("PATH", str(tmp_path / "nowhere"))
    (venv / "wheelgate").unlink()
    assert init_command.running_wheelgate() is None


def test_init_unit_writes_the_running_wheelgate(runner: CliRunner, tmp_path: Path,
                                                monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(init_command, "running_wheelgate", lambda: "/srv/wg/bin/wheelgate")
    out = tmp_path / "wheelgate.service"
    result = runner.invoke(main, ["init", "--unit", "-o", str(out)])
    assert result.exit_code == 0, result.output
    assert exec_start(out.read_text()).startswith("ExecStart=/srv/wg/bin/wheelgate run -c ")
    assert "the systemd unit (it starts /srv/wg/bin/wheelgate)" in result.stdout
    printed = runner.invoke(main, ["init", "--unit", "-o", "-"])
    assert printed.stdout == out.read_text()
    monkeypatch.setattr(init_command, "running_wheelgate", lambda: None)
    unknown = runner.invoke(main, ["init", "--unit", "-o", "-"])
    assert unknown.stdout == SHIPPED
