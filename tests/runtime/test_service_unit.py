"""config/wheelgate.service: the settings the daemon relies on, and an ExecStart it accepts."""

from __future__ import annotations

import inspect
import re
import shlex
import shutil
import subprocess
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from gateway.config import load_config
from gateway.runtime import daemon
from gateway.runtime.server import ControlServer
from tests.conftest import CONFIG_DIR

UNIT = CONFIG_DIR / "wheelgate.service"

#: The options of ``wheelgate run`` and whether each takes a value.
RUN_OPTIONS = {"-c": True, "--config": True, "--sim": False, "--record": True, "--socket": True}

_DIRECTIVE = re.compile(r"([A-Za-z][A-Za-z0-9]*)=(.*)\Z")


@dataclass
class Unit:
    """A unit file as systemd reads it: repeated keys kept in order, comments apart."""

    sections: dict[str, list[tuple[str, str]]] = field(default_factory=dict)
    #: ``#Key=value`` lines: directives shipped commented out, by section.
    commented: dict[str, list[tuple[str, str]]] = field(default_factory=dict)

    def values(self, section: str, key: str) -> list[str]:
        return [v for k, v in self.sections.get(section, []) if k == key]

    def one(self, section: str, key: str) -> str:
        values = self.values(section, key)
        assert len(values) == 1, f"[{section}] {key}: expected one value, got {values}"
        return values[0]

    def commented_values(self, section: str, key: str) -> list[str]:
        return [v for k, v in self.commented.get(section, []) if k == key]


def parse_unit(text: str) -> Unit:
    """Parse systemd's ini dialect (``systemd.syntax(7)``): ``#``/``;`` full-line comments,
    backslash continuation, keys that may repeat."""
    unit = Unit()
    section = ""
    pending = ""
    for number, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip()
        if pending:
            line = pending + " " + line
            pending = ""
        if line.endswith("\\") and not line.startswith(("#", ";")):
            pending = line[:-1].rstrip()
            continue
        if not line:
            continue
        if line.startswith(("#", ";")):
            match = _DIRECTIVE.match(line[1:].strip())
            if match and section:
                unit.commented.setdefault(section, []).append((match[1], match[2].strip()))
            continue
        if line.startswith("["):
            assert line.endswith("]"), f"line {number}: bad section header {line!r}"
            section = line[1:-1]
            unit.sections.setdefault(section, [])
            continue
        match = _DIRECTIVE.match(line)
        assert match and section, f"line {number}: not a directive: {line!r}"
        unit.sections[section].append((match[1], match[2].strip()))
    assert not pending, "file ends inside a continued line"
    return unit


@pytest.fixture(scope="module")
def unit() -> Unit:
    return parse_unit(UNIT.read_text(encoding="utf-8"))


def test_parser_reads_systemd_syntax() -> None:
    parsed = parse_unit(
        "# header\n[Service]\nExecStartPre=a\nExecStartPre=b \\\n  c\n;Nice=-5\n#Foo=1\n"
        "Environment=A=1 B=2\n"
    )
    assert parsed.values("Service", "ExecStartPre") == ["a", "b c"]
    assert parsed.one("Service", "Environment") == "A=1 B=2"
    assert parsed.commented == {"Service": [("Nice", "-5"), ("Foo", "1")]}
    with pytest.raises(AssertionError, match="not a directive"):
        parse_unit("[Service]\nType notify\n")


@pytest.mark.parametrize(
    ("key", "expected"),
    [
        ("Type", "notify"),
        ("NotifyAccess", "main"),
        ("WatchdogSec", "1s"),
        ("Restart", "on-failure"),
        ("RestartSec", "1s"),
        ("TimeoutStopSec", "5s"),
        ("KillSignal", "SIGTERM"),
        ("RuntimeDirectory", "wheelgate"),
        ("RuntimeDirectoryMode", "0750"),
        ("StateDirectory", "wheelgate"),
        ("User", "wheelgate"),
        ("Group", "wheelgate"),
    ],
)
def test_service_setting(unit: Unit, key: str, expected: str) -> None:
    assert unit.one("Service", key) == expected


def test_environment(unit: Unit) -> None:
    assignments = [a for v in unit.values("Service", "Environment") for a in shlex.split(v)]
    env = dict(a.split("=", 1) for a in assignments)
    assert env == {"PYTHONUNBUFFERED": "1", "MALLOC_ARENA_MAX": "1", "OPENBLAS_NUM_THREADS": "1"}


def test_install_and_ordering(unit: Unit) -> None:
    assert unit.one("Install", "WantedBy") == "multi-user.target"
    assert "sys-subsystem-net-devices-can0.device" in unit.one("Unit", "After").split()


def test_realtime_options_are_offered_commented(unit: Unit) -> None:
    assert unit.commented_values("Service", "LimitRTPRIO") == ["60"]
    assert unit.commented_values("Service", "CPUSchedulingPolicy") == ["fifo"]
    assert unit.commented_values("Service", "CPUSchedulingPriority") == ["50"]
    assert unit.commented_values("Service", "LimitMEMLOCK") == ["infinity"]
    assert unit.commented_values("Service", "TimerSlackNSec") == ["1"]
    assert len(unit.commented_values("Service", "CPUAffinity")) == 1
    # RestrictRealtime=yes would make SCHED_FIFO fail; PrivateNetwork would hide can0.
    for key in ("RestrictRealtime", "PrivateNetwork", "CPUSchedulingPolicy", "LimitRTPRIO"):
        assert unit.values("Service", key) == []


def test_can_link_setup_is_offered_commented_and_privileged(unit: Unit) -> None:
    pre = unit.commented_values("Service", "ExecStartPre")
    argvs = [shlex.split(line) for line in pre]
    assert all(argv[0] == "+/usr/sbin/ip" for argv in argvs), pre
    # The bitrate of the shipped configuration the README installs (python-can does not set
    # it on SocketCAN: a mismatch is a silent bus).
    bitrate = str(load_config(CONFIG_DIR / "mecanum.yaml").bus.bitrate)
    assert ["link", "set", "can0", "up", "type", "can", "bitrate", bitrate, "restart-ms",
            "100"] in [argv[1:] for argv in argvs]
    assert ["link", "set", "can0", "txqueuelen", "1000"] in [argv[1:] for argv in argvs]


def test_open_files_leave_room_for_max_clients(unit: Unit) -> None:
    """systemd's default soft limit (1024) was max_clients itself: accept() failed with
    EMFILE before max_clients, and a new connection's estop was not answered."""
    max_clients = inspect.signature(ControlServer).parameters["max_clients"].default
    assert int(unit.one("Service", "LimitNOFILE")) >= max_clients + ControlServer.FD_HEADROOM


def test_the_notifications_are_described_as_the_daemon_sends_them() -> None:
    """WATCHDOG=1 depends on the bus taking frames, not on the loop's deadlines; READY=1 is
    sent at start, not once the drives are enabled (both said so before)."""
    text = " ".join(UNIT.read_text(encoding="utf-8").replace("#", " ").split())
    assert "keeps its deadlines" not in text
    assert "WATCHDOG=1 from the control loop's cycle while the CAN bus takes frames" in text
    doc = " ".join((daemon.__doc__ or "").split())
    assert "READY=1 once the drives are enabled" not in doc
    assert "READY=1 at start, once the bus is open and the socket listens" in doc
    assert "WATCHDOG=1 from the loop while the bus takes frames" in doc


def test_no_end_of_line_comments(unit: Unit) -> None:
    # systemd would pass "# ..." on to the program or fail to parse the value.
    for section, items in unit.sections.items():
        for key, value in items:
            assert not re.search(r"\s[#;]", value), f"[{section}] {key}={value}"


def exec_start(unit: Unit) -> list[str]:
    return shlex.split(unit.one("Service", "ExecStart"))


def test_exec_start_uses_only_run_options(unit: Unit) -> None:
    argv = exec_start(unit)
    assert argv[0].startswith("/")
    assert Path(argv[0]).name == "wheelgate"
    assert argv[1] == "run"
    values: dict[str, str] = {}
    args = iter(argv[2:])
    for arg in args:
        option = arg.split("=", 1)[0]
        assert option in RUN_OPTIONS, f"wheelgate run has no option {option!r}"
        if RUN_OPTIONS[option] and "=" not in arg:
            value = next(args, None)
            assert value is not None and not value.startswith("-"), f"{option} needs a value"
            values[option] = value
    assert values["-c"] == "/etc/wheelgate/robot.yaml"
    assert values["--socket"] == "/run/wheelgate/wheelgate.sock"
    # the socket lives in the RuntimeDirectory that systemd creates for the service user
    assert Path(values["--socket"]).parent == Path("/run") / unit.one("Service", "RuntimeDirectory")


def test_exec_start_parses_with_the_real_command(unit: Unit) -> None:
    from gateway import cli

    if "run" not in cli.COMMANDS:
        pytest.skip("wheelgate run is not registered yet")
    argv = exec_start(unit)
    root = cli.main.make_context("wheelgate", argv[1:], resilient_parsing=False)
    command = cli.main.get_command(root, "run")
    assert command is not None
    with command.make_context("run", argv[2:], parent=root) as ctx:
        assert ctx.params  # parsed without a usage error


def test_systemd_analyze_verify_accepts_every_directive(tmp_path: Path) -> None:
    """systemd itself parses the unit, commented options included (skipped without it)."""
    analyze = shutil.which("systemd-analyze")
    if analyze is None:
        pytest.skip("systemd-analyze not installed")
    text = UNIT.read_text(encoding="utf-8")
    # Uncomment every shipped directive and point ExecStart at an existing program.
    text = re.sub(r"^#(?=[A-Z][A-Za-z]*=)", "", text, flags=re.MULTILINE)
    text = re.sub(r"^ExecStart=\S+", f"ExecStart={shutil.which('true') or '/bin/true'}", text,
                  flags=re.MULTILINE)
    # systemd-analyze wants a short, private path for the unit.
    work = Path(tempfile.mkdtemp(prefix="wg-unit-"))
    try:
        path = work / "wheelgate.service"
        path.write_text(text, encoding="utf-8")
        result = subprocess.run(
            [analyze, "verify", "--man=no", str(path)],
            capture_output=True, text=True, timeout=30, check=False,
        )
    finally:
        shutil.rmtree(work, ignore_errors=True)
    complaints = [line for line in (result.stdout + result.stderr).splitlines()
                  if "wheelgate.service" in line]
    assert complaints == [], "\n".join(complaints)
