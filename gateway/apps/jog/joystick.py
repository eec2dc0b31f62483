"""The gamepad device of ``wheelgate jog --joystick``: opened without blocking, read whenever
``select`` says so, and opened again after a loss (an unplugged or out-of-range pad).

What the events mean, and the safety rules, are in :mod:`gateway.apps.jog.pad`.  A read that
fails (``ENODEV``: unplugged), an end of file, or bytes that are not joydev events lose the
pad: :attr:`Joystick.pad` is then not enabled (the session stops a motion it held), and the
device is opened again every :data:`REOPEN_PERIOD_S`; a pad that comes back must have its
enable button pressed anew.  A wireless pad that goes out of range is lost only when the
kernel removes its device (the Bluetooth link's supervision timeout): until then joydev keeps
its last state, as it does for ROS ``joy_linux``.
"""

from __future__ import annotations

import errno
import os
import time

from gateway.apps.jog.pad import Pad, PadError, PadMap, parse_events

#: How often a lost pad is looked for again (s).
REOPEN_PERIOD_S = 1.0
#: The most bytes taken in one read (64 events).
READ_BYTES = 512


class JoystickError(Exception):
    """The device cannot be opened at the start (a usage error: nothing was driven yet)."""


class Joystick:
    """One joydev device.

    :param path: the device (``/dev/input/js0``).
    :param pad_map: which button enables and which axes drive.
    :raises JoystickError: if it cannot be opened now.
    """

    def __init__(self, path: str, pad_map: PadMap) -> None:
        self.path = path
        self.map = pad_map
        self.pad = Pad(pad_map)
        self.fd: int | None = None
        #: Why the pad is lost (``""`` while it is read).
        self.error = ""
        self._rest = b""
        self._retry_s = 0.0
        try:
            self._open()
        except OSError as err:
            hint = ("; is the pad connected? (ls /dev/input/js*)" if err.errno == errno.ENOENT
                    else "; the user must be allowed to read it (ls -l shows its group, "
                         "usually input)" if err.errno == errno.EACCES else "")
            raise JoystickError(f"cannot open {path}: {err.strerror}{hint}") from err

    def _open(self) -> None:
        self.fd = os.open(self.path, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC)
        self.pad = Pad(self.map)
        self._rest = b""
        self.error = ""

    def read(self) -> None:
        """Take what the device has (call when ``select`` finds :attr:`fd` readable)."""
        if self.fd is None:
            return
        try:
            data = os.read(self.fd, READ_BYTES)
        except BlockingIOError:
            return
        except OSError as err:
            self._lose(f"{self.path}: {err.strerror} (unplugged?)")
            return
        if not data:
            self._lose(f"{self.path}: end of file (unplugged?)")
            return
        try:
            events, self._rest = parse_events(self._rest + data)
        except PadError as err:
            self._lose(f"{self.path}: {err}")
            return
        self.pad = self.pad.apply(events)

    def retry(self, now_s: float) -> None:
        """Open a lost device again, at most every :data:`REOPEN_PERIOD_S`."""
        if self.fd is not None or now_s < self._retry_s:
            return
        self._retry_s = now_s + REOPEN_PERIOD_S
        try:
            self._open()
        except OSError as err:
            self.error = f"{self.path}: {err.strerror}; looking for it again"

    def next_retry_s(self) -> float:
        """When :meth:`retry` has something to do (``inf`` while the device is open)."""
        return self._retry_s if self.fd is None else float("inf")

    def describe(self) -> str:
        """One line for the screen."""
        if self.fd is None:
            return f"joystick: LOST {self.error}"
        missing = self.pad.missing()
        state = ("DRIVING (enable held)" if self.pad.armed else
                 "enable held since before it was opened: release and press it" if self.pad.held
                 else "idle")
        return (f"joystick: {self.path} {state}; {self.map.describe()}"
                + (f"; not on this pad: {missing}" if missing else ""))

    def _lose(self, why: str) -> None:
        self.close()
        self.error = why
        self.pad = Pad(self.map)
        self._retry_s = time.monotonic() + REOPEN_PERIOD_S

    def close(self) -> None:
        if self.fd is not None:
            os.close(self.fd)
            self.fd = None
