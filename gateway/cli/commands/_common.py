"""Helpers shared by subcommands: loading the config with CLI overrides, parsing twists, and
``--json`` failures of the commands that compute (:func:`json_failures`)."""

from __future__ import annotations

import contextlib
import json
import math
import os
from pathlib import Path
from typing import TYPE_CHECKING, Any

import click

from gateway.cli import EXIT_INFEASIBLE, UsageExit
from gateway.config import client_socket_path, load_config
from gateway.core.errors import GatewayError, InfeasibleTwistError
from gateway.core.types import MAX_TWIST_COMPONENT

if TYPE_CHECKING:
    from collections.abc import Collection, Iterator

    from gateway.core.settings import GatewayConfig
    from gateway.core.types import Twist


#: What to do instead of a ``virtual`` bus when processes must share it.
VIRTUAL_HINT = (
    "to share a bus between processes, use a kernel one: sudo modprobe vcan && sudo ip link add "
    "vcan0 type vcan && sudo ip link set vcan0 up, then give every command "
    "--interface socketcan --channel vcan0 (see 'A real kernel bus without hardware' in the "
    "README)"
)


def load(ctx: click.Context, path: str | None,
         interfaces: Collection[str] | None = None) -> GatewayConfig:
    """The configuration at ``path`` (or the shipped example it names,
    :func:`config_file`) with the root group's bus overrides; ``bus.interface`` checked
    against ``interfaces`` with the file's other problems when given."""
    obj = ctx.find_root().obj or {}
    return load_config(config_file(ctx, path),
                       {"interface": obj.get("interface"), "channel": obj.get("channel"),
                        "bitrate": obj.get("bitrate")},
                       interfaces)


def bitrate_stated(ctx: click.Context, path: str | None) -> bool:
    """Whether the bus's bitrate was said (``-c``, ``--bitrate`` or ``GATEWAY_BITRATE``), not
    the embedded demo's: a command that may run without a configuration (``scan``) sets and
    checks only a bitrate it was told."""
    obj = ctx.find_root().obj or {}
    return (path is not None or obj.get("bitrate") is not None
            or os.environ.get("GATEWAY_BITRATE") is not None)


def config_file(ctx: click.Context, path: str | None) -> str | None:
    """``-c path`` as a file to read: ``path`` itself, unless no such file is here and it is a
    bare name (no directory) of a shipped example, ``NAME`` or ``NAME.yaml`` (``wheelgate init
    --list``): then that example where it is installed, said once on stderr.  A file that
    exists always wins."""
    if path is None or os.sep in path or (os.altsep and os.altsep in path) or Path(path).exists():
        return path
    if Path(path + ".yaml").is_file():  # a file here wins, with or without its suffix too
        return path + ".yaml"
    # Imported here: only a missing file pays for it (the commands' start-up does not).
    from gateway.apps.init.shipped import example_file  # noqa: PLC0415

    found = example_file(path)
    if found is None:
        return path
    root = ctx.find_root()
    said = root.meta.setdefault("wheelgate.shipped_said", set())
    if path not in said and not ctx.resilient_parsing:  # (not while completing a command)
        said.add(path)
        click.echo(f"-c {path}: no such file here; using the shipped example "
                   f"{found.stem!r} ({found})", err=True)
    return str(found)


def socket_for(ctx: click.Context, config_path: str | None, socket_path: str | None) -> str:
    """The daemon's socket: ``--socket``, else the config's ``gateway.socket`` (with ``-c``),
    else the default path."""
    if socket_path:
        return socket_path
    if config_path is not None:
        cfg = load(ctx, config_path)
        if cfg.loop.socket:
            return cfg.loop.socket
    return client_socket_path()


def _other_robot(ours: GatewayConfig, config_path: str, running: object) -> str | None:
    """Why the daemon's robot (``running``: its status's ``robot``) is not that of ``ours``
    (the file ``config_path``, loaded); ``None`` when it is, or when it does not say."""
    if not isinstance(running, str) or running == ours.name:
        return None
    return (f"the daemon on this socket runs the robot {running!r}, not {ours.name!r} of "
            f"{config_path}")


def daemon_runs(ctx: click.Context, config_path: str | None,
                reply: dict[str, Any]) -> tuple[str | None, str | None]:
    """With ``-c``, what the daemon's status ``reply`` says against the file, which is read
    once: why its robot is another, or else what to know when it runs
    this robot from another text (:func:`other_text`); ``(None, None)`` without ``-c``."""
    if config_path is None:
        return None, None
    ours = load(ctx, config_path)
    why = _other_robot(ours, config_path, reply.get("robot"))
    return why, None if why is not None else other_text(ours, config_path, reply.get("config"))


def other_text(ours: GatewayConfig, config_path: str, running: object) -> str | None:
    """When the daemon runs the robot of ``ours`` (the file ``config_path``, loaded) from a
    text other than the file's (``running``: its status's ``config``, path and fingerprint):
    what to know, e.g. the file was edited after the daemon read it; ``None`` when the texts
    are the same, or when there is nothing to compare (an earlier daemon, a configuration not
    from a file)."""
    if not isinstance(running, dict):
        return None
    path, theirs = running.get("path"), running.get("fingerprint")
    if not isinstance(path, str) or not isinstance(theirs, str) or not theirs \
            or not ours.fingerprint or theirs == ours.fingerprint:
        return None
    if _same_file(path, ours.source):
        return (f"the daemon runs {path} as it was when the daemon started; the file has "
                f"changed since (restart the daemon to use the change)")
    return (f"the daemon runs the robot {ours.name!r} from {path}, whose text differs from "
            f"{config_path}'s (CRC-32 {theirs} and {ours.fingerprint})")


def _same_file(a: str, b: str) -> bool:
    try:
        return Path(a).resolve() == Path(b).resolve()
    except (OSError, ValueError):  # (a path the reply made up: too long, a NUL in it)
        return False


def daemon_config(ctx: click.Context, reply: dict[str, Any]) -> tuple[GatewayConfig | None, str]:
    """Without ``-c``: the configuration the daemon runs (its status ``reply``) read from its
    file, when this process can read it and it is that robot's, with a warning when the file
    has changed since the daemon read it (:func:`other_text`); ``(None, "")`` otherwise (the
    caller keeps the embedded default's, and says so when the daemon runs another robot)."""
    running = reply.get("config")
    path = running.get("path") if isinstance(running, dict) else None
    if not isinstance(path, str):
        return None, ""
    try:
        cfg = load(ctx, path) if Path(path).is_file() else None
    except (GatewayError, OSError, ValueError):  # unreadable here (a 0700 directory), invalid
        return None, ""
    if cfg is None or cfg.name != reply.get("robot"):
        return None, ""
    note = other_text(cfg, path, running)
    return cfg, "" if note is None else f"warning: {note}"


def refuse_other_robot(ctx: click.Context, config_path: str | None, client: Any) -> str:
    """Before driving with ``-c``: a usage error (exit 2) when the daemon runs another robot
    (a TurtleBot's twist must not drive the mecanum).

    :return: a warning when it runs this one from another text (:func:`other_text`), else
        ``""``.
    """
    if config_path is None:
        return ""
    why, note = daemon_runs(ctx, config_path, client.request({"op": "status"}))
    if why is not None:
        raise UsageExit(f"{why}: refusing to drive it (drop -c, or use its socket)")
    return "" if note is None else f"warning: {note}"


def twist_options(func: Any) -> Any:
    """``--vx --vy --wz`` options."""
    # Bounded as the control socket bounds a twist (MAX_TWIST_COMPONENT): a larger value is a
    # usage error (exit 2) in every command, never 300-digit output or a refusal by the daemon.
    bound = click.FloatRange(-MAX_TWIST_COMPONENT, MAX_TWIST_COMPONENT)
    for name, unit in (("wz", "rad/s, CCW positive"), ("vy", "m/s, left"), ("vx", "m/s, forward")):
        func = click.option(f"--{name}", type=bound, default=0.0, show_default=True,
                            help=f"Body twist component ({unit}, at most "
                                 f"{MAX_TWIST_COMPONENT:g} either way).")(func)
    return func


def check_finite(**values: float) -> None:
    """Reject NaN and infinity in numeric options (click accepts them as floats).

    :raises click.BadParameter: naming the option.
    """
    for name, value in values.items():
        if not math.isfinite(value):
            raise click.BadParameter(f"expected a finite number, got {value!r}",
                                     param_hint=f"--{name}")


def twist_json(t: Twist) -> dict[str, float]:
    """A twist as a JSON object."""
    return {"vx_m_s": t.vx_m_s, "vy_m_s": t.vy_m_s, "wz_rad_s": t.wz_rad_s}


def infeasible_json(err: InfeasibleTwistError) -> str:
    """The JSON error object printed on stdout for an infeasible twist with ``--json``: the
    shape of every ``--json`` failure (``{"ok": false, "error": {"code", "message"}}``) with
    the control socket's details of this one (README, the control socket's ``twist`` reply)."""
    return json.dumps({"ok": False, "error": {
        "code": "infeasible_twist",
        "message": str(err),
        "wheel": err.wheel,
        "constraint": err.constraint,
        "residual_m_s": err.residual_m_s,
        "twist": twist_json(err.twist),
        "nearest": twist_json(err.nearest),
    }})


@contextlib.contextmanager
def json_failures(ctx: click.Context, as_json: bool) -> Iterator[None]:
    """With ``--json``, a failure in the block is a JSON object on stdout, as every command's
    (``{"ok": false, "error": {"code", "message"}}``: ``bad_config``, ``bad_usage``,
    ``bus_unavailable``, ``error``; an infeasible twist: :func:`infeasible_json`), with the
    exit code it has without ``--json`` (2, 2, 1, 1; 3).  Without ``--json``, it goes on as
    it came (the message on stderr)."""
    try:
        yield
    except InfeasibleTwistError as err:
        if not as_json:
            raise
        click.echo(infeasible_json(err))
        ctx.exit(EXIT_INFEASIBLE)
    except (GatewayError, click.ClickException) as err:
        if not as_json:
            raise
        # Imported here: only a failure pays for it (``ik``'s start-up does not).
        from gateway.cli.commands._guards import fail_json_of  # noqa: PLC0415

        fail_json_of(ctx, err)


def rad_s_to_rpm(value: float) -> float:
    """rad/s to revolutions per minute."""
    return value * 60.0 / (2.0 * math.pi)
