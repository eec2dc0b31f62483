"""The live view: the loop's news served to the Foxglove app and recorded to an MCAP file.

:class:`LiveView` serves a Foxglove WebSocket server (the Foxglove SDK's,
https://docs.foxglove.dev/docs/sdk) and/or records the same channels to an MCAP
file (https://mcap.dev/spec).  The channels -- ``/tf``, ``/odom/pose``, ``/odom``, ``/wheels``,
``/steering``, ``/state``, ``/errors``, ``/diagnostics`` -- are listed with their schemas and
fields in :mod:`gateway.runtime.liveview_channels`; every message is stamped with the
snapshot's ``stamp_ns`` (wall clock), the errors and the diagnostics with the wall clock when
the worker takes them.

To watch a robot: in the Foxglove app (desktop, or https://app.foxglove.dev), *Open connection*
-> *Foxglove WebSocket* -> ``ws://127.0.0.1:8765`` (the URL the daemon logs at start; the
``foxglove:`` block's host and port).  A 3D panel shows ``base_link`` moving in ``odom`` (the
``/tf`` transforms; display frame ``odom``), a Plot panel takes paths such as
``/wheels.front_left.measured_rad_s`` or ``/odom.twist.vx_m_s``, a Log panel shows ``/errors``,
the Diagnostics panels show ``/diagnostics`` (the gateway, the CAN bus and each motor).
A recording opens with *Open local file*, and ``wheelgate odom FILE.mcap`` replays its wheels
through the odometry (:mod:`gateway.apps.replay.mcap_source`).

Threads: the loop only posts to :attr:`LiveView.mailbox` (:mod:`gateway.runtime.mailbox`: a
lock held for a few stores; the newest snapshot replaces an older one the worker has not taken).
The worker thread (``wheelgate-liveview``) takes the news, builds the messages and logs them to
the SDK's channels; the SDK's own threads send them to the WebSocket clients and write the file.
No exception of the worker reaches the loop: a channel whose message fails is logged once with
its topic and counted (:attr:`LiveViewStats.failures`), bad data (a number that is not finite, a
value not measured yet) is written as ``null`` (a pose that is not finite is left out of
``/tf`` and ``/odom/pose``), and anything else is logged and the worker goes on.

The SDK is imported when a :class:`LiveView` is made, so this module costs nothing to a daemon
without a ``foxglove:`` block or ``--record-mcap``; without the SDK, :class:`LiveViewError`
says to install the extra.  MCAP chunks are LZ4-compressed (readable with the ``mcap`` package's
own dependencies) and finished every :data:`FLUSH_S`, so a daemon that dies loses at most that
much of its recording.
"""

from __future__ import annotations

import enum
import json
import logging
import os
import threading
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from gateway.core.errors import GatewayError
from gateway.runtime.diagnostics import diagnostic_array
from gateway.runtime.liveview_channels import (
    DIAGNOSTICS_TOPIC,
    ERRORS_TOPIC,
    POSE_TOPIC,
    STATE_TOPIC,
    TF_TOPIC,
    Channels,
    log_time_ns,
    planar,
)
from gateway.runtime.mailbox import MAX_ERRORS, Mailbox

if TYPE_CHECKING:
    from collections.abc import Callable, Mapping, Sequence
    from types import ModuleType

    from gateway.core.bridge_settings import FoxgloveSettings
    from gateway.core.status import GatewayStatus
    from gateway.runtime.liveview_channels import Planar
    from gateway.runtime.mailbox import Delivery, Snapshot

log = logging.getLogger(__name__)

__all__ = ["INSTALL_HINT", "LiveView", "LiveViewError", "LiveViewStats", "import_foxglove"]

INSTALL_HINT = "install the extra: pip install 'wheelgate[foxglove]'"
#: Seconds the worker waits for news before looking again (it also wakes on news).
WORKER_WAKE_S = 0.5
#: Seconds between two finished MCAP chunks (what a daemon that dies loses at most).
FLUSH_S = 1.0
#: Seconds :meth:`LiveView.close` waits for the worker.
CLOSE_TIMEOUT_S = 5.0
#: Uncompressed bytes after which the MCAP writer finishes a chunk on its own.
MCAP_CHUNK_BYTES = 256 * 1024


class LiveViewError(GatewayError):
    """The live view cannot start: the SDK is missing, the port is taken, the file cannot be
    written."""


def import_foxglove() -> ModuleType:
    """The ``foxglove`` module (foxglove-sdk), with its channels, messages and MCAP options.

    :raises LiveViewError: when it is not installed, saying how to install it.
    """
    try:
        import foxglove  # noqa: PLC0415 - optional, imported only for a live view
        import foxglove.channels  # noqa: PLC0415
        import foxglove.mcap  # noqa: PLC0415
        import foxglove.messages  # noqa: PLC0415
    except ImportError as err:
        raise LiveViewError(f"foxglove: the foxglove-sdk package is not installed ({err}); "
                            f"{INSTALL_HINT}") from err
    return foxglove


@dataclass(frozen=True, slots=True)
class LiveViewStats:
    """What the worker did so far.

    :param snapshots: snapshots published (each on every per-snapshot channel that took it).
    :param errors: errors published on ``/errors``.
    :param errors_dropped: errors the mailbox dropped before the worker took them.
    :param failures: messages a channel failed to take (see the log: once per channel).
    :param bad_data: snapshots whose time stamp or pose could not be used (other values that
        are not finite are written as ``null`` and not counted).
    :param diagnostics: diagnostics reports published on ``/diagnostics``.
    """

    snapshots: int
    errors: int
    errors_dropped: int
    failures: int
    bad_data: int
    diagnostics: int = 0


class LiveView:
    """The Foxglove live view of one robot (see the module's doc).

    :param settings: the ``foxglove:`` block (host, port, ``mcap`` file).
    :param robot_name: the robot's name (the server's name, the ``/errors`` source).
    :param wheel_names: the driven wheels, as the snapshots name them (``/wheels``' keys).
    :param steer_names: the steering actuators (``/steering``' keys; no channel when empty).
    :param record_mcap: record to this file ('' for ``settings.mcap``; this one wins when both
        are given); an existing file is replaced.
    :param serve: serve the WebSocket server (``False``: record only).
    :param hardware: each motor's hardware id in ``/diagnostics``, by its name in the status
        (:func:`gateway.runtime.diagnostics.hardware_ids`).
    :raises LiveViewError: when the SDK is missing, there is nothing to do (no server and no
        file), the server cannot listen, or the file cannot be created -- naming which.
    """

    def __init__(self, settings: FoxgloveSettings, robot_name: str, wheel_names: Sequence[str],
                 steer_names: Sequence[str] = (), *, record_mcap: str = "",
                 serve: bool = True, hardware: Mapping[str, str] | None = None) -> None:
        self.settings = settings
        self.robot_name = robot_name
        self.hardware = dict(hardware or {})
        #: The file recorded to ('' for none).
        self.mcap_path = record_mcap or settings.mcap
        #: The server's address, e.g. ``ws://127.0.0.1:8765`` (the real port when 0 was
        #: asked; '' when not serving).
        self.url = ""
        #: Where the loop posts (thread-safe, never blocks on the worker).
        self.mailbox: Mailbox[None] = Mailbox()
        if not serve and not self.mcap_path:
            raise LiveViewError("foxglove: nothing to do: expected a server (serve=True) or an "
                                "MCAP file to record to, got neither")
        fg = import_foxglove()
        self._context = fg.Context()
        self._channels = Channels(fg, self._context, robot_name, wheel_names, steer_names)
        self._writer: Any = None
        self._server: Any = None
        self._lock = threading.Lock()
        self._thread: threading.Thread | None = None
        self._closed = False
        self._snapshots = self._errors = self._dropped = self._failures = self._bad_data = 0
        self._diagnostics = 0
        self._failed: set[str] = set()
        self._last_error_ns = 0
        self._flush_at = 0.0
        try:   # the server first: a port in use leaves an existing file as it was
            if serve:
                self._server = self._serve(fg)
            if self.mcap_path:
                self._writer = self._open_mcap(fg, wheel_names, steer_names)
        except BaseException:
            self._stop_sinks()
            raise

    # ----------------------------------------------------------------- sinks

    def _serve(self, fg: ModuleType) -> Any:
        s = self.settings
        try:
            server = fg.start_server(name=f"wheelgate {self.robot_name}", host=s.host,
                                     port=s.port, context=self._context)
        except Exception as err:  # FoxgloveError (a RuntimeError): port in use, unknown host
            raise LiveViewError(
                f"foxglove: cannot serve the live view on {s.host}:{s.port} (expected a free "
                f"port on a local address): {err}; set foxglove.port to a free port, or 0 for "
                "any free one") from err
        host = f"[{s.host}]" if ":" in s.host else s.host
        self.url = f"ws://{host}:{server.port}"
        return server

    def _open_mcap(self, fg: ModuleType, wheel_names: Sequence[str],
                   steer_names: Sequence[str]) -> Any:
        path = self.mcap_path
        folder = os.path.dirname(os.path.abspath(path))
        if not os.path.isdir(folder) or os.path.isdir(path):
            raise LiveViewError(f"foxglove: cannot record the live view to {path!r}: expected a "
                                f"file in an existing directory, got "
                                + ("a directory" if os.path.isdir(path) else
                                   f"{folder!r}, which does not exist"))
        options = fg.mcap.MCAPWriteOptions(compression=fg.mcap.MCAPCompression.Lz4,
                                           chunk_size=MCAP_CHUNK_BYTES)
        writer = None
        try:
            writer = fg.open_mcap(path, allow_overwrite=True, context=self._context,
                                  writer_options=options)
            writer.write_metadata("wheelgate", {
                "robot": self.robot_name,
                "wheels": json.dumps(list(wheel_names)),
                "steering": json.dumps(list(steer_names)),
            })
        except Exception as err:  # OSError mostly; the SDK's own errors are RuntimeErrors
            if writer is not None:
                writer.close()
            raise LiveViewError(f"foxglove: cannot record the live view to {path!r} (expected "
                                f"a file that can be written): {err}") from err
        return writer

    def _stop_sinks(self) -> None:
        server, self._server = self._server, None
        writer, self._writer = self._writer, None
        if server is not None:
            try:
                server.stop()
            except Exception:  # closing is best effort: the process ends next
                log.exception("foxglove: stopping the server at %s failed", self.url)
        if writer is not None:
            try:
                writer.close()
            except Exception:
                log.exception("foxglove: finishing the recording %s failed", self.mcap_path)

    # ----------------------------------------------------------------- the caller's side

    def start(self) -> None:
        """Start the worker thread (once; does nothing after :meth:`close`)."""
        with self._lock:
            if self._thread is not None or self._closed:
                return
            self._flush_at = time.monotonic() + FLUSH_S
            self._thread = threading.Thread(target=self._work, name="wheelgate-liveview",
                                            daemon=True)
            self._thread.start()

    def close(self, timeout_s: float = CLOSE_TIMEOUT_S) -> None:
        """Publish what is pending, end the worker (waiting ``timeout_s`` at most), stop the
        server and finish the MCAP file.  Idempotent."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
            thread = self._thread
        self.mailbox.close()
        if thread is not None:
            thread.join(timeout_s)
            if thread.is_alive():
                log.warning("foxglove: the live view's worker did not end within %.1f s",
                            timeout_s)
        self._stop_sinks()

    def stats(self) -> LiveViewStats:
        """What the worker did so far."""
        return LiveViewStats(self._snapshots, self._errors, self._dropped, self._failures,
                             self._bad_data, self._diagnostics)

    def __enter__(self) -> LiveView:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ----------------------------------------------------------------- the worker

    def _work(self) -> None:
        while True:
            news = self.mailbox.take(WORKER_WAKE_S)
            try:
                self._publish(news)
                self._flush()
            except Exception:  # a bug or an SDK error must not end the worker silently
                self._failures += 1
                log.exception("foxglove: publishing failed")
            if news.closed:
                return

    def _publish(self, news: Delivery[None]) -> None:
        snap = news.snapshot
        if snap is not None:
            self._snapshot(snap)
        elif news.status is not None:
            status = news.status
            self._guarded(STATE_TOPIC, lambda: self._channels.state(
                status.state, status.reason, self._now_ns()))
        if news.errors or news.errors_dropped:
            self._report_errors(news)
        if news.report is not None:
            report = news.report
            self._guarded(DIAGNOSTICS_TOPIC, lambda: self._diagnostics_report(report))

    def _diagnostics_report(self, report: GatewayStatus) -> None:
        t = self._now_ns()
        self._channels.diagnostics(diagnostic_array(report, self.robot_name, self.hardware, t), t)
        self._diagnostics += 1

    def _flush(self) -> None:
        writer = self._writer
        now = time.monotonic()
        if writer is None or now < self._flush_at:
            return
        self._flush_at = now + FLUSH_S
        self._guarded(self.mcap_path, writer.flush)

    def _guarded(self, topic: str, action: Callable[[], object]) -> None:
        try:
            action()
        except Exception as err:
            self._fail(topic, err)

    def _fail(self, topic: str, err: Exception) -> None:
        self._failures += 1
        if topic not in self._failed:
            self._failed.add(topic)
            log.error("foxglove: %s: a message failed (logged once for this channel; the "
                      "others go on): %s", topic, err, exc_info=err)

    def _bad(self, what: str, detail: str) -> bool:
        if what not in self._failed:
            self._failed.add(what)
            log.warning("foxglove: bad data in a snapshot (logged once): %s", detail)
        return True

    @staticmethod
    def _now_ns() -> int:
        return time.time_ns()

    # ----------------------------------------------------------------- messages

    def _snapshot(self, snap: Snapshot) -> None:
        bad = False
        t = log_time_ns(snap.stamp_ns)
        if t is None:
            bad = self._bad("stamp_ns", f"expected stamp_ns as ns since the epoch (an int in "
                                        f"[0, 2**64)), got {snap.stamp_ns!r}: stamped with the "
                                        "clock")
            t = self._now_ns()
        xyt: Planar | None = None
        try:
            pose = snap.odometry.pose
            xyt = planar(pose)
            if xyt is None:
                bad = self._bad("pose", f"expected a finite pose, got {pose}: left out of "
                                        f"{TF_TOPIC} and {POSE_TOPIC}")
        except Exception as err:  # not a pose at all (/odom fails too, and says so)
            bad = True
            self._fail(TF_TOPIC, err)
        for topic, publish in self._channels.per_snapshot:
            try:
                publish(snap, t, xyt)
            except Exception as err:
                self._fail(topic, err)
        self._snapshots += 1
        self._bad_data += bad

    def _report_errors(self, news: Delivery[None]) -> None:
        lines: list[tuple[bool, str]] = []
        if news.errors_dropped:
            self._dropped += news.errors_dropped
            lines.append((False, f"{news.errors_dropped} errors dropped: the live view fell "
                                 f"more than {MAX_ERRORS} errors behind"))
        for err in news.errors:
            code = getattr(err, "code", None)
            name = code.name.lower() if isinstance(code, enum.Enum) else str(code)
            lines.append((True, f"{name}: {getattr(err, 'message', err)}"))
        for error, text in lines:
            # Strictly increasing, so a reader sorting by log time keeps their order.
            t = self._last_error_ns = max(self._now_ns(), self._last_error_ns + 1)
            try:
                self._channels.log(error, text, t)
            except Exception as exc:
                self._fail(ERRORS_TOPIC, exc)
                continue
            self._errors += error
