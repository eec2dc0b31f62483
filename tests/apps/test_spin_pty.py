"""``wheelgate spin`` and Ctrl-Z on a terminal with job control, as a shell runs it.

The command runs under a tiny job-control shell (:data:`SHELL`) on a pseudo-terminal
(:class:`tests.pty_helpers.Pty`): the pty is the shell's controlling terminal, spin a job in
its own foreground process group, so Ctrl-Z typed on the master side is what it is at a real
shell -- SIGTSTP to the job when the terminal generates signals.  The shell says when the job
is suspended (``[shell] suspended``), continues it on ``fg`` and says how it ended and whether
the terminal was left as it was.  The simulated motor is in the spin process (``--sim``);
whether it stopped is said by spin's stop line and its verdict.  Every wait is bounded.
"""

from __future__ import annotations

import re
import sys
from typing import TYPE_CHECKING

import pytest

from tests.pty_helpers import Pty

if TYPE_CHECKING:
    from collections.abc import Iterator

pytestmark = pytest.mark.timeout(60)

#: A job-control shell of one job: ``python -c SHELL tty|no-tty ARGS...`` runs ``python -m
#: gateway ARGS`` in the foreground (``no-tty``: with standard input from /dev/null).
SHELL = r"""
import fcntl, os, signal, sys, termios
fcntl.ioctl(0, termios.TIOCSCTTY, 0)
saved = termios.tcgetattr(0)
signal.signal(signal.SIGTTOU, signal.SIG_IGN)
pid = os.fork()
if pid == 0:
    os.setpgid(0, 0)
    if sys.argv[1] == "no-tty":
        os.dup2(os.open(os.devnull, os.O_RDONLY), 0)
    signal.signal(signal.SIGTTOU, signal.SIG_DFL)
    os.execv(sys.executable, [sys.executable, "-m", "gateway", *sys.argv[2:]])
try:
    os.setpgid(pid, pid)
except OSError:
    pass
os.tcsetpgrp(1, pid)
while True:
    _, status = os.waitpid(pid, os.WUNTRACED)
    if not os.WIFSTOPPED(status):
        break
    os.tcsetpgrp(1, os.getpgrp())
    termios.tcsetattr(0, termios.TCSADRAIN, saved)
    print("[shell] suspended", flush=True)
    while sys.stdin.readline().strip() != "fg":
        pass
    os.tcsetpgrp(1, pid)
    os.killpg(pid, signal.SIGCONT)
restored = termios.tcgetattr(0) == saved
print(f"[shell] exit {os.waitstatus_to_exitcode(status)}, terminal restored: {restored}",
      flush=True)
"""
SPIN = ["spin", "front_left", "--sim", "--duration", "10", "--no-ask"]
_STOPPED = re.compile(r"spin: stop sent \(zero and disarm\) after (\S+) s, stopped by (\S+)")
_EXIT = re.compile(r"\[shell\] exit (\d+), terminal restored: (\w+)")


@pytest.fixture
def job() -> Iterator[list[Pty]]:
    started: list[Pty] = []
    yield started
    for p in started:
        if "[shell] suspended" in p.text and p.proc.poll() is None:
            p.send(b"fg\n")  # let a suspended spin go on to its own stop before the kill
            p.wait_exit(15)
        p.close()


def start(job: list[Pty], stdin: str) -> Pty:
    job.append(Pty([sys.executable, "-c", SHELL, stdin, *SPIN], env={"NO_COLOR": "1"}))
    return job[-1]


def wait_text(p: Pty, what: str, check: object, timeout_s: float = 20.0) -> None:
    p.wait_for(what, lambda _: bool(check(p.text)), timeout_s)  # type: ignore[operator]


def test_ctrl_z_at_the_terminal_stops_the_wheel_without_suspending(job: list[Pty]) -> None:
    p = start(job, "tty")
    wait_text(p, "the motor enabled", lambda t: "spin: enabled in" in t)
    p.pump(0.3)
    p.send(b"\x1a")  # Ctrl-Z
    wait_text(p, "the stop, or the job suspended",
              lambda t: _STOPPED.search(t) or "[shell] suspended" in t)
    assert "[shell] suspended" not in p.text, p.text  # never suspended with the motor turning
    stopped = _STOPPED.search(p.text)
    assert stopped is not None and stopped.group(2) == "Ctrl-Z", p.text
    assert float(stopped.group(1)) < 3.0, p.text  # at the key, not at the end of the spin
    wait_text(p, "the shell's last line", _EXIT.search)
    assert p.wait_exit(10) == 0
    ended = _EXIT.search(p.text)
    assert ended is not None and ended.groups() == ("1", "True"), p.text
    assert "front_left: nothing judged: stopped early by Ctrl-Z" in p.text


def test_sigtstp_from_the_terminal_stops_the_wheel_then_suspends(job: list[Pty]) -> None:
    # Standard input is no terminal: spin reads no keys and the terminal's Ctrl-Z is SIGTSTP.
    p = start(job, "no-tty")
    wait_text(p, "the motor enabled", lambda t: "spin: enabled in" in t)
    p.pump(0.3)
    p.send(b"\x1a")
    wait_text(p, "the job suspended", lambda t: "[shell] suspended" in t)
    stopped = _STOPPED.search(p.text)
    assert stopped is not None and stopped.group(2) == "SIGTSTP", p.text
    assert p.text.index("spin: stop sent") < p.text.index("[shell] suspended"), p.text
    assert float(stopped.group(1)) < 3.0, p.text
    p.send(b"fg\n")
    wait_text(p, "the shell's last line", _EXIT.search)
    assert p.wait_exit(10) == 0
    ended = _EXIT.search(p.text)
    assert ended is not None and ended.groups() == ("1", "True"), p.text
    assert p.text.count("spin: stop sent") == 1 and "enabled in" in p.text
    assert "front_left: nothing judged: stopped early by SIGTSTP" in p.text
