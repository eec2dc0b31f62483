"""Node IDs from a bus scan: ``wheelgate scan --json``'s output read, and its nodes put on the
controllers of a configuration, in order.

The scan's output is a JSON list of objects, one per row: a controller has a ``node_id``, the
``driver`` that speaks its ``protocol`` (CANopen nodes: ``cia402``) and ``extended_id``, whether
it answered on 29-bit identifiers (11-bit when absent); the gateway's own messages and unknown
identifiers have ``node_id: null`` and are skipped, as are the other fields.  A row without
``driver`` is taken as ``protocol`` naming the driver.

A node's address is its node ID and its identifier type.  A driver whose blocks choose the type
(a key ``extended_id``: ODrive, ``axis.config.can.is_extended``) gets it written into the block
that takes the node, where the block would otherwise say another (``extended_id: true`` for an
axis on 29-bit identifiers); the other drivers' protocols have one type each (VESC 29-bit,
CANopen and DJI 11-bit), which is all their probes find.

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

from gateway.apps.scan.known import EXTENDED_KEY, extended_spec
from gateway.core.errors import ConfigError

if TYPE_CHECKING:
    from collections.abc import Sequence

    from gateway.apps.init.annotated import Document, KeyPath


#: The motor-block key that chooses a node's identifier type, for the drivers that have one.


@dataclass(frozen=True, slots=True, order=True)
class FoundNode:
    """One controller that answered a scan.

    :param driver: the driver that speaks its protocol (``odrive``, ``cia402``, ...).
    :param node_id: its node ID.
    :param extended: whether it answered on 29-bit identifiers.
    """

    driver: str
    node_id: int
    extended: bool = False


@dataclass(frozen=True, slots=True)
class Assignment:
    """A controller of the configuration and the node it was given.

    :param block: where its block is in the file (``motors.front_left``).
    :param driver: its driver.
    :param node_id: the node ID it was given.
    :param extended: whether the node is on 29-bit identifiers.
    """

    block: str
    driver: str
    node_id: int
    extended: bool = False

    def address(self) -> str:
        """``odrive node 1`` (``... on 29-bit identifiers``)."""
        return f"{self.driver} node {self.node_id}" + (
            " on 29-bit identifiers" if self.extended else "")


def parse_scan(text: str | bytes, source: str) -> tuple[FoundNode, ...]:
    """The nodes of a ``wheelgate scan --json`` output (its text, or the bytes of its file),
    each once, sorted.

    :raises ConfigError: naming ``source`` and the entry, for text that is not such a list, or
        bytes that are not UTF-8 (the byte and its offset, as the configuration loader says
        it of a configuration file).
    """
    if isinstance(text, bytes):
        try:
            text = text.decode("utf-8")
        except UnicodeDecodeError as err:
            raise ConfigError(f"{source}: expected UTF-8 text (the JSON of `wheelgate scan "
                              f"--json`), got byte {err.object[err.start]:#04x} at offset "
                              f"{err.start}") from err
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
        extended = entry.get("extended_id", False)
        if not isinstance(extended, bool):
            raise ConfigError(f"{source}: [{i}].extended_id: expected true (29-bit identifiers) "
                              f"or false (11-bit), got {extended!r}")
        found.add(FoundNode(driver, node_id, extended))
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
    nodes: dict[str, list[FoundNode]] = {}
    for node in sorted(found):
        ids.setdefault(node.driver, []).append(node.node_id)
        nodes.setdefault(node.driver, []).append(node)
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
        for (path, label), node in zip(blocks, nodes[driver], strict=True):
            block = doc.get(path)
            block["node_id"] = node.node_id
            _address(doc, path, driver, node.extended)
            done = Assignment(label, driver, node.node_id, node.extended)
            doc.annotate(path[:2], end=f"from the scan: {done.address()}")
            out.append(done)
    unused = tuple(n for p in others for n in nodes[p])
    return tuple(out), unused


def _address(doc: Document, path: KeyPath, driver: str, extended: bool) -> None:
    """Write the node's identifier type into the block at ``path`` when its driver takes one
    (see the module's doc) and the block, or the defaults it takes it from, says another."""
    spec = extended_spec(driver)
    if spec is None:
        return
    block = doc.get(path)
    defaults = _mapping(doc.data.get("steering_defaults" if path[0] == "steering"
                                     else "motor_defaults"))
    if block.get(EXTENDED_KEY, defaults.get(EXTENDED_KEY, spec.default)) != extended:
        block[EXTENDED_KEY] = extended
