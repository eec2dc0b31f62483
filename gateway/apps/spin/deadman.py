"""The deadman of ``wheelgate spin``: why the spin must stop, taken while the motor may turn.

A key on the terminal, read without its signal characters (no ``ISIG``, as ``jog``'s raw
mode: POSIX, General Terminal Interface, "Special Control Characters"), so Ctrl-C, Ctrl-\\ and
Ctrl-Z come as keys that stop the spin -- never a suspension with the motor holding its last
command (a DJI ESC keeps its current) -- and the terminal is restored on
every way out; or SIGINT, SIGTERM, SIGHUP, SIGQUIT or SIGTSTP, whose handlers only take note: the
stop goes out from the spin's loop, never from a signal handler.  SIGTSTP from elsewhere
(Ctrl-Z where standard input is no terminal, ``kill -TSTP``) stops the spin too; the command
then suspends itself (:func:`suspend`), once the stop is sent.
"""

from __future__ import annotations

import contextlib
import os
import select
import signal
import termios
import threading
import time
from typing import TYPE_CHECKING, Any

from gateway.core.lifecycle import Closing

if TYPE_CHECKING:
    from types import FrameType

#: The signals the deadman takes, by the name that says what stopped the spin.
_SIGNALS = {signal.SIGINT: "Ctrl-C", signal.SIGTERM: "SIGTERM", signal.SIGHUP: "SIGHUP",
            signal.SIGQUIT: "SIGQUIT", signal.SIGTSTP: "SIGTSTP"}
#: The terminal's interrupt, quit and suspend characters (``termios`` indices), which reach
#: the deadman as keys: the name of what each one stops the spin as.
_SIGNAL_KEYS = ((termios.VINTR, "Ctrl-C"), (termios.VQUIT, "Ctrl-\\"),
                (termios.VSUSP, "Ctrl-Z"))
#: The exit status after a signal, or its key, stopped the spin: 128 + its number, as a shell
#: reports a process the signal killed (Ctrl-C: 130, Ctrl-\\: 131).  Not SIGTSTP (the command
#: suspends after the stop, then goes on) nor Ctrl-Z (a key like any other here).
SIGNAL_EXIT = {name: 128 + int(signum) for signum, name in _SIGNALS.items()
               if signum != signal.SIGTSTP} | {"Ctrl-\\": 128 + int(signal.SIGQUIT)}


class Deadman(Closing):
    """Why the spin must stop: a key on the terminal ``tty_fd`` (read without echo, line
    editing, flow control or signal characters until :meth:`close`: Ctrl-C, Ctrl-\\ and
    Ctrl-Z are keys, named as such), or SIGINT, SIGTERM, SIGHUP, SIGQUIT or SIGTSTP (handled
    until :meth:`close`; only in the main thread, where Python runs handlers).

    :param tty_fd: a terminal to watch for keys; ``None``: signals only.
    """

    def __init__(self, tty_fd: int | None) -> None:
        self.reason = ""
        #: Whether SIGTSTP came (also after another stop, or after the spin): the command
        #: suspends once the stop is sent and this is closed (:func:`suspend`).
        self.suspend_asked = False
        self._fd = tty_fd
        self._saved_tty: list[Any] | None = None
        self._keys: dict[int, str] = {}
        self._saved: dict[int, object] = {}
        if threading.current_thread() is threading.main_thread():
            self._saved = {int(s): signal.signal(s, self._on_signal) for s in _SIGNALS}
        if tty_fd is not None:
            try:
                self._saved_tty = termios.tcgetattr(tty_fd)
                self._keys = signal_keys(self._saved_tty)
                termios.tcsetattr(tty_fd, termios.TCSAFLUSH, keys_mode(self._saved_tty))
            except termios.error:
                self._fd = None

    def _on_signal(self, signum: int, frame: FrameType | None) -> None:
        self.suspend_asked = self.suspend_asked or signum == signal.SIGTSTP
        self.reason = self.reason or _SIGNALS.get(signal.Signals(signum), str(signum))

    def wait(self, timeout_s: float) -> str:
        """Wait up to ``timeout_s`` for a stop; return why to stop (``""``: keep going)."""
        if not self.reason:
            timeout_s = max(timeout_s, 0.0)
            if self._fd is None:
                time.sleep(timeout_s)
            else:
                ready, _, _ = select.select([self._fd], [], [], timeout_s)
                if ready:
                    try:
                        typed = os.read(self._fd, 64)
                    except OSError:  # the terminal is gone
                        typed = b""
                    self.reason = self.reason or (self._keys.get(typed[0], "a key") if typed
                                                  else "end of input")
        return self.reason

    def close(self) -> None:
        """Restore the terminal (dropping keys typed since the spin ended, meant for it) and
        the signal handlers (safe to call twice)."""
        for signum, handler in self._saved.items():
            signal.signal(signum, handler)  # type: ignore[arg-type]
        self._saved = {}
        if self._saved_tty is not None and self._fd is not None:
            with contextlib.suppress(termios.error):
                termios.tcsetattr(self._fd, termios.TCSAFLUSH, self._saved_tty)
            self._saved_tty = None


def keys_mode(mode: list[Any]) -> list[Any]:
    """The terminal mode ``mode`` (``termios.tcgetattr``'s) as the deadman reads it: every key
    at once (no ``ICANON``, ``VMIN`` 1), unechoed, and none taken by the terminal itself: no
    ``ISIG`` (Ctrl-C, Ctrl-\\, Ctrl-Z raise no signal: a suspended spin would leave the motor
    at its last command), no ``IEXTEN`` (Ctrl-V, Ctrl-O), no ``IXON`` (Ctrl-S would freeze the
    output).  Output is processed as before, so lines printed meanwhile stay lines."""
    new = [*mode[:6], list(mode[6])]
    new[0] &= ~termios.IXON
    new[3] &= ~(termios.ICANON | termios.ECHO | termios.ISIG | termios.IEXTEN)
    new[6][termios.VMIN] = 1
    new[6][termios.VTIME] = 0
    return new


def signal_keys(mode: list[Any]) -> dict[int, str]:
    """The bytes of the terminal mode ``mode``'s interrupt, quit and suspend characters (as
    ``stty`` set them; none when disabled), by what they stop the spin as."""
    keys: dict[int, str] = {}
    for index, name in _SIGNAL_KEYS:
        char = mode[6][index]
        if isinstance(char, bytes) and len(char) == 1 and char != b"\x00":
            keys.setdefault(char[0], name)
    return keys


def suspend() -> None:
    """Suspend this process as SIGTSTP's default action does, now that the stop is sent and
    the terminal restored (:attr:`Deadman.suspend_asked`); it returns once continued
    (``fg``: SIGCONT), and nothing turns again.  Nothing happens when SIGTSTP is ignored or
    handled by someone else."""
    if signal.getsignal(signal.SIGTSTP) is signal.SIG_DFL:
        os.kill(os.getpid(), signal.SIGTSTP)
