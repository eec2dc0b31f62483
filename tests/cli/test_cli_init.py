"""``wheelgate init``: the file it writes passes ``wheelgate check``, it never replaces a file
without ``--force``, and it says what it did; ``--unit`` and ``--list``."""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING

import yaml

import gateway.cli.commands.init as init_command
from gateway.apps.init import Written
from gateway.cli import main
from tests.conftest import CONFIG_DIR

if TYPE_CHECKING:
    import pytest
    from click.testing import CliRunner

DBC = "example_controller.dbc"


def test_it_writes_a_file_that_check_accepts(runner: CliRunner, tmp_path: Path) -> None:
    out = tmp_path / "robot.yaml"
    result = runner.invoke(main, ["init", "--drive", "mecanum", "-o", str(out),
                                  "--acknowledge-no-controller-stop"])
    assert result.exit_code == 0, result.output
    assert result.stdout.splitlines()[0] == (
        f"wrote {out}: drive mecanum, from the example 'mecanum', drive motors on dji")
    assert f"then wheelgate check -c {out}" in result.stdout
    assert "check: ok, with 4 warning(s)" in result.stdout  # the DJI ESCs' missing stop
    assert yaml.safe_load(out.read_text()) == yaml.safe_load(
        (CONFIG_DIR / "mecanum.yaml").read_text())
    check = runner.invoke(main, ["check", "-c", str(out)])
    assert check.exit_code == 0 and "ok, with 4 warning(s)" in check.output, check.output


def test_controllers_that_cannot_stop_by_themselves_need_the_builders_word(
        runner: CliRunner, tmp_path: Path) -> None:
    """The mecanum example's DJI ESCs hold their last current if wheelgate dies; the example
    acknowledges that for the demo, but a file for a robot says so only with the flag."""
    out = tmp_path / "robot.yaml"
    result = runner.invoke(main, ["init", "--drive", "mecanum", "-o", str(out)])
    assert result.exit_code == 2
    assert ("Error: the controllers of motor 'front_left' (dji node 1), motor 'front_right' "
            "(dji node 2), motor 'rear_left' (dji node 3), motor 'rear_right' (dji node 4) "
            "cannot stop by themselves") in result.output
    assert "run init again with --acknowledge-no-controller-stop" in result.output
    assert "Nothing was written." in result.output and not out.exists()
    # On another driver, whose controllers stop by themselves, nothing to acknowledge.
    other = runner.invoke(main, ["init", "--drive", "mecanum", "--driver", "odrive", "-o",
                                 str(out)])
    assert other.exit_code == 0, other.output
    assert "no_controller_stop" not in out.read_text()


def test_without_o_it_writes_robot_yaml_here(runner: CliRunner, tmp_path: Path,
                                            monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    result = runner.invoke(main, ["init", "--drive", "omni3", "--driver", "vesc"])
    assert result.exit_code == 0, result.output
    raw = yaml.safe_load((tmp_path / "robot.yaml").read_text())
    assert raw["motor_defaults"]["driver"] == "vesc"
    assert "drive motors on vesc" in result.stdout


def test_it_never_replaces_a_file_without_force(runner: CliRunner, tmp_path: Path) -> None:
    out = tmp_path / "robot.yaml"
    out.write_text("mine\n")
    result = runner.invoke(main, ["init", "--drive", "omni3", "-o", str(out)])
    assert result.exit_code == 2
    assert f"{out}: the file exists; expected a new file (--force replaces it)" in result.output
    assert out.read_text() == "mine\n"
    result = runner.invoke(main, ["init", "--drive", "omni3", "-o", str(out), "--force"])
    assert result.exit_code == 0, result.output
    assert "name: omni3" in out.read_text()


def test_the_dbc_file_it_names_is_written_beside_it(runner: CliRunner, tmp_path: Path) -> None:
    out = tmp_path / "new" / "robot.yaml"
    result = runner.invoke(main, ["init", "--drive", "differential_tub", "--driver", "dbc",
                                  "-o", str(out)])
    assert result.exit_code == 0, result.output
    assert (out.parent / DBC).read_bytes() == (CONFIG_DIR / DBC).read_bytes()
    assert f"wrote {out.parent / DBC}: the file its motor blocks name" in result.stdout
    assert runner.invoke(main, ["check", "-c", str(out)]).exit_code == 0
    # The same DBC file there already: left as it is.
    again = runner.invoke(main, ["init", "--drive", "example_dbc", "-o",
                                 str(out.parent / "b.yaml")])
    assert again.exit_code == 0, again.output
    # Another file of that name: refused, and nothing written.
    (out.parent / DBC).write_text("VERSION \"mine\"\n")
    refused = runner.invoke(main, ["init", "--drive", "example_dbc", "-o",
                                   str(out.parent / "c.yaml")])
    assert refused.exit_code == 2
    assert f"{out.parent / DBC}: the file exists" in refused.output
    assert not (out.parent / "c.yaml").exists()


def test_to_standard_output_it_names_the_installed_dbc_file(
        runner: CliRunner, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    result = runner.invoke(main, ["init", "--drive", "example_dbc", "-o", "-"])
    assert result.exit_code == 0, result.output
    assert list(tmp_path.iterdir()) == []
    raw = yaml.safe_load(result.stdout)
    dbc = Path(raw["motor_defaults"]["dbc"])
    assert dbc.is_absolute() and dbc.read_bytes() == (CONFIG_DIR / DBC).read_bytes()
    assert result.stderr.startswith("wrote to standard output: drive differential, from the "
                                    "example 'example_dbc'")
    assert f"note: it names {DBC} where wheelgate is installed" in result.stderr


def test_node_ids_come_from_a_saved_scan_or_standard_input(runner: CliRunner,
                                                          tmp_path: Path) -> None:
    rows: list[dict[str, object]] = [
        {"protocol": "vesc", "node_id": n, "driver": "vesc"} for n in (31, 30)]
    rows.append({"protocol": "wheelgate", "node_id": None, "driver": None})
    scan = tmp_path / "scan.json"
    scan.write_text(json.dumps(rows))
    out = tmp_path / "robot.yaml"
    result = runner.invoke(main, ["init", "--drive", "differential_tub", "--from-scan",
                                  str(scan), "-o", str(out)])
    assert result.exit_code == 0, result.output
    assert (f"node IDs from the scan {scan}, in order (check each wheel: wheelgate spin -c "
            f"{out} WHEEL):\n"
            "  motors.left   vesc node 30\n  motors.right  vesc node 31\n") in result.stdout
    assert yaml.safe_load(out.read_text())["motors"] == {
        "left": {"node_id": 30}, "right": {"node_id": 31, "invert": True}}
    piped = runner.invoke(main, ["init", "--drive", "differential_tub", "--from-scan", "-",
                                 "-o", "-"], input=json.dumps(rows))
    assert piped.exit_code == 0, piped.output
    assert yaml.safe_load(piped.stdout)["motors"]["left"] == {"node_id": 30}


def test_a_scan_that_does_not_fit_is_a_usage_error_and_writes_nothing(
        runner: CliRunner, tmp_path: Path) -> None:
    scan = tmp_path / "scan.json"
    scan.write_text(json.dumps([{"protocol": "vesc", "node_id": 1, "driver": "vesc"}]))
    out = tmp_path / "robot.yaml"
    result = runner.invoke(main, ["init", "--drive", "differential_tub", "--from-scan",
                                  str(scan), "-o", str(out)])
    assert result.exit_code == 2
    assert (f"Error: {scan}: the scan found 1 vesc node(s) (1); expected 2, one per vesc "
            "controller (motors.left, motors.right)") in result.output
    assert not out.exists()
    missing = runner.invoke(main, ["init", "--drive", "mecanum", "--from-scan",
                                   str(tmp_path / "none.json")])
    assert missing.exit_code == 2 and "none.json" in missing.output


def test_a_configuration_check_refuses_is_never_written(
        runner: CliRunner, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    bad = Written("mecanum", "mecanum", ("dji",), "name: x\ndrive: hexapod\n")
    monkeypatch.setattr("gateway.cli.commands.init.generate", lambda *a, **k: bad)
    out = tmp_path / "robot.yaml"
    result = runner.invoke(main, ["init", "--drive", "mecanum", "-o", str(out)])
    assert result.exit_code == 2
    assert ("the configuration made from 'mecanum' does not pass `wheelgate check`, so it was "
            f"not written:\n{out}: drive: expected one of ") in result.output
    assert "wheelgate-init-" not in result.output and not out.exists()


def test_drive_is_needed_and_must_name_an_example(runner: CliRunner, tmp_path: Path,
                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)  # where robot.yaml would go
    result = runner.invoke(main, ["init"])
    assert result.exit_code == 2
    assert "Missing option '--drive': the example to start from, one of ackermann, " \
           "differential_castor" in result.output
    result = runner.invoke(main, ["init", "--drive", "hexapod"])
    assert result.exit_code == 2
    assert "--drive hexapod: no shipped example of that name or drive; expected one of " \
           "ackermann, differential_castor" in result.output
    assert "or a drive: ackermann, differential, generic, mecanum, omni," in result.output
    result = runner.invoke(main, ["init", "--drive", "mecanum", "--driver", "canopen"])
    assert result.exit_code == 2 and "Unknown driver 'canopen'" in result.output
    assert list(tmp_path.iterdir()) == []


def test_list_names_every_example_with_its_drive_and_drivers(runner: CliRunner) -> None:
    result = runner.invoke(main, ["init", "--list"])
    assert result.exit_code == 0
    lines = result.output.splitlines()
    assert lines[0].split() == ["example", "drive", "drivers"]
    assert [line.split()[0] for line in lines[1:]] == sorted(
        p.stem for p in CONFIG_DIR.glob("*.yaml"))
    assert "ackermann            ackermann     vesc, odrive (steering)" in lines


def test_unit_writes_the_systemd_unit(runner: CliRunner, tmp_path: Path,
                                     monkeypatch: pytest.MonkeyPatch) -> None:
    # ExecStart= names the wheelgate that runs (tests/apps/test_init_unit.py); here: none known
    monkeypatch.setattr(init_command, "running_wheelgate", lambda: None)
    unit = (CONFIG_DIR / "wheelgate.service").read_bytes()
    monkeypatch.chdir(tmp_path)
    result = runner.invoke(main, ["init", "--unit"])
    assert result.exit_code == 0, result.output
    assert (tmp_path / "wheelgate.service").read_bytes() == unit
    assert "install it as /etc/systemd/system/wheelgate.service" in result.stdout
    assert runner.invoke(main, ["init", "--unit"]).exit_code == 2  # it exists
    printed = runner.invoke(main, ["init", "--unit", "-o", "-"])
    assert printed.exit_code == 0 and printed.stdout_bytes == unit
    mixed = runner.invoke(main, ["init", "--unit", "--drive", "mecanum"])
    assert mixed.exit_code == 2 and "--unit writes the systemd unit only" in mixed.output


def test_a_scan_file_that_is_not_utf8_is_named_not_a_traceback(runner: CliRunner,
                                                              tmp_path: Path) -> None:
    scan = tmp_path / "bin.json"
    scan.write_bytes(b"\xff\xfe")
    out = tmp_path / "robot.yaml"
    said = (f"Error: {scan}: expected UTF-8 text (the JSON of `wheelgate scan --json`), got "
            f"byte 0xff at offset 0\n")
    result = runner.invoke(main, ["init", "--drive", "differential", "--from-scan", str(scan),
                                  "-o", str(out)])
    assert (result.exit_code, result.stderr) == (2, said), result.output
    assert isinstance(result.exception, SystemExit) and not out.exists()
    piped = runner.invoke(main, ["init", "--drive", "differential", "--from-scan", "-", "-o",
                                 str(out)], input=b"[\xc3]")
    assert (piped.exit_code, piped.stderr) == (2, "Error: <stdin>: expected UTF-8 text (the "
                                                  "JSON of `wheelgate scan --json`), got byte "
                                                  "0xc3 at offset 1\n"), piped.output


def test_o_says_what_is_in_the_way_and_creates_missing_directories(runner: CliRunner,
                                                                   tmp_path: Path) -> None:
    """One line each, naming the path, what was expected and what is there; --force replaces
    a file, never a directory.  A missing directory is created, as the README's systemd steps
    need (/etc/wheelgate/robot.yaml on a fresh machine), and said."""
    def init(*args: str) -> tuple[int, str]:
        result = runner.invoke(main, ["init", "--drive", "differential", *args])
        return result.exit_code, result.stderr if result.exit_code else result.stdout

    folder = tmp_path / "adir"
    folder.mkdir()
    for force in ((), ("--force",)):
        assert init("-o", str(folder), *force) == (2, (
            f"Error: {folder}: a directory is there; expected the name of a file to write "
            f"(e.g. {folder / 'robot.yaml'}); --force replaces files only\n"))
    unit = runner.invoke(main, ["init", "--unit", "-o", str(folder)])
    assert unit.exit_code == 2 and f"(e.g. {folder / 'wheelgate.service'})" in unit.stderr
    afile = tmp_path / "g.json"
    afile.write_text("{}")
    for inside in (afile / "x.yaml", afile / "deeper" / "x.yaml"):
        assert init("-o", str(inside)) == (
            2, f"Error: {inside}: {afile} is a file; expected a directory there\n")
    assert afile.read_text() == "{}" and list(folder.iterdir()) == []
    new = tmp_path / "no" / "such" / "r.yaml"
    code, said = init("-o", str(new))
    assert code == 0 and said.startswith(
        f"created {tmp_path / 'no'}: the directory did not exist\n"
        f"created {tmp_path / 'no' / 'such'}: the directory did not exist\n"
        f"wrote {new}: drive differential"), said
    assert new.is_file()


def test_on_dji_escs_the_bus_runs_at_their_only_bitrate(runner: CliRunner, tmp_path: Path
                                                       ) -> None:
    """The TurtleBot's example runs at 250 kbit/s; DJI ESCs talk at 1 Mbit/s only, which
    ``check`` requires.  init said "check: ok" and wrote 250000, which check then refused."""
    out = tmp_path / "robot.yaml"
    result = runner.invoke(main, ["init", "--drive", "turtlebot3_burger", "--driver", "dji",
                                  "--acknowledge-no-controller-stop", "-o", str(out)])
    assert result.exit_code == 0, result.output
    text = out.read_text()
    header = " ".join(line[2:] for line in text.splitlines() if line.startswith("# "))
    assert ("Its bus runs at 1000000 bit/s, the only bitrate of the DJI controllers, fixed in "
            "them (the example's: 250000).") in header
    assert yaml.safe_load(text)["bus"]["bitrate"] == 1_000_000
    check = runner.invoke(main, ["check", "-c", str(out)])
    assert check.exit_code == 0, check.output
    said = result.stdout.split("check: ok, with ")[1].split(" ")[0]
    assert check.output.rstrip().endswith(f"ok, with {said} warning(s)")
    # Drivers that talk at any bitrate keep the example's.
    same = runner.invoke(main, ["init", "--drive", "turtlebot3_burger", "--driver", "vesc",
                                "-o", str(out), "--force"])
    assert same.exit_code == 0, same.output
    assert yaml.safe_load(out.read_text())["bus"]["bitrate"] == 250_000


def test_the_bus_budget_is_judged_as_check_judges_it(
        runner: CliRunner, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    raw = yaml.safe_load((CONFIG_DIR / "turtlebot3_burger.yaml").read_text())
    out = tmp_path / "robot.yaml"
    for rate, code in ((1000, 2), (500, 0)):  # 103.5 % nominal: refused; 71.8 % worst: warned
        raw["gateway"] = {**raw.get("gateway", {}), "rate_hz": rate}
        made = Written("turtlebot3_burger", "differential", ("odrive",), yaml.safe_dump(raw))
        monkeypatch.setattr("gateway.cli.commands.init.generate", lambda *a, m=made, **k: m)
        result = runner.invoke(main, ["init", "--drive", "turtlebot3_burger", "-o", str(out)])
        assert result.exit_code == code, result.output
        if code:
            assert ("does not pass `wheelgate check`, so it was not written:\n"
                    f"{out}: bus.bitrate: the configuration's periodic frames need 103.5 %"
                    ) in result.output
            assert not out.exists()
        else:
            assert "check: ok, with 1 warning(s)" in result.stdout
            check = runner.invoke(main, ["check", "-c", str(out)])
            assert check.output.rstrip().endswith("ok, with 1 warning(s)"), check.output
