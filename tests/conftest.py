"""Shared fixtures: unique virtual channels, a leak check on every test, the CLI runner."""

from __future__ import annotations

import itertools
import os
from pathlib import Path
from typing import TYPE_CHECKING

import pytest
from can.interfaces import virtual
from click.testing import CliRunner
from hypothesis import settings

if TYPE_CHECKING:
    from collections.abc import Iterator

    from gateway.runtime.daemon import Daemon

# Timing belongs in benchmarks (tools/), not in assertions: no example fails for taking longer
# than hypothesis' default 200 ms deadline on a loaded machine (CI runs the kernel-bus tier's VM
# beside the suite).
settings.register_profile("wheelgate", deadline=None)
settings.load_profile("wheelgate")

REPO = Path(__file__).resolve().parent.parent
CONFIG_DIR = REPO / "config"
DATA_DIR = Path(__file__).resolve().parent / "data"

_counter = itertools.count()

#: The ODrive watchdog's endpoint IDs of the simulated ODrive (firmware "0.0.0", which no real
#: ODrive reports), as the shipped configurations name them: test configurations on ODrive 0.6
#: take them so the gateway sets the watchdog, as ``controller_watchdog: required`` demands.
SIM_ODRIVE_ENDPOINTS = {"fw_version": "0.0.0", "enable_watchdog": 1, "watchdog_timeout": 2}

#: A mecanum robot with two drivers, their motors interleaved (VESC, ODrive, VESC, ODrive):
#: the drive set's status order differs from its drivers' order.
MIXED_ROBOT: dict[str, object] = {
    "name": "mixed", "drive": "mecanum",
    "geometry": {"wheel_radius": 0.05, "wheelbase": 0.4, "track": 0.36},
    "motor_defaults": {"gear_ratio": 10.0, "max_rpm": 3000},
    "motors": {
        "front_left": {"driver": "vesc", "node_id": 1, "pole_pairs": 7},
        "front_right": {"driver": "odrive", "node_id": 2,
                        "watchdog_endpoints": SIM_ODRIVE_ENDPOINTS},
        "rear_left": {"driver": "vesc", "node_id": 3, "pole_pairs": 7},
        "rear_right": {"driver": "odrive", "node_id": 4,
                       "watchdog_endpoints": SIM_ODRIVE_ENDPOINTS},
    },
    "bus": {"interface": "virtual", "channel": "unused"},
}


@pytest.fixture
def channel(request: pytest.FixtureRequest) -> str:
    """A virtual-bus channel name no other test uses."""
    return f"wg-{request.node.name}-{next(_counter)}"


@pytest.fixture(autouse=True)
def _no_leaked_buses() -> Iterator[None]:
    """Fail a test that leaves a virtual bus open (python-can's own conftest idea)."""
    before = set(virtual.channels)
    yield
    leaked = set(virtual.channels) - before
    for name in leaked:
        virtual.channels.pop(name, None)
    assert not leaked, f"virtual bus channels left open: {sorted(map(str, leaked))}"


@pytest.fixture(autouse=True)
def _own_state_directory(tmp_path_factory: pytest.TempPathFactory,
                         monkeypatch: pytest.MonkeyPatch) -> None:
    """Every test gets a state directory of its own (the e-stop latch lives there), and so do
    the daemons it starts as subprocesses: no latch leaks from one test into another."""
    monkeypatch.setenv("STATE_DIRECTORY", str(tmp_path_factory.mktemp("state")))


@pytest.fixture
def runner() -> CliRunner:
    """A click test runner."""
    return CliRunner()


@pytest.fixture
def sock_path() -> Iterator[str]:
    """A short path for a control socket (AF_UNIX paths are limited to 107 bytes)."""
    import shutil
    import tempfile

    folder = tempfile.mkdtemp(prefix="wg", dir="/tmp")
    yield f"{folder}/s.sock"
    shutil.rmtree(folder, ignore_errors=True)


@pytest.fixture
def sock_dir() -> Iterator[Path]:
    """A folder on a tmpfs for the control socket of the ``socketcan`` tier (not the VM's
    shared folder: Unix sockets do not work there)."""
    import shutil
    import tempfile

    base = "/run" if os.access("/run", os.W_OK) else None
    folder = Path(tempfile.mkdtemp(prefix="wgt", dir=base))
    yield folder
    shutil.rmtree(folder, ignore_errors=True)


@pytest.fixture
def daemon(sock_path: str, channel: str) -> Iterator[Daemon]:
    """A gateway daemon for the TurtleBot3 config with simulated controllers, running in a
    thread on ``sock_path``; stopped (zero and disarm) at the end."""
    import threading
    import time

    from gateway.config import load_config
    from gateway.core.types import GatewayState
    from gateway.runtime.daemon import Daemon
    from gateway.runtime.sdnotify import SystemdNotifier

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


#: The kernel CAN interface of the ``socketcan`` tier (a vcan, or a real bus with nothing else
#: on it: the tier's tests send on it).
VCAN = os.environ.get("WHEELGATE_TEST_VCAN", "vcan0")


def socketcan_missing(name: str = VCAN) -> str | None:
    """Why the ``socketcan`` tier cannot run here (``None``: it can)."""
    import socket

    try:
        s = socket.socket(socket.AF_CAN, socket.SOCK_RAW, socket.CAN_RAW)
    except (AttributeError, OSError) as err:
        return (f"this kernel has no SocketCAN (AF_CAN: {err}); on Linux: sudo modprobe vcan "
                f"&& sudo ip link add {name} type vcan && sudo ip link set {name} up")
    try:
        s.bind((name,))
    except OSError as err:
        return (f"no CAN interface {name!r} ({err}); create it: sudo ip link add {name} type vcan "
                f"&& sudo ip link set {name} up, or name another in WHEELGATE_TEST_VCAN")
    finally:
        s.close()
    flags = Path(f"/sys/class/net/{name}/flags")
    if flags.exists() and not int(flags.read_text(), 16) & 0x1:
        return f"CAN interface {name!r} is down: sudo ip link set {name} up"
    return None


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Skip the ``socketcan`` tier, with the reason, where there is no kernel CAN interface.
    The tier lives in ``tests/socketcan/`` (``.ci/run`` collects that folder alone): a test
    marked ``socketcan`` elsewhere is an error."""
    tier = [item for item in items if item.get_closest_marker("socketcan")]
    if not tier:
        return
    home = Path(__file__).parent / "socketcan"
    stray = [item.nodeid for item in tier if home not in item.path.parents]
    if stray:
        raise pytest.UsageError(f"tests marked socketcan must live in {home}, found: {stray}")
    why = socketcan_missing()
    if why is None:
        return
    skip = pytest.mark.skip(reason=f"socketcan tier: {why}")
    for item in tier:
        item.add_marker(skip)


@pytest.fixture
def vcan() -> str:
    """The kernel CAN interface of the ``socketcan`` tier (tests carrying the mark only)."""
    return VCAN
