"""``wheelgate twist`` and ``wheelgate status`` against a daemon running in a thread."""

from __future__ import annotations

import json
import threading
import time
from typing import TYPE_CHECKING

import pytest

from gateway.cli import main
from gateway.config import load_config
from gateway.daemon import Daemon
from gateway.sdnotify import SystemdNotifier
from gateway.types import GatewayState
from tests.conftest import CONFIG_DIR

if TYPE_CHECKING:
    from collections.abc import Iterator

    from click.testing import CliRunner


@pytest.fixture
def daemon(sock_path: str, channel: str) -> Iterator[Daemon]:
    cfg = load_config(CONFIG_DIR / "turtlebot3_burger.yaml", {"channel": channel})
    d = Daemon(cfg, sim=True, socket_path=sock_path, notifier=SystemdNotifier(None))
    thread = threading.Thread(target=d.run, daemon=True)
    thread.start()
    end = time.monotonic() + 10
    while d.gateway.state is not GatewayState.RUNNING and time.monotonic() < end:
        time.sleep(0.02)
    yield d
    d.request_stop()
    thread.join(timeout=10)


def test_twist_and_status(runner: CliRunner, daemon: Daemon, sock_path: str) -> None:
    result = runner.invoke(main, ["twist", "--socket", sock_path, "--vx", "0.1", "--wz", "0.5",
                                  "--duration", "0.5", "--rate", "20"])
    assert result.exit_code == 0, result.output
    assert "ok: following" in result.stdout
    result = runner.invoke(main, ["status", "--socket", sock_path, "--json"])
    assert result.exit_code == 0, result.output
    doc = json.loads(result.stdout)
    assert doc["state"] == "running"
    assert doc["odometry"]["distance"] > 0.01
    assert [m["name"] for m in doc["motors"]] == ["left", "right"]
    assert doc["timing"]["cycles"] > 10
    result = runner.invoke(main, ["status", "--socket", sock_path])
    assert result.exit_code == 0, result.output
    assert "state: running" in result.stdout
    assert "odometry: x=" in result.stdout


def test_twist_errors(runner: CliRunner, daemon: Daemon, sock_path: str) -> None:
    result = runner.invoke(main, ["twist", "--socket", sock_path, "--vy", "0.1"])
    assert result.exit_code == 3
    assert "breaks its sliding constraint" in result.stderr
    result = runner.invoke(main, ["twist", "--socket", sock_path, "--vx", "inf"])
    assert result.exit_code == 2


def test_no_daemon_is_a_clear_error(runner: CliRunner, sock_path: str) -> None:
    result = runner.invoke(main, ["status", "--socket", sock_path])
    assert result.exit_code == 1
    assert sock_path in result.stderr
