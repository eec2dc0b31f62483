"""What the commands refuse and how, beside :mod:`gateway.cli.commands._common`: the bound of
a duration option, and a failure as a JSON object on stdout for ``--json``.

Numbers are bounded as everywhere in the CLI: ``click.FloatRange`` with the bound in the
option (shown in ``--help``), and :func:`~gateway.cli.commands._common.check_finite` for NaN,
which passes every range (its comparisons are all false).
"""

from __future__ import annotations

import contextlib
import json
import signal
import threading
from typing import TYPE_CHECKING, NoReturn

import click

from gateway.cli import EXIT_ERROR, EXIT_USAGE
from gateway.core.errors import BusError, ConfigError, GatewayError
from gateway.runtime.client import ClientError

if TYPE_CHECKING:
    from collections.abc import Iterator, Sequence
    from types import FrameType

#: The longest ``--duration`` of a command (s): a day; more is surely a mistake (and beyond
#: what a timer takes: ``1e300`` s overflows the platform's ``time_t``).
MAX_DURATION_S = 86_400.0


def error_code(err: Exception) -> tuple[str, int]:
    """The JSON error code and the exit code of a failure (or of the error it wraps):
    ``no_gateway`` (no daemon answers: 1), ``bus_unavailable`` (1), ``bad_config`` (2),
    ``bad_usage`` (a click exception of exit code 2), else ``error`` (1, or the click
    exception's code)."""
    for cause in (err, err.__cause__):
        if isinstance(cause, ClientError):
            return "no_gateway", EXIT_ERROR
        if isinstance(cause, BusError):
            return "bus_unavailable", EXIT_ERROR
        if isinstance(cause, ConfigError):
            return "bad_config", EXIT_USAGE
    if isinstance(err, click.ClickException):
        return ("bad_usage" if err.exit_code == EXIT_USAGE else "error"), err.exit_code
    return "error", EXIT_ERROR


def fail_json(ctx: click.Context, code: str, exit_code: int = EXIT_ERROR, *, message: str,
              warnings: Sequence[str] = ()) -> NoReturn:
    """Print ``{"ok": false, "error": {"code", "message"}}`` (and ``"warnings"`` when there
    are any) on stdout, as ``status --json`` answers without a daemon, and exit."""
    doc: dict[str, object] = {"ok": False, "error": {"code": code, "message": message}}
    if warnings:
        doc["warnings"] = list(warnings)
    click.echo(json.dumps(doc))
    ctx.exit(exit_code)


def fail_json_of(ctx: click.Context, err: click.ClickException | GatewayError) -> NoReturn:
    """:func:`fail_json` for a command's failure ``err``: its code, exit code and message
    (:func:`error_code`; a click exception's message as click would print it)."""
    message = err.format_message() if isinstance(err, click.ClickException) else str(err)
    fail_json(ctx, *error_code(err), message=message)


#: The signals that end a command which must send stop first (``twist --duration``, ``jog``).
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


@contextlib.contextmanager
def caught_signals(wakeup_fd: int | None = None, active: bool = True) -> Iterator[list[str]]:
    """While it lasts, :data:`STOP_SIGNALS` are collected by name (the command then ends and
    sends stop) instead of ending the program with the robot still driving; ``wakeup_fd``
    (``signal.set_wakeup_fd``) wakes a ``select`` loop.  Nothing is caught unless ``active``,
    nor outside the main thread (no signal handlers there)."""
    caught: list[str] = []
    if not active or threading.current_thread() is not threading.main_thread():
        yield caught
        return

    def handler(signum: int, frame: FrameType | None) -> None:
        caught.append(signal.Signals(signum).name)

    old_fd = None if wakeup_fd is None else signal.set_wakeup_fd(wakeup_fd)
    old = {s: signal.signal(s, handler) for s in STOP_SIGNALS}
    try:
        yield caught
    finally:
        for s, h in old.items():
            signal.signal(s, h)
        if old_fd is not None:
            signal.set_wakeup_fd(old_fd)
