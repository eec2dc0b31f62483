"""The jog session's connection to the daemon: its requests, their log (``jog --log``) and
reconnection after a loss, without holding the screen up (every reply waits at most
:data:`REPLY_TIMEOUT_S`; a lost connection is tried again every :data:`RECONNECT_PERIOD_S`)."""

from __future__ import annotations

import json
import time
from typing import IO, TYPE_CHECKING, Any

from gateway.runtime.client import ClientError, ControlClient

if TYPE_CHECKING:
    from gateway.apps.jog.keys import Request

#: How often a lost connection is retried (s).
RECONNECT_PERIOD_S = 1.0
#: Longest wait for any reply (s); the deadman loop must not hang on a stuck daemon.
REPLY_TIMEOUT_S = 1.0


class JogLink:
    """The connection to the daemon: requests, their log, reconnection after a loss.

    :raises ClientError: if the first connection fails.
    """

    def __init__(self, path: str, log_file: IO[str] | None) -> None:
        self.path = path
        self.log_file = log_file
        self.client: ControlClient | None = ControlClient(path, timeout_s=REPLY_TIMEOUT_S)
        self.error = ""
        self.last_op = ""
        self._retry_s = 0.0
        self._t0 = time.monotonic()

    def request(self, payload: dict[str, object]) -> dict[str, Any] | None:
        """The reply, or ``None`` when the daemon cannot be reached (``error`` says why)."""
        if self.client is None:
            return None
        try:
            return self.client.request(payload)
        except ClientError as err:
            self.error = str(err)
            self.client.close()
            self.client = None
            self._retry_s = time.monotonic() + RECONNECT_PERIOD_S
            return None

    def send(self, req: Request) -> dict[str, Any] | None:
        """Send a twist or stop, and log it with its reply."""
        if self.client is None:
            self.retry(force=req.op == "stop")
        payload = req.payload()
        reply = self.request(payload)
        self.last_op = req.op if reply is not None and reply.get("ok") else ""
        if self.log_file is not None:
            entry = {"t_s": round(time.monotonic() - self._t0, 4), "request": payload,
                     "reply": reply, **({"error": self.error} if reply is None else {})}
            self.log_file.write(json.dumps(entry) + "\n")
            self.log_file.flush()
        return reply

    def retry(self, force: bool = False) -> None:
        """Reconnect after a loss, at most every :data:`RECONNECT_PERIOD_S` unless forced."""
        if self.client is not None or (not force and time.monotonic() < self._retry_s):
            return
        self._retry_s = time.monotonic() + RECONNECT_PERIOD_S
        try:
            # (no waiting on a refused connection: the screen keeps its rate; this retries)
            self.client = ControlClient(self.path, timeout_s=REPLY_TIMEOUT_S, refused_retry_s=0.0)
            self.error = ""
        except ClientError as err:
            self.error = str(err)

    def close(self) -> None:
        if self.client is not None:
            self.client.close()
            self.client = None
