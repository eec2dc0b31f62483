"""Frames the drivers rejected in a replay (:mod:`gateway.drive.rejections`): counted by
driver and reason with the last one's detail in the summary, ``wheelgate odom``'s text and
JSON; exit 0 as with unreadable lines, and part of the error when nothing else is left.

The logs are built in the test from ODrive Get_Encoder_Estimates frames of the TurtleBot
(nodes 1 and 2: IDs 0x029 and 0x049).
"""

from __future__ import annotations

import json
from typing import TYPE_CHECKING

from gateway.apps.replay.replay import Replay
from gateway.cli.commands.odom import command
from gateway.config import load_config
from gateway.drive.rejections import RejectedFrames
from tests.apps.odom_helpers import DIFF, OBJ, line
from tests.conftest import CONFIG_DIR

if TYPE_CHECKING:
    from pathlib import Path

    from click.testing import CliRunner

SHORT = "(0.025000) can0 029#000000 R\n"  # Get_Encoder_Estimates carries 8 bytes
NAN = "(0.035000) can0 029#0000C07F00000000 R\n"  # position NaN (float32 0x7FC00000)
NAN_TEXT = ("Expected finite encoder estimates from ODrive node 1, but got position nan "
            "turns, velocity 0.0 turns/s.")


def log_with_rejections() -> list[str]:
    good = [line(k * 0.01, node, k * 0.1 * (1 if node == 1 else -1))
            for k in range(6) for node in (1, 2)]
    return [*good[:6], SHORT, *good[6:8], NAN, *good[8:]]


def replay(lines: list[str], config: Path = DIFF) -> Replay:
    r = Replay(load_config(config), 0.0)
    for _ in r.feed_lines(lines):
        pass
    return r


def test_the_summary_counts_rejected_frames_by_reason_with_the_last_detail() -> None:
    s = replay(log_with_rejections()).summary()
    assert s.rejections == (RejectedFrames("odrive", "malformed", 2, NAN_TEXT),)
    assert s.rejected_frames == 2
    assert s.corrupt_lines == 0  # readable lines: the drivers refused them
    assert s.updates == 6
    clean = replay([t for t in log_with_rejections() if t not in (SHORT, NAN)]).summary()
    assert clean.rejections == () and clean.rejected_frames == 0
    assert s.pose == clean.pose


def test_listener_only_rejections_are_left_out() -> None:
    # A CiA 402 SDO response answers a request the replay never sent (the gateway's, in a
    # --record log): the driver counts it, as the monitor's does, and it is no fault of the log.
    r = replay(["(0.000000) can0 585#6040600000000000 R\n"] * 2, CONFIG_DIR / "tricycle.yaml")
    assert sum(drv.rejected["unexpected SDO response"] for drv, _ in r.drives.groups) == 2
    assert r.summary().rejections == ()


def test_cli_reports_rejected_frames_and_exits_0(runner: CliRunner, tmp_path: Path) -> None:
    log = tmp_path / "rejected.log"
    log.write_text("".join(log_with_rejections()), encoding="ascii")
    result = runner.invoke(command, ["-c", str(DIFF), str(log)], obj=OBJ)
    assert result.exit_code == 0, result.output
    assert "14 of the motors (2 rejected by their drivers); 0 unreadable lines skipped" \
        in result.stdout
    assert result.stderr == (
        "warning: odrive rejected 2 frames of the motors, the replay went on without them "
        f"(malformed; the last: {NAN_TEXT})\n")
    quiet = runner.invoke(command, ["-c", str(DIFF), str(log), "-q"], obj=OBJ)
    assert quiet.exit_code == 0 and quiet.stderr == result.stderr  # not a line-by-line list
    doc = json.loads(runner.invoke(command, ["-c", str(DIFF), str(log), "--json"],
                                   obj=OBJ).stdout)
    assert doc["rejected_frames"] == 2
    assert doc["rejected"] == [{"driver": "odrive", "reason": "malformed", "frames": 2,
                                "last": NAN_TEXT}]
    clean = tmp_path / "clean.log"
    clean.write_text("".join(t for t in log_with_rejections() if t not in (SHORT, NAN)))
    plain = runner.invoke(command, ["-c", str(DIFF), str(clean), "--json"], obj=OBJ)
    assert json.loads(plain.stdout)["rejected"] == [] and plain.stderr == ""


def test_cli_names_the_rejections_when_nothing_is_left(runner: CliRunner,
                                                       tmp_path: Path) -> None:
    log = tmp_path / "short.log"
    log.write_text("".join(f"({k * 0.01:.6f}) can0 {ident}#000000 R\n"
                           for k in range(3) for ident in ("029", "049")), encoding="ascii")
    result = runner.invoke(command, ["-c", str(DIFF), str(log)], obj=OBJ)
    assert result.exit_code == 2, result.output
    assert result.stdout == ""
    assert ("no odometry: 6 of 6 frames belong to turtlebot3_burger's motors, none from left, "
            "right; their drivers rejected 6 of them (odrive, malformed: Expected 8 data "
            "bytes in Get_Encoder_Estimates of ODrive node 2 (ID 0x49), but got 3.)"
            ) in result.stderr
    doc = json.loads(runner.invoke(command, ["-c", str(DIFF), str(log), "--json"],
                                   obj=OBJ).stdout)
    assert doc["error"]["code"] == "no_odometry"
    assert "their drivers rejected 6 of them" in doc["error"]["message"]


def test_help_states_the_exit_status(runner: CliRunner) -> None:
    out = runner.invoke(command, ["--help"], obj=OBJ).stdout
    assert "Exit 0: the replay, also with unreadable lines" in " ".join(out.split())
