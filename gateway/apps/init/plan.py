"""``wheelgate init``'s choices applied to a shipped example: the text of a new configuration.

:func:`generate` starts from the example's text with its comments
(:mod:`gateway.apps.init.annotated`), puts the drive motors on another driver if asked (the
driver's protocol keys, with their comments, come from the first shipped example that uses
it), gives the controllers the node IDs of a scan if given (:mod:`gateway.apps.init.nodes`),
and adds what each block means and what to measure or fill in
(:mod:`gateway.apps.init.notes`).  Nothing here reads or writes a file: the examples come in
as text, the configuration goes out as text.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from gateway.apps.init import notes
from gateway.apps.init.annotated import Document, read, render
from gateway.apps.init.nodes import FoundNode, assign, controllers
from gateway.config.keys import MOTOR_KEYS
from gateway.core.errors import ConfigError, DriverNotFoundError
from gateway.drive.registry import get_driver_class

if TYPE_CHECKING:
    from collections.abc import Collection, Mapping, Sequence

    from gateway.apps.init.annotated import KeyPath
    from gateway.apps.init.nodes import Assignment
    from gateway.core.options import OptionSpec


@dataclass(frozen=True, slots=True)
class Written:
    """A configuration made by :func:`generate`.

    :param example: the shipped example it started from.
    :param drive: its ``drive:``.
    :param drivers: the drive motors' drivers.
    :param text: the YAML, with comments.
    :param files: shipped files it names, by name, that belong beside it (a DBC file).
    :param assignments: the node IDs a scan gave, per controller.
    :param unused: the scanned nodes of protocols no controller uses.
    :param bus: the ``bus:`` keys given (``--interface``, ``--channel``, ``--bitrate``).
    :param bus_was: the example's ``bus:`` block, in words, when ``bus`` changed it.
    """

    example: str
    drive: str
    drivers: tuple[str, ...]
    text: str
    files: tuple[str, ...] = ()
    assignments: tuple[Assignment, ...] = ()
    unused: tuple[FoundNode, ...] = ()
    bus: Mapping[str, str | int] = dataclasses.field(default_factory=dict)
    bus_was: str = ""


@dataclass(frozen=True, slots=True)
class Chosen:
    """The example ``--drive`` chose.

    :param example: its name.
    :param drive: the drive it was chosen for (``None``: chosen by its name).
    :param others: the other examples of that drive, by name.
    """

    example: str
    drive: str | None = None
    others: tuple[str, ...] = ()


def choose(examples: Mapping[str, str], wanted: str,
           by_drive: Mapping[str, str] | None = None) -> Chosen:
    """The example ``--drive wanted`` names: the one of that name, else, for a drive, its
    example in ``by_drive`` (:data:`gateway.apps.init.shipped.BY_DRIVE`), else the only one
    with ``drive: wanted``.

    :raises ConfigError: naming the examples to choose from.
    """
    if wanted in examples:
        return Chosen(wanted)
    same = sorted(n for n, text in examples.items()
                  if read(text, f"{n}.yaml").data.get("drive") == wanted)
    first = (by_drive or {}).get(wanted)
    if first not in same:
        first = same[0] if len(same) == 1 else None
    if first is not None:
        return Chosen(first, wanted, tuple(n for n in same if n != first))
    if same:
        raise ConfigError(f"--drive {wanted}: {len(same)} shipped examples have drive: {wanted} "
                          f"({', '.join(same)}) and none is its first; expected the name of one")
    kinds = sorted({str(read(t, f"{n}.yaml").data.get("drive")) for n, t in examples.items()})
    raise ConfigError(f"--drive {wanted}: no shipped example of that name or drive; expected "
                      f"one of {', '.join(sorted(examples))}, or a drive: {', '.join(kinds)}")


def generate(
    examples: Mapping[str, str],
    name: str,
    driver: str | None = None,
    found: Sequence[FoundNode] | None = None,
    scan_source: str = "",
    file: str = "robot.yaml",
    shipped: Collection[str] = (),
    place: Mapping[str, str] | None = None,
    bus: Mapping[str, str | int] | None = None,
) -> Written:
    """A commented configuration from the example ``name``.

    :param examples: every shipped example's text, by name.
    :param driver: the drive motors' driver, if not the example's.
    :param found: the nodes of a scan, to give the controllers (``None``: keep the example's).
    :param scan_source: where the scan came from, for messages.
    :param file: where the configuration will be written, for its comments.
    :param shipped: the names of the shipped files other than the examples (DBC files).
    :param place: how to name a shipped file the configuration uses (default: by its name,
        beside the configuration).
    :param bus: ``bus:`` keys to set (``interface``, ``channel``, ``bitrate``: the root options).
    :raises ConfigError: for an unknown driver, or a scan that does not fit.
    """
    doc = read(examples[name], f"{name}.yaml")
    drive = str(doc.data.get("drive"))
    changes = []
    was = _motor_drivers(doc)
    if driver is not None and was != (driver,):
        _check_driver(driver)
        template = _template(examples, driver)
        _switch(doc, driver, template[1] if template else None)
        source = f"from the example {template[0]!r}" if template else "none from an example"
        changes.append(f"Its drive motors are on the {driver} driver (the example's: "
                       f"{', '.join(was)}; protocol keys {source}).")
        changes += _renumber(doc, driver) + _only_bitrate(doc, driver)
    assignments: tuple[Assignment, ...] = ()
    unused: tuple[FoundNode, ...] = ()
    if found is not None:
        assignments, unused = assign(doc, found, scan_source)
        changes.append(f"Node IDs from the scan {scan_source}, in order: check each wheel's.")
    bus_was = _set_bus(doc, bus or {})
    if bus:
        changes.append(f"Its bus: {', '.join(f'{k} {v}' for k, v in bus.items())}, as given "
                       f"to init (the example's: {bus_was}).")
    files = _shipped_files(doc, shipped, place or {})
    _annotate(doc, drive)
    doc.header = notes.header(name, drive, tuple(changes), file, doc.header)
    return Written(name, drive, _motor_drivers(doc), render(doc), files, assignments, unused,
                   dict(bus or {}), bus_was if bus else "")


def _set_bus(doc: Document, bus: Mapping[str, str | int]) -> str:
    """Set the ``bus:`` keys ``bus`` gives; the example's block before, in words."""
    block = doc.get(("bus",))
    was = (", ".join(f"{k} {v}" for k, v in block.items()) if isinstance(block, dict) and block
           else "none")
    if bus:
        if not isinstance(block, dict):
            doc.insert(("bus",), {})
        doc.data["bus"].update(bus)
    return was


def describe(examples: Mapping[str, str]) -> list[tuple[str, str, str]]:
    """``(name, drive, drivers)`` of every example, for a listing (steering actuators'
    drivers marked as such)."""
    out = []
    for name in sorted(examples):
        doc = read(examples[name], f"{name}.yaml")
        found = controllers(doc)
        motors = sorted({d for path, _, d in found if path[0] != "steering"})
        steering = sorted({d for path, _, d in found if path[0] == "steering"})
        drivers = ", ".join(motors) + "".join(f", {d} (steering)" for d in steering)
        out.append((name, str(doc.data.get("drive")), drivers))
    return out


def _motor_drivers(doc: Document) -> tuple[str, ...]:
    return tuple(sorted({d for path, _, d in controllers(doc) if path[0] != "steering"}))


def _check_driver(driver: str) -> None:
    try:
        get_driver_class(driver)
    except DriverNotFoundError as err:
        raise ConfigError(f"--driver: {err}") from err


def _protocol(driver: object) -> Mapping[str, OptionSpec]:
    """A driver's protocol keys (none if it cannot load: the loader will say why)."""
    try:
        return get_driver_class(str(driver)).OPTIONS
    except DriverNotFoundError:
        return {}


def _template(examples: Mapping[str, str], driver: str) -> tuple[str, Document] | None:
    """The first example (by name) whose ``motor_defaults:`` names ``driver``."""
    for name in sorted(examples):
        doc = read(examples[name], f"{name}.yaml")
        defaults = doc.data.get("motor_defaults")
        if isinstance(defaults, dict) and defaults.get("driver") == driver:
            return name, doc
    return None


def _switch(doc: Document, driver: str, template: Document | None) -> None:
    """Put every drive motor on ``driver``: the example's protocol keys out (defaults and
    motor blocks), the template's in, into ``motor_defaults:``."""
    blocks = [path for path, _, _ in controllers(doc) if path[0] != "steering"]
    for path in blocks:
        block = doc.get(path)
        for key in [k for k in block if k == "driver" or k not in MOTOR_KEYS]:
            doc.delete((*path, key))
    if not isinstance(doc.data.get("motor_defaults"), dict):
        doc.insert(("motor_defaults",), {},
                   before="wheels" if doc.data.get("drive") == "generic" else "motors")
    defaults: dict[str, Any] = doc.data["motor_defaults"]
    for key in [k for k in defaults if k == "driver" or k not in MOTOR_KEYS]:
        doc.delete(("motor_defaults", key))
    given: dict[str, Any] = {}
    if template is not None:
        given = {k: v for k, v in template.data["motor_defaults"].items()
                 if k not in MOTOR_KEYS}
    kept = dict(defaults)
    defaults.clear()
    defaults.update({"driver": driver, **given, **kept})
    for key in given:
        doc.adopt(template, ("motor_defaults", key), ("motor_defaults", key))  # type: ignore[arg-type]


def _renumber(doc: Document, driver: str) -> list[str]:
    """Number the drive motors from the lowest free node ID of ``driver`` when the example's
    are not its node IDs or are its steering actuators' (another protocol's numbering).

    :return: the line that says so, if it did.
    """
    motors = [path for path, _, _ in controllers(doc) if path[0] != "steering"]
    steering = {doc.get(path).get("node_id") for path, _, d in controllers(doc)
                if path[0] == "steering" and d == driver}
    low, high = get_driver_class(driver).node_id_range(doc.data["motor_defaults"])
    ids = [doc.get(path).get("node_id") for path in motors]
    if all(isinstance(i, int) and low <= i <= high and i not in steering for i in ids):
        return []
    free = iter([n for n in range(max(low, 1), high + 1) if n not in steering])
    for path in motors:
        doc.get(path)["node_id"] = next(free)
    return [f"The drive motors are numbered from node {max(low, 1)}: the example's node IDs "
            f"({', '.join(map(str, ids))}) are not free {driver} node IDs ({low}..{high})."]


def _only_bitrate(doc: Document, driver: str) -> list[str]:
    """Set ``bus.bitrate`` to the only bitrate of ``driver``'s controllers when the example's
    is another (DJI ESCs: 1 Mbit/s, fixed in them; ``check`` refuses any other).

    :return: the line that says so, if it did.
    """
    cls = get_driver_class(driver)
    rates = cls.BITRATES
    block = doc.get(("bus",))
    was = block.get("bitrate") if isinstance(block, dict) else None
    if not rates or was in rates:
        return []
    if not isinstance(block, dict):
        doc.insert(("bus",), {})
    doc.data["bus"]["bitrate"] = rates[0]
    return [f"Its bus runs at {rates[0]} bit/s, the only bitrate of the {cls.PROTOCOL} "
            f"controllers, fixed in them (the example's: {was if was is not None else 'none'})."]


def _shipped_files(doc: Document, shipped: Collection[str], place: Mapping[str, str]
                   ) -> tuple[str, ...]:
    """The shipped files the controllers' keys name (renamed as ``place`` says)."""
    paths: list[KeyPath] = [("motor_defaults",), ("steering_defaults",)]
    paths += [path for path, _, _ in controllers(doc)]
    files = set()
    for path in paths:
        block = doc.get(path)
        if not isinstance(block, dict):
            continue
        for key, value in block.items():
            if isinstance(value, str) and value in shipped:
                files.add(value)
                block[key] = place.get(value, value)
    return tuple(sorted(files))


def _annotate(doc: Document, drive: str) -> None:
    """What each block means, and what to measure or fill in, as comments."""
    for key, lines in notes.blocks(drive).items():
        if key in doc.data:
            doc.annotate((key,), above=lines, first=True)
    limits = doc.data.get("limits")
    if isinstance(limits, dict):
        doc.annotate(("limits",), above=notes.not_limited(limits))
    drivers = {"motor_defaults": _protocol(_block(doc, "motor_defaults").get("driver")),
               "steering_defaults": _protocol(_block(doc, "steering_defaults").get("driver"))}
    for block in ("geometry", "motor_defaults", "steering_defaults", "limits", "kinematics"):
        for key in _block(doc, block):
            path = (block, key)
            if key not in MOTOR_KEYS and path in doc.notes:
                continue  # a protocol key the example explains
            _note(doc, path, notes.key_note(block, key, drivers.get(block)))


def _block(doc: Document, key: str) -> dict[str, Any]:
    value = doc.data.get(key)
    return value if isinstance(value, dict) else {}


def _note(doc: Document, path: tuple[str, ...], text: str) -> None:
    """``text`` as the end comment of ``path``, or above it if the example has one there."""
    if not text:
        return
    old = doc.notes.get(path)
    if old is not None and old.end and old.end != text:
        doc.annotate(path, above=(text,))
    else:
        doc.annotate(path, end=text)
