"""A small, non-blocking ``sd_notify(3)`` client for running the daemon under systemd.

The protocol is one datagram of newline-separated ``KEY=value`` assignments sent to the
``AF_UNIX`` socket named by ``$NOTIFY_SOCKET``.  This module does it without libsystemd and
without the ``sdnotify`` package (blocking socket, every error swallowed silently):

* the address is read once from the environment and **removed from it**, so child processes
  cannot notify on our behalf (``sd_notify``'s ``unset_environment``);
* only ``/absolute/path`` and ``@abstract`` addresses are accepted (``@`` becomes a NUL);
* the socket is ``SOCK_DGRAM | SOCK_CLOEXEC``, connected once, and every send uses
  ``MSG_DONTWAIT``, so a notification never blocks the control loop;
* send errors never escape: they are counted in :attr:`SystemdNotifier.errors` and the first
  one is logged at warning level;
* without ``$NOTIFY_SOCKET`` (a developer's shell, tests) the notifier is disabled and every
  call is a cheap no-op that returns ``False``.

The watchdog follows ``sd_watchdog_enabled(3)``: ``$WATCHDOG_USEC`` holds the timeout and
``$WATCHDOG_PID``, if set, the one process that must ping.  :func:`watchdog_period_s` returns
half the timeout, the recommended ping period.  Ping from the control loop itself, so a stalled
loop is restarted by systemd rather than kept alive by a helper thread.

Typical use in the daemon::

    notifier = SystemdNotifier.from_env()
    period = notifier.watchdog_period_s         # None: no watchdog configured
    ...                                          # open the bus, load the configuration
    notifier.ready(status="running at 200 Hz")
    while running:
        ...                                      # one control cycle
        if period is not None and now - last_ping >= period and loop_healthy:
            notifier.watchdog()
    notifier.stopping()
"""

from __future__ import annotations

import logging
import os
import re
import socket
from typing import TYPE_CHECKING

from gateway.core.errors import EncodeError
from gateway.core.lifecycle import Closing

if TYPE_CHECKING:
    from collections.abc import Mapping, MutableMapping

log = logging.getLogger(__name__)

#: Environment variables of the protocol.
NOTIFY_SOCKET = "NOTIFY_SOCKET"
WATCHDOG_USEC = "WATCHDOG_USEC"
WATCHDOG_PID = "WATCHDOG_PID"

#: A field name as systemd's ``sd_notify`` documentation writes them.
_FIELD_NAME = re.compile(r"[A-Z][A-Z0-9_]*\Z")


def parse_address(address: str) -> str:
    """The ``connect()`` address for a ``$NOTIFY_SOCKET`` value.

    :param address: ``/absolute/path`` or ``@abstract-name``.
    :return: the path unchanged, or the abstract name with ``@`` replaced by NUL.
    :raises EncodeError: for anything else (empty, relative, ``vsock:`` and so on).
    """
    if address.startswith("/"):
        return address
    if address.startswith("@") and len(address) > 1:
        return "\0" + address[1:]
    raise EncodeError(
        f"{NOTIFY_SOCKET}: expected an absolute path or an @abstract name, got {address!r}"
    )


def watchdog_period_s(
    environ: Mapping[str, str] | None = None, pid: int | None = None
) -> float | None:
    """The recommended watchdog ping period: half of ``$WATCHDOG_USEC``.

    As in ``sd_watchdog_enabled(3)``, pings are expected only if ``$WATCHDOG_PID`` is unset or
    equals our process id.  Malformed values are logged and treated as "no watchdog".

    :param environ: the environment to read; :data:`os.environ` when omitted.
    :param pid: our process id; :func:`os.getpid` when omitted.
    :return: the ping period in seconds, or ``None`` when no watchdog applies to us.
    """
    env = os.environ if environ is None else environ
    usec_text = env.get(WATCHDOG_USEC)
    if not usec_text:
        return None
    try:
        usec = int(usec_text)
    except ValueError:
        usec = 0
    if usec <= 0:
        log.warning("%s: expected a positive integer, got %r; watchdog off",
                    WATCHDOG_USEC, usec_text)
        return None
    pid_text = env.get(WATCHDOG_PID)
    if pid_text:
        try:
            watched = int(pid_text)
        except ValueError:
            log.warning("%s: expected a process id, got %r; watchdog off",
                        WATCHDOG_PID, pid_text)
            return None
        if watched != (os.getpid() if pid is None else pid):
            return None
    return usec / 2e6


class SystemdNotifier(Closing):
    """Sends ``sd_notify`` messages to systemd without ever blocking or raising on I/O errors.

    Use :meth:`from_env` in the daemon; the constructor is for tests and special set-ups.
    A notifier is a context manager; :meth:`close` may be called more than once.

    :param address: the ``$NOTIFY_SOCKET`` value (``/path`` or ``@abstract``), or ``None``
        for a disabled notifier.  An invalid or unreachable address gives a disabled notifier
        and a warning.
    :param watchdog_period_s: the ping period that :attr:`watchdog_period_s` reports.
    """

    def __init__(self, address: str | None, watchdog_period_s: float | None = None) -> None:
        #: Number of notifications that could not be sent (bad address, send errors).
        self.errors = 0
        #: The last send or connect error, for status reports.
        self.last_error: OSError | None = None
        self._watchdog_period_s = watchdog_period_s
        self._warned = False
        self._sock: socket.socket | None = None
        if address is None:
            return
        try:
            target = parse_address(address)
        except EncodeError as err:
            self.errors += 1
            log.warning("sd_notify disabled: %s", err)
            self._warned = True
            return
        sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM | socket.SOCK_CLOEXEC)
        try:
            sock.connect(target)
        except OSError as err:
            sock.close()
            self._failed(err, f"cannot connect to {address!r}")
            return
        self._sock = sock

    @classmethod
    def from_env(
        cls, environ: MutableMapping[str, str] | None = None, pid: int | None = None
    ) -> SystemdNotifier:
        """A notifier for the address in ``$NOTIFY_SOCKET``, which is removed from ``environ``.

        The watchdog period is read at the same time (:func:`watchdog_period_s`; ``None``
        without an address).  The watchdog variables are left in place, since
        ``$WATCHDOG_PID`` already keeps children from taking them for their own.

        :param environ: the environment; :data:`os.environ` when omitted.
        :param pid: our process id; :func:`os.getpid` when omitted.
        :return: an enabled notifier, or a disabled one if ``$NOTIFY_SOCKET`` is unset, empty
            or invalid.
        """
        env = os.environ if environ is None else environ
        address = env.pop(NOTIFY_SOCKET, None) or None
        return cls(address, watchdog_period_s(env, pid) if address else None)

    @property
    def enabled(self) -> bool:
        """True while notifications are actually being sent."""
        return self._sock is not None

    @property
    def watchdog_period_s(self) -> float | None:
        """How often to call :meth:`watchdog`, in seconds (``None``: no watchdog expected)."""
        return self._watchdog_period_s

    def send_raw(self, message: str | bytes) -> bool:
        """Send one datagram as it is.

        :param message: newline-separated ``KEY=value`` assignments.
        :return: True if the datagram was handed to the kernel.
        """
        sock = self._sock
        if sock is None:
            return False
        data = message.encode() if isinstance(message, str) else message
        try:
            sock.send(data, socket.MSG_DONTWAIT)
        except OSError as err:
            self._failed(err, "send failed")
            return False
        return True

    def notify(self, **fields: str | int) -> bool:
        """Send several assignments in one datagram, e.g. ``notify(READY=1, STATUS="up")``.

        Newlines inside values become spaces, so a value cannot inject another assignment.

        :param fields: upper-case field names and their values.
        :return: True if the datagram was handed to the kernel.
        :raises EncodeError: if a field name is not upper-case letters, digits and ``_``.
        """
        parts = []
        for name, value in fields.items():
            if not _FIELD_NAME.match(name):
                raise EncodeError(
                    f"sd_notify field name: expected upper-case letters, digits and '_', "
                    f"got {name!r}"
                )
            parts.append(f"{name}={_single_line(str(value))}")
        return self.send_raw("\n".join(parts))

    def ready(self, status: str | None = None) -> bool:
        """``READY=1``: start-up is complete (optionally with a status line)."""
        if status is None:
            return self.send_raw(b"READY=1")
        return self.notify(READY=1, STATUS=status)

    def stopping(self, status: str | None = None) -> bool:
        """``STOPPING=1``: shutdown has begun (optionally with a status line)."""
        if status is None:
            return self.send_raw(b"STOPPING=1")
        return self.notify(STOPPING=1, STATUS=status)

    def status(self, text: str) -> bool:
        """``STATUS=text``, shown by ``systemctl status``; newlines become spaces."""
        return self.send_raw("STATUS=" + _single_line(text))

    def watchdog(self) -> bool:
        """``WATCHDOG=1``: the keep-alive ping."""
        return self.send_raw(b"WATCHDOG=1")

    def extend_timeout(self, seconds: float) -> bool:
        """``EXTEND_TIMEOUT_USEC=``: ask for more time to start up or shut down.

        :param seconds: the time still needed from now, > 0.
        """
        return self.send_raw(f"EXTEND_TIMEOUT_USEC={max(1, round(seconds * 1e6))}")

    def close(self) -> None:
        """Close the socket; later calls are no-ops.  Safe to call more than once."""
        sock, self._sock = self._sock, None
        if sock is not None:
            sock.close()

    def _failed(self, err: OSError, what: str) -> None:
        self.errors += 1
        self.last_error = err
        if not self._warned:
            self._warned = True
            log.warning("sd_notify %s: %s (further errors are only counted)", what, err)
        else:
            log.debug("sd_notify %s: %s (%d errors)", what, err, self.errors)


def _single_line(text: str) -> str:
    """``text`` with CR/LF line breaks replaced by single spaces (the protocol is line-based)."""
    return text.replace("\r\n", " ").replace("\n", " ").replace("\r", " ")
