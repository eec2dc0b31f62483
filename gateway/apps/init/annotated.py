"""A configuration's YAML with its comments: read from an example, changed, written back.

PyYAML drops comments, yet the shipped examples' comments carry what a robot builder needs
(which VESC Tool setting a stated timeout is, why ODrive node 8 is left out).  :func:`read`
keeps them: it loads the data with the configuration's strict loader and, from the composed
nodes' line marks, ties each comment to the key it stands above or beside.  :class:`Document`
is that data with its comments and its flow-style marks, changed key by key, and
:func:`render` writes it as YAML again, in the example's style: a block written as a flow
mapping stays one (wrapped when long), every comment stands where it stood.

Only what configurations use is supported: mappings, sequences and scalars, comments on lines
of their own above a key or a sequence item, and comments at the end of a key's line.
"""

from __future__ import annotations

import dataclasses
import textwrap
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import yaml

from gateway.config.yaml_text import load_yaml, not_a_mapping
from gateway.core.errors import ConfigError

if TYPE_CHECKING:
    from collections.abc import Iterator, Mapping

#: A key path: mapping keys and sequence indexes from the top.
KeyPath = tuple["str | int", ...]

#: The longest line :func:`render` writes where it can choose (flow values are wrapped, end
#: comments move above their key).
WIDTH = 100
#: The column end comments start at, where the line leaves room.
END_COLUMN = 32


@dataclass(frozen=True, slots=True)
class Notes:
    """The comments of one key or sequence item (text without the ``#``).

    :param above: comment lines on lines of their own just above it.
    :param end: the comment at the end of its line.
    """

    above: tuple[str, ...] = ()
    end: str = ""


@dataclass
class Document:
    """A configuration's data with its comments, for changing and writing again.

    :param header: the comment lines at the top of the file, above the first key.
    :param data: the top-level mapping (plain YAML data).
    :param notes: comments by key path.
    :param flow: the key paths whose mapping or sequence is written in flow style.
    """

    header: tuple[str, ...]
    data: dict[str, Any]
    notes: dict[KeyPath, Notes] = dataclasses.field(default_factory=dict)
    flow: set[KeyPath] = dataclasses.field(default_factory=set)

    def get(self, path: KeyPath) -> Any:
        """The value at ``path`` (``None`` if it is not there)."""
        value: Any = self.data
        for part in path:
            if isinstance(value, dict) and part in value:
                value = value[part]
            elif isinstance(value, list) and isinstance(part, int) and part < len(value):
                value = value[part]
            else:
                return None
        return value

    def delete(self, path: KeyPath) -> None:
        """Remove a mapping key with its comments and those of everything under it."""
        parent = self.get(path[:-1])
        if isinstance(parent, dict):
            parent.pop(path[-1], None)
        self.notes = {p: n for p, n in self.notes.items() if p[:len(path)] != path}
        self.flow = {p for p in self.flow if p[:len(path)] != path}

    def insert(self, path: KeyPath, value: Any, before: str | None = None) -> None:
        """Set a mapping key (a new key goes before ``before``, if that key is there, else at
        the end; a key already there keeps its place)."""
        parent = self.get(path[:-1])
        if not isinstance(parent, dict):
            raise ConfigError(f"{'.'.join(map(str, path[:-1]))}: expected a mapping")
        key = path[-1]
        if key in parent or before not in parent:
            parent[key] = value
            return
        items = list(parent.items())
        at = [k for k, _ in items].index(before)
        items.insert(at, (key, value))
        parent.clear()
        parent.update(items)

    def annotate(self, path: KeyPath, above: tuple[str, ...] = (), end: str = "",
                 first: bool = False) -> None:
        """Add comment lines above ``path`` (after the ones there, or ``first``: before them)
        and set its end comment when it has none."""
        old = self.notes.get(path, Notes())
        lines = (*above, *old.above) if first else (*old.above, *above)
        self.notes[path] = Notes(lines, old.end or end)

    def adopt(self, other: Document, src: KeyPath, dest: KeyPath) -> None:
        """Take ``other``'s comments and flow marks of ``src`` and what is under it, for the
        value now at ``dest``."""
        n = len(src)
        for path, notes in other.notes.items():
            if path[:n] == src:
                self.notes[dest + path[n:]] = notes
        self.flow |= {dest + p[n:] for p in other.flow if p[:n] == src}


def read(text: str, source: str) -> Document:
    """A configuration's text as a :class:`Document`.

    :raises ConfigError: if it is not valid YAML for a configuration, or not a mapping.
    """
    data = load_yaml(text, source)
    if not isinstance(data, dict):
        raise not_a_mapping(data, source)
    root = yaml.compose(text, Loader=yaml.SafeLoader)
    lines = text.splitlines()
    walked = list(_walk(root, (), block=True)) if root is not None else []
    flow = {path for path, value, _, _ in walked
            if isinstance(value, yaml.CollectionNode) and value.flow_style}
    entries = sorted(((line, path, value, key) for path, value, key, line in walked if line >= 0),
                     key=lambda e: e[0])
    first = entries[0][0] if entries else len(lines)
    header = tuple(_text(line) for line in lines[:first] if _is_comment(line))
    notes: dict[KeyPath, Notes] = {}
    taken = set()  # a sequence item and its first key share a line: the item takes the above
    for line, path, value, key in entries:
        above: list[str] = []
        at = line - 1
        while line not in taken and at >= first and _is_comment(lines[at]):
            above.insert(0, _text(lines[at]))
            at -= 1
        taken.add(line)
        end = _end_comment(lines, value, key)
        if above or end:
            notes[path] = Notes(tuple(above), end)
    return Document(header, data, notes, flow)


def _walk(
    node: yaml.Node, path: KeyPath, block: bool
) -> Iterator[tuple[KeyPath, yaml.Node, yaml.Node | None, int]]:
    """``(path, value node, key node, line)`` of every key and item; ``line`` is -1 inside a
    flow collection (its keys share their lines and take no comments of their own)."""
    if isinstance(node, yaml.MappingNode):
        inside = block and not node.flow_style
        for key, value in node.value:
            here = (*path, key.value)
            yield here, value, key, key.start_mark.line if inside else -1
            yield from _walk(value, here, inside)
    elif isinstance(node, yaml.SequenceNode):
        inside = block and not node.flow_style
        for i, item in enumerate(node.value):
            here = (*path, i)
            yield here, item, None, item.start_mark.line if inside else -1
            yield from _walk(item, here, inside)


def _is_comment(line: str) -> bool:
    return line.lstrip().startswith("#")


def _text(line: str) -> str:
    """A comment line's text: without the ``#`` and one space after it."""
    body = line.lstrip()[1:]
    return body[1:] if body.startswith(" ") else body


def _end_comment(lines: list[str], value: yaml.Node, key: yaml.Node | None) -> str:
    """The comment at the end of a key's (or item's) line, after its value when the value
    ends on that line or after the key's colon when a block collection follows."""
    if isinstance(value, yaml.CollectionNode) and not value.flow_style:
        if key is None:
            return ""
        mark = key.end_mark
        rest = lines[mark.line][mark.column:].lstrip().removeprefix(":")
    else:
        mark = value.end_mark
        if mark.line >= len(lines):
            return ""
        rest = lines[mark.line][mark.column:]
    rest = rest.strip()
    return _text(rest) if rest.startswith("#") else ""


# ----------------------------------------------------------------------------- writing


def render(doc: Document) -> str:
    """The document as YAML text: the header, then each top-level key after a blank line."""
    out = _comments(doc.header, 0)
    for key, value in doc.data.items():
        if out:
            out.append("")
        out += _key_lines(doc, (key,), value, 0)
    return "\n".join(out) + "\n"


def _comment(text: str, indent: int) -> str:
    """A comment line at ``indent``; a text too long for :data:`WIDTH` is wrapped into
    several (:func:`_comments`), so this takes only texts that fit."""
    return " " * indent + ("# " + text if text else "#")


def _comments(texts: tuple[str, ...], indent: int) -> list[str]:
    """Comment lines at ``indent``, each text wrapped to :data:`WIDTH`."""
    out = []
    width = WIDTH - indent - 2
    for text in texts:
        if len(text) <= width:
            out.append(_comment(text, indent))
            continue
        lead = text[:len(text) - len(text.lstrip())]
        parts = textwrap.wrap(text, width, initial_indent=lead, subsequent_indent=lead,
                              break_long_words=False, break_on_hyphens=False)
        out += [_comment(part, indent) for part in parts]
    return out


def _scalar(value: Any) -> str:
    """A scalar, or a collection in flow style, as PyYAML writes it on one line."""
    text = yaml.safe_dump(value, default_flow_style=True, width=1 << 30, sort_keys=False,
                          allow_unicode=True)
    return text.removesuffix("\n...\n").removesuffix("\n")


def _flow(value: Any, first: int, indent: int) -> list[str]:
    """A value in flow style starting at column ``first``: one line if it fits, else a
    mapping's or sequence's items packed into lines of at most :data:`WIDTH` columns (one
    long item may pass it), the further lines at ``indent``."""
    one = _scalar(value)
    if first + len(one) <= WIDTH or not isinstance(value, (dict, list)) or not value:
        return [one]
    if isinstance(value, dict):
        items = [f"{_scalar(k)}: {_scalar(v)}" for k, v in value.items()]
        opening, closing = "{", "}"
    else:
        items = [_scalar(v) for v in value]
        opening, closing = "[", "]"
    lines = [opening]
    column = first + 1
    for i, item in enumerate(items):
        piece = item + (closing if i == len(items) - 1 else ",")
        if i and column + 1 + len(piece) > WIDTH:
            lines.append(" " * indent + piece)
            column = indent + len(piece)
        else:
            lines[-1] += (" " if i else "") + piece
            column += (1 if i else 0) + len(piece)
    return lines


def _key_lines(doc: Document, path: KeyPath, value: Any, indent: int) -> list[str]:
    """``key: value`` at ``indent``, with its comments."""
    notes = doc.notes.get(path, Notes())
    head = " " * indent + f"{_scalar(path[-1])}:"
    lines = _comments(notes.above, indent)
    if isinstance(value, (dict, list)) and value and path not in doc.flow:
        lines.append(_with_end(head, notes.end, lines, indent))
        lines += _collection_lines(doc, path, value, indent + 2)
        return lines
    body = _flow(value, len(head) + 1, indent + 4)
    first = _with_end(f"{head} {body[0]}", notes.end if len(body) == 1 else "", lines, indent)
    lines += [first, *body[1:]]
    if len(body) > 1 and notes.end:
        at = len(lines) - len(body)
        lines[at:at] = _comments((notes.end,), indent)
    return lines


def _with_end(line: str, end: str, lines: list[str], indent: int) -> str:
    """``line`` with its end comment, or the comment moved above it (into ``lines``) when
    the line would grow too long."""
    if not end:
        return line
    column = max(len(line) + 2, END_COLUMN)
    if column + 2 + len(end) <= WIDTH:
        return f"{line.ljust(column)}# {end}"
    lines += _comments((end,), indent)
    return line


def _collection_lines(doc: Document, path: KeyPath, value: Any, indent: int) -> list[str]:
    """The keys of a block mapping or the items of a block sequence, at ``indent``."""
    if isinstance(value, dict):
        out: list[str] = []
        for key, item in value.items():
            out += _key_lines(doc, (*path, key), item, indent)
        return out
    out = []
    for i, item in enumerate(value):
        here = (*path, i)
        notes = doc.notes.get(here, Notes())
        out += _comments(notes.above, indent)
        if isinstance(item, dict) and item and here not in doc.flow:
            inner = _collection_lines(doc, here, item, indent + 2)
            at = next(j for j, line in enumerate(inner) if not line.lstrip().startswith("#"))
            inner[at] = " " * indent + "- " + inner[at][indent + 2:]
            out += inner
            continue
        body = _flow(item, indent + 2, indent + 3)
        if len(body) > 1 and notes.end:
            out += _comments((notes.end,), indent)
        out.append(_with_end(" " * indent + "- " + body[0], notes.end if len(body) == 1 else "",
                             out, indent))
        out += body[1:]
    return out


def data_of(text: str, source: str) -> Mapping[str, Any]:
    """The data a written document holds, read back with the configuration's loader."""
    data = load_yaml(text, source)
    if not isinstance(data, dict):
        raise not_a_mapping(data, source)
    return data
