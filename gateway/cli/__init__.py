"""The ``wheelgate`` command: a click group that loads one module per subcommand.

Errors are mapped to exit codes in one place: 0 ok, 1 other gateway error, 2 bad usage or
configuration, 3 infeasible twist (and ``spin``'s own 4: something to fix, with the advice).
``--debug`` re-raises to show the traceback.
"""

from __future__ import annotations

import importlib
import logging
import os
import sys
from typing import TYPE_CHECKING, Any, ClassVar

import click

from gateway import __version__
from gateway.core.errors import ConfigError, GatewayError, InfeasibleTwistError

if TYPE_CHECKING:
    from collections.abc import Callable

# numpy's OpenBLAS starts a worker thread per further CPU when numpy is imported, unless this
# is set before: wheelgate's matrices have a few rows, which OpenBLAS does not split across
# threads, so the workers only cost start-up and memory, all of it locked once the daemon
# locks its memory (`lock_memory`: 345 MB locked with one worker on a 2-CPU machine, 304 MB
# without).  The systemd unit sets it too; a value already in the environment is kept.
# (Set here, before any command's module imports numpy; a library user's process is left
# alone.)
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

#: Subcommand name -> module under ``gateway.cli.commands`` (``module:name`` for one of its
#: commands, else its ``command``).
COMMANDS: dict[str, str] = {
    "check": "check",
    "ik": "ik",
    "fk": "fk",
    "frames": "frames",
    "run": "run",
    "twist": "twist",
    "status": "status",
    "jog": "jog",
    "monitor": "monitor",
    "odom": "odom",
    "calibrate": "calibrate",
    "sim": "sim",
    "init": "init",
    "spin": "spin",
    "scan": "scan",
    "estop": "ops:estop",
    "enable": "ops:enable",
    "disable": "ops:disable",
}

EXIT_ERROR = 1
EXIT_USAGE = 2
EXIT_INFEASIBLE = 3


class InfeasibleExit(click.ClickException):
    """An infeasible twist: message on stderr, exit code 3."""

    exit_code = EXIT_INFEASIBLE


class ConfigExit(click.ClickException):
    """A configuration error: message on stderr, exit code 2."""

    exit_code = EXIT_USAGE


class UsageExit(click.ClickException):
    """Bad input that is not a typing error (a refusal): its message on stderr, exit code 2,
    and no "Usage: ... Try --help" lines (the command line was well formed)."""

    exit_code = EXIT_USAGE


class JournalFormatter(logging.Formatter):
    """Log lines for journald: a ``<N>`` syslog priority prefix (sd-daemon(3)) and no time
    stamp (the journal adds its own)."""

    _PRIORITY: ClassVar[dict[int, int]] = {
        logging.CRITICAL: 2, logging.ERROR: 3, logging.WARNING: 4, logging.INFO: 6,
        logging.DEBUG: 7,
    }

    def format(self, record: logging.LogRecord) -> str:
        prio = self._PRIORITY.get(record.levelno, 6)
        return f"<{prio}>{record.name}: {super().format(record)}"


class LazyGroup(click.Group):
    """A group that imports a subcommand's module only when it runs."""

    def list_commands(self, ctx: click.Context) -> list[str]:
        return sorted(COMMANDS)

    def get_command(self, ctx: click.Context, cmd_name: str) -> click.Command | None:
        where = COMMANDS.get(cmd_name)
        if where is None:
            return None
        module, _, name = where.partition(":")  # (a module of several commands names one)
        command: click.Command = getattr(
            importlib.import_module(f"gateway.cli.commands.{module}"), name or "command")
        return command

    def resolve_command(
        self, ctx: click.Context, args: list[str]
    ) -> tuple[str | None, click.Command | None, list[str]]:
        name, cmd, rest = super().resolve_command(ctx, args)
        # For invoke: a command line error of a command asked for JSON is answered in JSON.
        ctx.meta["wheelgate.json"] = cmd is not None and _asks_json(cmd, rest)
        return name, cmd, rest

    def invoke(self, ctx: click.Context) -> Any:
        try:
            return super().invoke(ctx)
        except click.UsageError as err:
            # click's own parse errors (``scan --json --timeout -1``) come before the command
            # runs, so the command cannot answer them in JSON itself.
            if not ctx.meta.get("wheelgate.json"):
                raise
            from gateway.cli.commands._guards import fail_json_of  # noqa: PLC0415 - rare path

            fail_json_of(ctx, err)
        except GatewayError as err:
            if ctx.obj and ctx.obj.get("debug"):
                raise
            if isinstance(err, InfeasibleTwistError):
                raise InfeasibleExit(str(err)) from err
            if isinstance(err, ConfigError):
                raise ConfigExit(str(err)) from err
            raise click.ClickException(str(err)) from err


def _asks_json(cmd: click.Command, args: list[str]) -> bool:
    """Whether ``args`` give ``cmd`` its ``--json`` flag: as an option, not as the value of
    another option (``--socket --json``) nor after ``--``."""
    if not any(p.name == "as_json" for p in cmd.params):
        return False
    takes_value = {name for p in cmd.params if isinstance(p, click.Option)
                   and not p.is_flag and not p.count for name in p.opts}
    skip = False
    for arg in args:
        if skip:
            skip = False
        elif arg == "--":
            return False
        elif arg == "--json":
            return True
        else:
            skip = arg in takes_value
    return False


@click.group(cls=LazyGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="wheelgate")
@click.option("--interface", help="python-can interface, overrides the config (e.g. socketcan).")
@click.option("--channel", help="CAN channel, overrides the config (e.g. can0).")
@click.option("--bitrate", type=int,
              help="CAN bitrate (bit/s), overrides the config (e.g. 1000000): set on an adapter "
                   "python-can drives, checked against a SocketCAN interface.")
@click.option("-v", "--verbose", count=True, help="More log output (repeat for debug).")
@click.option("--debug", is_flag=True, help="Show tracebacks instead of short errors.")
@click.pass_context
def main(
    ctx: click.Context, interface: str | None, channel: str | None, bitrate: int | None,
    verbose: int, debug: bool
) -> None:
    """wheelgate: twist in, wheel frames out, odometry back, over CAN."""
    level = logging.WARNING - 10 * min(verbose, 2)
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(JournalFormatter() if os.environ.get("JOURNAL_STREAM") else
                         logging.Formatter("%(asctime)s %(levelname)s %(name)s: %(message)s"))
    logging.basicConfig(level=level, handlers=[handler])
    if interface is not None:
        check_interface(interface, "--interface")
    ctx.obj = {"interface": interface, "channel": channel, "bitrate": bitrate, "debug": debug}


def check_interface(interface: str, hint: str) -> None:
    """A usage error (exit 2) naming python-can's interfaces when ``interface`` is none of them
    (python-can is imported here, not at start-up: only a command that names one pays)."""
    from can.interfaces import VALID_INTERFACES  # noqa: PLC0415 - see the docstring

    if interface not in VALID_INTERFACES:
        raise click.BadParameter(
            f"expected a python-can interface, one of {', '.join(sorted(VALID_INTERFACES))}; "
            f"got {interface!r}", param_hint=hint)


class FilePath(click.Path):
    """:class:`click.Path` that refuses an empty string (which click takes as a path: an
    empty ``--socket ''`` would quietly mean the default)."""

    def convert(self, value: Any, param: click.Parameter | None,
                ctx: click.Context | None) -> Any:
        if isinstance(value, str) and not value:
            self.fail("expected a path, got an empty string", param, ctx)
        return super().convert(value, param, ctx)


def config_option(func: Callable[..., Any]) -> Callable[..., Any]:
    """The ``-c/--config FILE`` option shared by subcommands (embedded default if omitted)."""
    return click.option(
        "-c",
        "--config",
        "config_path",
        type=FilePath(dir_okay=False),
        default=None,
        help="Robot configuration (YAML). Default: the embedded demo robot.",
    )(func)


def json_option(func: Callable[..., Any]) -> Callable[..., Any]:
    """The ``--json`` flag shared by subcommands."""
    return click.option("--json", "as_json", is_flag=True, help="Machine-readable output.")(func)
