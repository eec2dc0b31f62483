"""Reading a configuration's YAML without surprises: PyYAML's safe loader, made strict.

``yaml.safe_load`` accepts what a robot's configuration must not contain:

* a key given twice in one mapping: PyYAML keeps the last silently, so a second
  ``rear_right:`` drops the first one's ``invert: true``, and a second ``limits:`` block
  removes the acceleration limit.  Refused, naming both lines (YAML 1.2, section 3.2.1.1:
  mapping keys are unique);
* anchors and aliases: a few lines of nested aliases expand to gigabytes ("billion laughs")
  and hang the loader.  Refused: a configuration has ``motor_defaults`` and
  ``steering_defaults`` for shared keys;
* huge scalars: a 5,000-digit integer costs quadratic time to convert and ends in Python's
  ``int`` digit limit with a traceback.  Every scalar is bounded before it is converted.

The file itself is bounded too (:data:`MAX_BYTES`).
"""

from __future__ import annotations

import re
from typing import TYPE_CHECKING, Any

import yaml
from yaml.composer import Composer
from yaml.constructor import SafeConstructor
from yaml.resolver import Resolver

from gateway.core.errors import ConfigError

#: The largest configuration file read (bytes); the shipped ones are under 4 KiB.
MAX_BYTES = 1 << 20
#: The longest scalar (characters): long enough for any path, name or number.
MAX_SCALAR = 4096
#: The longest integer or float literal (characters): a 64-bit value in binary is 66.
MAX_NUMBER = 80
#: The deepest nesting of mappings and sequences.
MAX_DEPTH = 32


def _line(node: yaml.Node | yaml.Event | yaml.Token) -> int:
    mark = node.start_mark
    return mark.line + 1 if mark is not None else 0


if TYPE_CHECKING:
    _Mixin = yaml.SafeLoader  # what the mixin's methods call (the same methods in both loaders)
else:
    _Mixin = object


class _Strict(_Mixin):
    """The checks added to PyYAML's safe loading: unique keys, no aliases, bounded scalars.

    A mixin of the loader classes below (it calls their composer and constructor).
    """

    source = ""
    _depth = 0

    def compose_node(self, parent: yaml.Node | None, index: int) -> yaml.Node | None:
        if self.check_event(yaml.AliasEvent):
            event = self.peek_event()  # type: ignore[no-untyped-call]
            raise ConfigError(
                f"{self.source}: line {_line(event)}: expected plain YAML, got the alias "
                f"*{event.anchor} (anchors and aliases are not accepted; use motor_defaults or "
                f"steering_defaults for shared keys)"
            )
        event = self.peek_event()  # type: ignore[no-untyped-call]
        if getattr(event, "anchor", None):
            raise ConfigError(
                f"{self.source}: line {_line(event)}: expected plain YAML, got the anchor "
                f"&{event.anchor} (anchors and aliases are not accepted)"
            )
        if isinstance(event, yaml.ScalarEvent) and len(event.value) > MAX_SCALAR:
            raise ConfigError(
                f"{self.source}: line {_line(event)}: expected a value of at most "
                f"{MAX_SCALAR} characters, got {len(event.value)}"
            )
        nested = isinstance(event, (yaml.MappingStartEvent, yaml.SequenceStartEvent))
        if nested:
            self._depth += 1
            if self._depth > MAX_DEPTH:
                raise ConfigError(
                    f"{self.source}: line {_line(event)}: expected at most {MAX_DEPTH} levels "
                    f"of nesting, got more"
                )
        try:
            return super().compose_node(parent, index)
        finally:
            if nested:
                self._depth -= 1

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict[Any, Any]:
        seen: dict[object, int] = {}
        for key_node, _ in node.value:
            if not isinstance(key_node, yaml.ScalarNode):
                raise ConfigError(
                    f"{self.source}: line {_line(key_node)}: expected a plain key, got a "
                    f"{key_node.id}"
                )
            key = self.construct_object(key_node, deep=True)
            line = _line(key_node)
            if key in seen:
                raise ConfigError(
                    f"{self.source}: line {line}: key {key!r} is given twice in one mapping "
                    f"(first on line {seen[key]}); expected each key once"
                )
            seen[key] = line
        return super().construct_mapping(node, deep=deep)

    def construct_yaml_int(self, node: yaml.ScalarNode) -> int:
        self._check_number(node)
        return super().construct_yaml_int(node)

    def construct_yaml_float(self, node: yaml.ScalarNode) -> float:
        self._check_number(node)
        return super().construct_yaml_float(node)

    def _check_number(self, node: yaml.ScalarNode) -> None:
        if len(node.value) > MAX_NUMBER:
            raise ConfigError(
                f"{self.source}: line {_line(node)}: expected a number of at most "
                f"{MAX_NUMBER} characters, got {len(node.value)} ({node.value[:20]}...)"
            )


class _PyLoader(_Strict, yaml.SafeLoader):
    """The strict loader in pure Python (PyYAML built without libyaml)."""


_Loader: type[_Strict] = _PyLoader
if yaml.__with_libyaml__:
    from yaml._yaml import CParser

    class _CLoader(_Strict, Composer, CParser, SafeConstructor, Resolver):
        """The strict loader on libyaml's scanner and parser, about five times faster: the
        composing (where the checks of :class:`_Strict` sit) and constructing stay PyYAML's
        Python code, which read libyaml's events as they read the pure-Python parser's."""

        def __init__(self, stream: str) -> None:
            CParser.__init__(self, stream)
            Composer.__init__(self)
            SafeConstructor.__init__(self)
            Resolver.__init__(self)

    _Loader = _CLoader

_LOADERS: tuple[type[_Strict], ...] = (_PyLoader,) if _Loader is _PyLoader else (_PyLoader, _Loader)
#: A number with an exponent that PyYAML's YAML 1.1 rules read as text (``1e-3``, ``1.5e3``:
#: YAML 1.1 wants a dot and a signed exponent); YAML 1.2's core schema (section 10.3.2) reads
#: it as a float, and so does this loader.
_EXPONENT_FLOAT = re.compile(r"^[-+]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)[eE][-+]?[0-9]+$")
for _cls in _LOADERS:
    _cls.add_constructor("tag:yaml.org,2002:int", _Strict.construct_yaml_int)
    _cls.add_constructor("tag:yaml.org,2002:float", _Strict.construct_yaml_float)
    _cls.add_implicit_resolver("tag:yaml.org,2002:float", _EXPONENT_FLOAT,
                               list("-+0123456789."))


def read_text(data: bytes, source: str) -> str:
    """A configuration file's bytes as text, bounded and checked.

    :raises ConfigError: for a file over :data:`MAX_BYTES` or text that is not UTF-8.
    """
    if len(data) > MAX_BYTES:
        raise ConfigError(
            f"{source}: expected a configuration of at most {MAX_BYTES} bytes, got "
            f"{len(data)} or more"
        )
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as err:
        raise ConfigError(
            f"{source}: expected UTF-8 text, got byte {err.object[err.start]:#04x} at "
            f"offset {err.start}"
        ) from err


def load_yaml(text: str, source: str) -> object:
    """Parse a configuration's YAML strictly (see the module's doc).

    :raises ConfigError: naming ``source``, the line and what was wrong.
    """
    if len(text) > MAX_BYTES:
        raise ConfigError(
            f"{source}: expected a configuration of at most {MAX_BYTES} bytes, got "
            f"{len(text)} characters"
        )
    try:
        return _parse(_Loader, text, source)
    except yaml.YAMLError as first:
        err = first
        if _Loader is not _PyLoader:
            # libyaml's syntax errors lack the quoted line and caret of PyYAML's own: the
            # pure-Python parser says it again (the same error, at the same place).
            try:
                _parse(_PyLoader, text, source)
            except yaml.YAMLError as again:
                err = again
        raise ConfigError(f"{source}: not valid YAML: {err}") from err


#: At most this many characters of a wrong top level are quoted in the error.
_QUOTED = 60


def not_a_mapping(data: object, source: str) -> ConfigError:
    """The error for a document whose top level is not a mapping: what it is instead, and a
    short quote of it (a text file passed as the configuration is one long string).

    >>> str(not_a_mapping("root:x:0:0:root:/root:/bin/bash " * 9, "/etc/passwd")).split(", got ")
    ... # doctest: +NORMALIZE_WHITESPACE
    ["/etc/passwd: expected a mapping at the top level (a robot's configuration, key: value)",
     "a string of 288 characters, 'root:x:0:0:root:/root:/bin/bash root:x:0:0:root:/root:/bin/..."]
    >>> str(not_a_mapping([1, 2], "robot.yaml")).split(", got ")[1]
    'a list, [1, 2]'
    """
    kind = {str: "a string", list: "a list", int: "a number", float: "a number",
            bool: "a boolean"}.get(type(data), type(data).__name__)
    quoted = repr(data)
    if len(quoted) > _QUOTED:
        quoted = quoted[:_QUOTED] + "..."
    if isinstance(data, str) and len(data) > _QUOTED:
        kind += f" of {len(data)} characters"
    return ConfigError(f"{source}: expected a mapping at the top level (a robot's "
                       f"configuration, key: value), got {kind}, {quoted}")


def _parse(cls: type[_Strict], text: str, source: str) -> object:
    loader = None
    try:
        loader = cls(text)  # reads the first characters already
        loader.source = source
        return loader.get_single_data()
    except ConfigError:  # a ValueError too, already worded
        raise
    except RecursionError as err:
        raise ConfigError(
            f"{source}: expected YAML of modest depth, got nesting too deep"
        ) from err
    except ValueError as err:  # a conversion PyYAML does not wrap
        raise ConfigError(f"{source}: not valid YAML: {err}") from err
    finally:
        if loader is not None:
            loader.dispose()
