"""A blocking client of the control socket (:mod:`gateway.runtime.server`), for the CLI and
scripts::

    with ControlClient("/run/wheelgate.sock") as client:
        reply = client.request({"op": "twist", "vx": 0.2})   # {"ok": True, "id": 1, ...}
        client.request({"op": "subscribe", "topics": ["odometry"]})
        for event in client.events(timeout_s=1.0):
            ...

Every failure is a :class:`ClientError` whose message names the socket path.
"""

from __future__ import annotations

import itertools
import logging
import socket
import time
from collections import deque
from pathlib import Path
from typing import TYPE_CHECKING, Any

from gateway.core.errors import GatewayError, GatewayTimeoutError
from gateway.core.lifecycle import Closing
from gateway.wire.socket import ProtocolError, encode_line, parse_message

if TYPE_CHECKING:
    from collections.abc import Iterator, Mapping

log = logging.getLogger(__name__)

#: Longest line accepted from the gateway; a longer one means something else is talking.
MAX_REPLY_BYTES = 1 << 20
#: Events kept while waiting for a reply, for :meth:`ControlClient.events` to yield later.
MAX_BUFFERED_EVENTS = 1000
#: How long a refused connection is tried again while the socket file is there, s: a
#: daemon that is starting has bound the file but may not listen yet (a script that waits
#: for the file and then connects met that window), and a stale file from a daemon that died
#: is reported this much later.
REFUSED_RETRY_S = 0.5


class ClientError(GatewayError, ConnectionError):
    """The control socket cannot be reached or stopped answering; the message names the path."""


class ClientTimeoutError(ClientError, GatewayTimeoutError):
    """The gateway did not answer in time."""


def _connect(path: str, timeout_s: float, retry_s: float) -> socket.socket:
    """A connected socket; a refusal is tried again every 10 ms for up to ``retry_s`` (within
    ``timeout_s``) while the file is there.

    :raises OSError: as ``connect()`` raises it, the last refusal's after the retries.
    """
    give_up = time.monotonic() + min(retry_s, timeout_s)
    while True:
        sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        try:
            sock.settimeout(timeout_s)
            sock.connect(path)
        except ConnectionRefusedError:
            sock.close()
            if time.monotonic() >= give_up:
                raise
            time.sleep(0.01)
        except OSError:
            sock.close()
            raise
        else:
            return sock


class ControlClient(Closing):
    """A connection to the gateway's control socket.

    :param path: the socket file.
    :param timeout_s: longest wait for connecting and for each reply, s.
    :param refused_retry_s: how long a refused connection is tried again while the file is
        there (:data:`REFUSED_RETRY_S`; 0 for a caller that retries on its own, and must not
        wait, such as ``jog``'s screen).
    :raises ClientError: if nothing listens on ``path``, access is denied, or connecting
        times out (:class:`ClientTimeoutError`).
    """

    def __init__(self, path: str | Path, timeout_s: float = 2.0,
                 refused_retry_s: float = REFUSED_RETRY_S) -> None:
        self._closed = True
        self.path = Path(path)
        self.timeout_s = timeout_s
        self._ids = itertools.count(1)
        self._buffer = bytearray()
        self._events: deque[dict[str, Any]] = deque(maxlen=MAX_BUFFERED_EVENTS)
        try:
            sock = _connect(str(self.path), timeout_s, refused_retry_s)
        except (FileNotFoundError, ConnectionRefusedError) as err:
            raise ClientError(
                f"no gateway is listening on {self.path} (is `wheelgate run` running?)"
            ) from err
        except PermissionError as err:
            raise ClientError(
                f"permission denied for {self.path} (is your user in the socket's group?)"
            ) from err
        except TimeoutError as err:
            raise ClientTimeoutError(
                f"timed out after {timeout_s:g} s connecting to {self.path}"
            ) from err
        except OSError as err:
            raise ClientError(f"cannot connect to {self.path}: {err}") from err
        self._sock = sock
        self._closed = False

    def request(self, payload: Mapping[str, object]) -> dict[str, Any]:
        """Send one request and wait for its reply; events that arrive meanwhile are kept for
        :meth:`events`, replies to other ids are skipped.

        :param payload: the request, e.g. ``{"op": "twist", "vx": 0.2}``; an ``"id"`` is added
            unless present.
        :return: the reply object, ``{"ok": true, ...}`` or ``{"ok": false, "error": {...}}``.
        :raises ClientError: if the connection fails or closes, or the gateway sends garbage.
        :raises ClientTimeoutError: if no reply comes within ``timeout_s``.
        :raises EncodeError: if ``payload`` has a value with no JSON form.
        """
        self._check_open()
        message = dict(payload)
        if "id" not in message:
            message["id"] = next(self._ids)
        try:
            self._sock.settimeout(self.timeout_s)
            self._sock.sendall(encode_line(message))
        except TimeoutError as err:
            raise ClientTimeoutError(
                f"timed out after {self.timeout_s:g} s sending to {self.path}"
            ) from err
        except OSError as err:
            raise ClientError(f"cannot send to {self.path}: {err}") from err
        deadline = time.monotonic() + self.timeout_s
        while True:
            obj = self._read_message(deadline, f"the reply to request {message['id']!r}")
            if "event" in obj:
                self._events.append(obj)
            elif "ok" in obj and (
                obj.get("id") == message["id"] or (obj.get("id") is None and not obj["ok"])
            ):  # an error without id answers a request whose id the gateway could not read
                return obj
            else:
                log.debug("skipping a message for another request: %r", obj)

    def events(self, timeout_s: float | None = None) -> Iterator[dict[str, Any]]:
        """Yield events of the subscribed topics (subscribe first with :meth:`request`).

        :param timeout_s: longest wait for each event, s; ``None`` waits for ever.
        :raises ClientError: if the connection closes or fails.
        :raises ClientTimeoutError: if no event comes within ``timeout_s``.
        """
        while True:
            while self._events:
                yield self._events.popleft()
            self._check_open()
            deadline = None if timeout_s is None else time.monotonic() + timeout_s
            obj = self._read_message(deadline, "an event")
            if "event" in obj:
                yield obj

    def close(self) -> None:
        """Close the connection.  Safe to call twice."""
        if not self._closed:
            self._closed = True
            self._sock.close()

    def _check_open(self) -> None:
        if self._closed:
            raise ClientError(f"the connection to {self.path} is closed")

    def _read_message(self, deadline: float | None, what: str) -> dict[str, Any]:
        """The next complete line from the gateway, parsed."""
        while (newline := self._buffer.find(b"\n")) < 0:
            if len(self._buffer) > MAX_REPLY_BYTES:
                raise ClientError(
                    f"{self.path}: expected lines of at most {MAX_REPLY_BYTES} bytes, got more"
                )
            remaining = None if deadline is None else deadline - time.monotonic()
            if remaining is not None and remaining <= 0:
                raise ClientTimeoutError(f"timed out waiting for {what} from {self.path}")
            try:
                self._sock.settimeout(remaining)
                chunk = self._sock.recv(65536)
            except TimeoutError as err:
                raise ClientTimeoutError(
                    f"timed out waiting for {what} from {self.path}"
                ) from err
            except OSError as err:
                raise ClientError(f"cannot receive from {self.path}: {err}") from err
            if not chunk:
                raise ClientError(f"the gateway closed the connection on {self.path} "
                                  f"before sending {what}")
            self._buffer += chunk
        line = bytes(self._buffer[:newline])
        del self._buffer[: newline + 1]
        try:
            return parse_message(line)
        except ProtocolError as err:
            raise ClientError(f"{self.path}: {err}") from err
