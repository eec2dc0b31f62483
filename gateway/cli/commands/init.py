"""``wheelgate init``: a commented configuration from a shipped example, or the systemd unit.

The text comes from :mod:`gateway.apps.init`; this edge reads the shipped files and the scan,
loads the result from a temporary directory exactly as ``wheelgate check -c FILE`` will (so a
configuration ``check`` refuses is never written), and writes it, with the DBC file it names if
it names one, never over an existing file without ``--force``.  ``-o`` naming a directory, or a
path through a file, is refused naming it; the directories of ``-o`` that do not exist are
created, and said (the README's systemd steps write /etc/wheelgate/robot.yaml on a machine
without /etc/wheelgate).

``--drive`` takes an example's name or a drive (``differential``: the example
:data:`gateway.apps.init.shipped.BY_DRIVE` gives for it, the others named).  The root options
``--interface``/``--channel``/``--bitrate`` go into the written ``bus:`` block.  ``--unit``
writes the shipped unit with ``ExecStart=`` naming the ``wheelgate`` that runs
(:func:`running_wheelgate`).
"""

from __future__ import annotations

import contextlib
import dataclasses
import shutil
import sys
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING

import click

from gateway.apps.init import choose, describe, generate, parse_scan, shipped
from gateway.apps.init.unit import unit_text
from gateway.cli import UsageExit
from gateway.config import load_config
from gateway.config.budget import check_bus
from gateway.core.errors import ConfigError
from gateway.core.protection import Guard
from gateway.drive.driveset import DriveSet
from gateway.drive.registry import valid_drivers

if TYPE_CHECKING:
    from typing import BinaryIO

    from gateway.apps.init import Chosen, Written
    from gateway.core.settings import GatewayConfig

#: The configuration's file when no ``-o`` is given (the systemd unit reads
#: /etc/wheelgate/robot.yaml).
DEFAULT_OUTPUT = "robot.yaml"
#: ``-o`` for standard output.
STDOUT = "-"


@click.command()
@click.option("--drive", "example", metavar="EXAMPLE|DRIVE",
              shell_complete=lambda ctx, param, incomplete: [
                  n for n in sorted({*shipped.example_names(), *shipped.BY_DRIVE})
                  if n.startswith(incomplete)],
              help="The shipped example to start from: a name of --list, or a drive "
                   "(differential, omni, generic, ...: its simplest example, the others named).")
@click.option("--driver", metavar="NAME",
              shell_complete=lambda ctx, param, incomplete: [
                  n for n in valid_drivers() if n.startswith(incomplete)],
              help="Put the drive motors on this driver instead of the example's (its keys come "
                   "from a shipped example that uses it).")
@click.option("--from-scan", "scan", type=click.File("rb"), metavar="FILE",
              help="Give the controllers, in order, the node IDs of a saved `wheelgate scan "
                   "--json` output ('-': standard input, e.g. piped from the scan).")
@click.option("-o", "--output", metavar="FILE",
              help=f"Where to write: {DEFAULT_OUTPUT} (with --unit: {shipped.UNIT}) unless "
                   f"given (its missing directories are created); '{STDOUT}': standard "
                   f"output.")
@click.option("--force", is_flag=True, help="Replace files that exist.")
@click.option("--acknowledge-no-controller-stop", "acknowledged", is_flag=True,
              help="For controllers that cannot stop by themselves (DJI ESCs): you know, and "
                   "their power is cut by hardware when the computer stops (README, When "
                   "wheelgate dies).  Needed to write such a configuration.")
@click.option("--unit", is_flag=True, help="Write the systemd unit instead of a configuration.")
@click.option("--list", "listing", is_flag=True, help="List the shipped examples.")
@click.pass_context
def command(ctx: click.Context, example: str | None, driver: str | None, scan: BinaryIO | None,
            output: str | None, force: bool, acknowledged: bool, unit: bool,
            listing: bool) -> None:
    """Write a commented robot configuration from a shipped example, for `check` and `run`.

    It says what each block means and marks what to MEASURE on the robot and FILL IN; with
    --from-scan the controllers get the node IDs that answered a scan; the root options
    --interface/--channel/--bitrate go into its bus: block.  It never replaces a file unless
    --force.
    Example: wheelgate init --drive differential -o robot.yaml
    """
    if listing:
        _list()
        return
    if unit:
        if example or driver or scan:
            raise click.UsageError("--unit writes the systemd unit only; expected no --drive, "
                                   "--driver or --from-scan with it")
        target = output or shipped.UNIT
        program = running_wheelgate()
        text = unit_text(shipped.read_text(shipped.UNIT), program)
        created = _write(target, [(target, text.encode("utf-8"))], force, shipped.UNIT)
        _say_created(created)
        if target != STDOUT:
            starts = (f"it starts {program}" if program is not None else
                      "wheelgate was not found beside this Python nor on PATH: check its "
                      "ExecStart=")
            click.echo(f"wrote {target}: the systemd unit ({starts}); install it as "
                       f"/etc/systemd/system/{shipped.UNIT} (README, Running under systemd)")
        return
    if example is None:
        raise click.UsageError(f"Missing option '--drive': the example to start from, one of "
                               f"{', '.join(shipped.example_names())} (see --list), or a "
                               f"drive: {', '.join(sorted(shipped.BY_DRIVE))}")
    target = output or DEFAULT_OUTPUT
    obj = ctx.find_root().obj or {}
    bus: dict[str, str | int] = {k: obj[k] for k in ("interface", "channel", "bitrate")
                                 if obj.get(k) is not None}
    with contextlib.ExitStack() as stack:
        examples = _examples()
        chosen = choose(examples, example, shipped.BY_DRIVE)
        written = _generate(stack, examples, chosen.example, driver, scan, target, bus)
        config = _check(written, target, acknowledged)
        files = [(target, written.text.encode("utf-8"))]
        if target != STDOUT:
            beside = Path(target).parent
            files += [(str(beside / f), shipped.read(f)) for f in written.files]
        created = _write(target, files, force)
    _say_created(created)
    _summary(written, files[1:], config, target, _scan_name(scan), chosen)


def running_wheelgate() -> str | None:
    """The absolute path of the ``wheelgate`` console script that runs: beside this Python
    (a virtual environment's ``bin/``), else the one on ``PATH``; ``None`` when neither."""
    beside = Path(sys.executable).absolute().parent / "wheelgate"
    if beside.is_file():
        return str(beside)
    found = shutil.which("wheelgate")
    return str(Path(found).absolute()) if found else None


def _list() -> None:
    rows = describe(_examples())
    width = max(len(name) for name, _, _ in rows) + 2
    click.echo(f"{'example':<{width}}{'drive':<14}drivers")
    for name, drive, drivers in rows:
        click.echo(f"{name:<{width}}{drive:<14}{drivers}")


def _examples() -> dict[str, str]:
    return {name: shipped.read_text(name + shipped.SUFFIX) for name in shipped.example_names()}


def _generate(stack: contextlib.ExitStack, examples: dict[str, str], name: str,
              driver: str | None, scan: BinaryIO | None, target: str,
              bus: dict[str, str | int]) -> Written:
    """The configuration's text; on standard output, the shipped files it names are named
    where they are installed (there is no directory to put them beside it)."""
    others = [n for n in shipped.names() if not n.endswith(shipped.SUFFIX)]
    place = {}
    if target == STDOUT:
        place = {n: str(stack.enter_context(shipped.path_of(n))) for n in others}
    found = parse_scan(scan.read(), _scan_name(scan)) if scan is not None else None
    return generate(examples, name, driver, found, _scan_name(scan),
                    "robot.yaml" if target == STDOUT else target, others, place, bus)


def _scan_name(scan: BinaryIO | None) -> str:
    """How messages name the scan's file (``<stdin>`` for ``-``); ``""`` without one."""
    return "" if scan is None else str(getattr(scan, "name", "<stdin>"))


def _check(written: Written, target: str, acknowledged: bool) -> GatewayConfig:
    """The configuration loaded as ``wheelgate check -c`` will load it, from a temporary
    directory holding it and the files it names; see :func:`_acknowledge`.

    :raises ConfigError: what ``check`` would say, naming ``target``.
    """
    shown = "<stdout>" if target == STDOUT else target
    with tempfile.TemporaryDirectory(prefix="wheelgate-init-") as folder:
        path = Path(folder) / Path(shown).name
        path.write_text(written.text, encoding="utf-8")
        for name in written.files:
            (Path(folder) / name).write_bytes(shipped.read(name))
        try:
            config = load_config(path)
            drives = DriveSet(config)  # (the drivers may read the files named)
            bus = check_bus(config, drives)  # (what `check` adds to the loader's checks)
        except ConfigError as err:
            raise ConfigError(
                f"the configuration made from {written.example!r} does not pass `wheelgate "
                f"check`, so it was not written:\n" + str(err).replace(str(path), shown)
            ) from err
        _acknowledge(drives, acknowledged)
        return dataclasses.replace(config, warnings=(*config.warnings, *bus))


def _acknowledge(drives: DriveSet, acknowledged: bool) -> None:
    """The examples acknowledge for the demo that their DJI ESCs cannot stop by themselves
    (``no_controller_stop: acknowledged``, which ``run`` requires): a file written for a robot
    says so only when its builder does, with ``--acknowledge-no-controller-stop``.

    :raises click.UsageError: for such controllers without the flag (nothing is written).
    """
    unguarded = [label for label, p in drives.protections() if p.guard is Guard.NONE]
    if unguarded and not acknowledged:
        raise click.UsageError(
            f"the controllers of {', '.join(unguarded)} cannot stop by themselves (no command "
            f"timeout is known): if wheelgate dies, they keep their last current, and the "
            f"wheels their torque, until their power goes.  Power them through a relay or "
            f"e-stop loop that opens when the computer stops feeding a hardware watchdog "
            f"(README, When wheelgate dies), then run init again with "
            f"--acknowledge-no-controller-stop: the file then says `no_controller_stop: "
            f"acknowledged`, which `wheelgate run` requires.  Nothing was written.")


def _write(target: str, files: list[tuple[str, bytes]], force: bool,
           default: str = DEFAULT_OUTPUT) -> list[Path]:
    """Write every file, or none when one exists and ``force`` is not given (a shipped file
    beside the configuration that is there already with the same bytes is left as it is), or
    when a path cannot be a file (:func:`_check_path`).  The directories it names that do not
    exist are created (the README's systemd steps write /etc/wheelgate/robot.yaml on a machine
    that has no /etc/wheelgate yet).

    :param default: the file's name when ``-o`` is not given, for the advice.
    :return: the directories it created, to be said.
    :raises UsageExit: naming the path, what was expected and what is there.
    """
    if target == STDOUT:
        click.echo(files[0][1].decode("utf-8"), nl=False)
        return []
    for name, _ in files:
        _check_path(name, default)
    exist = [name for name, data in files if Path(name).exists()
             and (name == target or Path(name).read_bytes() != data)]
    if exist and not force:
        raise UsageExit(f"{', '.join(exist)}: the file exists; expected a new file (--force "
                        f"replaces it)")
    folder = Path(target).parent
    created = [d for d in (folder, *folder.parents) if not d.exists()][::-1]
    if created:
        try:
            folder.mkdir(parents=True, exist_ok=True)
        except OSError as err:
            raise click.ClickException(f"{created[0]}: could not create the directory for "
                                       f"{target}: {err.strerror}") from err
    for name, data in files:
        try:
            Path(name).write_bytes(data)
        except OSError as err:
            raise click.FileError(name, err.strerror) from err
    return created


def _check_path(name: str, default: str) -> None:
    """That ``name`` can be written as a file: it is no directory, and the nearest of its
    parents that exists is a directory.

    :raises UsageExit: naming the path, what was expected and what is there.
    """
    path = Path(name)
    if path.is_dir():
        raise UsageExit(f"{name}: a directory is there; expected the name of a file to write "
                        f"(e.g. {path / default}); --force replaces files only")
    for parent in path.parents:
        if parent.is_dir():
            return
        if parent.exists() or parent.is_symlink():
            what = "a file" if parent.is_file() else "not a directory"
            raise UsageExit(f"{name}: {parent} is {what}; expected a directory there")


def _say_created(created: list[Path]) -> None:
    """Say which directories were created for the files written."""
    for folder in created:
        click.echo(f"created {folder}: the directory did not exist")


def _summary(written: Written, beside: list[tuple[str, bytes]], config: GatewayConfig,
             target: str, scan: str, chosen: Chosen) -> None:
    """What was written and what to do next: on stdout, or on stderr when the configuration
    went there."""
    err = target == STDOUT
    def say(line: str) -> None:
        click.echo(line, err=err)
    where = "to standard output" if err else target
    say(f"wrote {where}: drive {written.drive}, from the example {written.example!r}, drive "
        f"motors on {', '.join(written.drivers)}")
    if chosen.drive is not None:
        others = (f"; the other examples of that drive: {', '.join(chosen.others)} (--drive "
                  f"NAME starts from one)" if chosen.others else "")
        say(f"--drive {chosen.drive}: {chosen.example!r} is the shipped example for drive: "
            f"{chosen.drive}{others}")
    if written.bus:
        say(f"bus: {', '.join(f'{k} {v}' for k, v in written.bus.items())} (from the root "
            f"options; the example's: {written.bus_was})")
    for name, _ in beside:
        say(f"wrote {name}: the file its motor blocks name (the example's; use your own)")
    if err and written.files:
        say(f"note: it names {', '.join(written.files)} where wheelgate is installed; copy "
            f"the file beside it and name it there")
    if written.assignments:
        say(f"node IDs from the scan {scan}, in order (check each wheel: wheelgate spin -c "
            f"{'FILE' if err else target} WHEEL):")
        width = max(len(a.block) for a in written.assignments) + 2
        for a in written.assignments:
            say(f"  {a.block:<{width}}{a.address()}")
    if written.unused:
        say("not used: " + ", ".join(f"{n.driver} node {n.node_id}" + (
            " (29-bit identifiers)" if n.extended else "") for n in written.unused))
    warned = f", with {len(config.warnings)} warning(s)" if config.warnings else ""
    check = "wheelgate check -c " + ("FILE" if err else target)
    say(f"check: ok{warned}; next: MEASURE and FILL IN what its comments mark, then {check}")
