"""Twist components are bounded the same way in every command (the control socket's bound):
beyond it, or not finite, is a usage error with exit status 2, before anything is computed or
sent."""

from __future__ import annotations

from typing import TYPE_CHECKING

import pytest

from gateway.cli import main
from gateway.cli.commands.twist import following
from gateway.wire.socket.messages import MAX_TWIST_COMPONENT

if TYPE_CHECKING:
    from click.testing import CliRunner


@pytest.mark.parametrize("command", [["ik"], ["frames"], ["twist", "--socket", "/nonexistent/s"]])
@pytest.mark.parametrize(("option", "value"), [
    ("--vx", "1e300"), ("--vy", "-1e9"), ("--wz", str(MAX_TWIST_COMPONENT * 1.01)),
    ("--vx", "nan"), ("--wz", "inf"),
])
def test_a_twist_beyond_the_bound_is_a_usage_error(
        runner: CliRunner, command: list[str], option: str, value: str) -> None:
    result = runner.invoke(main, [*command, option, value])
    assert result.exit_code == 2, result.output
    assert option in result.output


def test_a_twist_at_the_bound_is_computed(runner: CliRunner) -> None:
    result = runner.invoke(main, ["ik", "--vx", str(MAX_TWIST_COMPONENT), "--json"])
    assert result.exit_code == 0, result.output


def test_the_twist_command_says_what_the_robot_follows_and_why() -> None:
    reply = {"ok": True, "twist": {"vx_m_s": 5.0, "vy_m_s": 0.0, "wz_rad_s": 0.0},
             "projected": False, "applied": {"vx_m_s": 1.5, "vy_m_s": -2.776e-17,
                                             "wz_rad_s": -0.0},
             "limited_by": "max_linear_m_s 1.5 m/s"}
    asked = {"vx_m_s": 5.0, "vy_m_s": 0.0, "wz_rad_s": 0.0}
    assert following(reply, asked) == (
        "ok: following vx 1.5 m/s, vy 0 m/s, wz 0 rad/s (asked vx 5 m/s, vy 0 m/s, wz 0 rad/s; "
        "limited by max_linear_m_s 1.5 m/s)")
    plain = {**reply, "applied": reply["twist"], "limited_by": None}
    assert following(plain, asked) == "ok: following vx 5 m/s, vy 0 m/s, wz 0 rad/s"
