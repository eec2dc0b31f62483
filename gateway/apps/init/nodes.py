"""Node IDs from a bus scan: ``wheelgate scan --json``'s output read, and its nodes put on the
controllers of a configuration, in order.

The scan's output is a JSON list of objects, one per row: a controller has a ``node_id`` and
the ``driver`` that speaks its ``protocol`` (CANopen nodes: ``cia402``); the gateway's own
messages and unknown identifiers have ``node_id: null`` and are skipped, as are the other
fields.  A row without ``driver`` is taken as ``protocol`` naming the driver.

The controllers are the drive motors in the order of the file (``motors:``, or the driven
wheels of ``wheels:``), then the steering actuators (``steering:``); those of one driver take
that driver's nodes in rising order, so the lowest node ID goes to the first wheel.  A scan
cannot tell which wheel a controller turns: the assignment is a start, to be checked by spinning
each wheel.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from gateway.core.errors import ConfigError

if TYPE_CHECKING:
    from collections.abc import Sequence

    from gateway.apps.init.annotated import Document, KeyPath


@dataclass(frozen=True, slots=True, order=True)
class FoundNode:
    """One controller that answered a scan.

    :param driver: the driver that speaks its protocol (``odrive``, ``cia402``, ...).
    :param node_id: its node ID.
    """

    driver: str
    node_id: int


@dataclass(frozen=True, slots=True)
class Assignment:
    """A controller of the configuration and the node it was given.

    :param block: where its block is in the file (``motors.front_left``).
    :param driver: its driver.
    :param node_id: the node ID it was given.
    """

    block: str
    driver: str
    node_id: int


def parse_scan(text: str, source: str) -> tuple[FoundNode, ...]:
    """The nodes of a ``wheelgate scan --json`` output, each once, sorted.

    :raises ConfigError: naming ``source`` and the entry, for text that is not such a list.
    """
    try:
        raw = json.loads(text)
    except ValueError as err:
        raise ConfigError(f"{source}: expected the JSON of `wheelgate scan --json`, got text "
                          f"that is not JSON ({err})") from err
    if not isinstance(raw, list):
        raise ConfigError(f"{source}: expected a JSON list of nodes (`wheelgate scan --json`), "
                          f"got {type(raw).__name__}")
    found = set()
    for i, entry in enumerate(raw):
        if not isinstance(entry, dict):
            raise ConfigError(f"{source}: [{i}]: expected an object with driver (or protocol) "
                              f"and node_id, got {entry!r}")
        node_id = entry.get("node_id")
        if node_id is None:
            continue  # the gateway's own messages, an unknown identifier
        driver = entry.get("driver") or entry.get("protocol")
        if not isinstance(driver, str):
            raise ConfigError(f"{source}: [{i}].driver: expected a driver name, got {driver!r}")
        if not isinstance(node_id, int) or isinstance(node_id, bool) or node_id < 0:
            raise ConfigError(f"{source}: [{i}].node_id: expected a node ID (an integer >= 0), "
                              f"got {node_id!r}")
        found.add(FoundNode(driver, node_id))
    return tuple(sorted(found))


def controllers(doc: Document) -> list[tuple[KeyPath, str, str]]:
    """``(block path, label, driver)`` of every controller, drive motors first, in file order."""
    data = doc.data
    out: list[tuple[KeyPath, str, str]] = []
    defaults = _mapping(data.get("motor_defaults"))
    if data.get("drive") == "generic":
        for i, wheel in enumerate(data.get("wheels") or []):
            motor = _mapping(wheel.get("motor")) if isinstance(wheel, dict) else {}
            if motor:
                label = f"wheels[{i}].motor ({wheel.get('name')})"
                out.append((("wheels", i, "motor"), label, _driver(motor, defaults)))
    else:
        for name, block in _mapping(data.get("motors")).items():
            out.append((("motors", name), f"motors.{name}", _driver(_mapping(block), defaults)))
    steer_defaults = _mapping(data.get("steering_defaults"))
    for name, block in _mapping(data.get("steering")).items():
        out.append((("steering", name), f"steering.{name}",
                    _driver(_mapping(block), steer_defaults)))
    return out


def _mapping(value: object) -> dict[str, Any]:
    return value if isinstance(value, dict) else {}


def _driver(block: dict[str, Any], defaults: dict[str, Any]) -> str:
    return str(block.get("driver", defaults.get("driver", "")))


def _ids(ids: Sequence[int]) -> str:
    return ", ".join(map(str, ids))


def assign(
    doc: Document, found: Sequence[FoundNode], source: str
) -> tuple[tuple[Assignment, ...], tuple[FoundNode, ...]]:
    """Give the controllers of ``doc`` the nodes ``found``, in order (see the module's doc),
    each marked with an end comment.

    :return: the assignments, and the nodes of drivers no controller uses.
    :raises ConfigError: naming ``source``, when a driver's count of nodes is not its count
        of controllers (every such driver, one line each; a driver with no node found names
        the drivers that were, and ``--driver`` for the drive motors).
    """
    wanted: dict[str, list[tuple[KeyPath, str]]] = {}
    motors = set()
    for path, label, driver in controllers(doc):
        wanted.setdefault(driver, []).append((path, label))
        if path[0] != "steering":
            motors.add(driver)
    ids: dict[str, list[int]] = {}
    for node in sorted(found):
        ids.setdefault(node.driver, []).append(node.node_id)
    others = {p: v for p, v in ids.items() if p not in wanted}
    problems = []
    for driver, blocks in wanted.items():
        have = ids.get(driver, [])
        if len(have) == len(blocks):
            continue
        labels = ", ".join(label for _, label in blocks)
        got = f"{len(have)} {driver} node(s) ({_ids(have)})" if have else f"no {driver} node"
        line = (f"{source}: the scan found {got}; expected {len(blocks)}, one per {driver} "
                f"controller ({labels})")
        if not have and others:
            line += "; it found " + "; ".join(f"{p} nodes {_ids(v)}" for p, v in others.items())
            fits = [p for p, v in others.items() if len(v) == len(blocks)]
            if driver in motors and fits:
                line += f" (--driver {fits[0]} puts the drive motors on those)"
        problems.append(line)
    if problems:
        raise ConfigError("\n".join(problems))
    out = []
    for driver, blocks in wanted.items():
        for (path, label), node_id in zip(blocks, ids[driver], strict=True):
            block = doc.get(path)
            block["node_id"] = node_id
            doc.annotate(path[:2], end=f"from the scan: {driver} node {node_id}")
            out.append(Assignment(label, driver, node_id))
    unused = tuple(FoundNode(p, i) for p, v in others.items() for i in v)
    return tuple(out), unused
