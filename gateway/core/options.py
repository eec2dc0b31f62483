"""Typed keys of a configuration block: one validator for driver options and drive geometry."""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass

from gateway.core.errors import ConfigError


@dataclass(frozen=True, slots=True)
class OptionSpec:
    """One protocol key of a motor block.

    :param kind: the Python type expected (``int``, ``float``, ``str`` or ``bool``).
    :param default: value when the key is absent; ``None`` makes the key required.
    :param choices: allowed values, if restricted.
    :param minimum: smallest allowed number, if bounded.
    :param maximum: largest allowed number, if bounded.
    :param help: one line for docs and error messages.
    :param above: a number it must exceed, if bounded so (a length that must not be 0).
    :param unit: the unit of the bounds in messages (``" m"``), if any.
    """

    kind: type
    default: object = None
    choices: tuple[object, ...] = ()
    minimum: float | None = None
    maximum: float | None = None
    help: str = ""
    above: float | None = None
    unit: str = ""

    def validate(self, value: object, where: str) -> object:
        """Check one value and return it normalised (ints accepted for floats).

        :raises ConfigError: naming ``where``, what was expected and what came.
        """
        ok: bool
        if self.kind is float:
            ok = isinstance(value, (int, float)) and not isinstance(value, bool)
            if ok:
                value = float(value)  # type: ignore[arg-type]
                ok = math.isfinite(value)
        elif self.kind is int:
            ok = isinstance(value, int) and not isinstance(value, bool)
        else:
            ok = isinstance(value, self.kind)
        if not ok:
            if self.kind is float and isinstance(value, float):  # .nan, .inf
                raise ConfigError(f"{where}: expected a finite number, got {value!r}")
            raise ConfigError(f"{where}: expected {self.kind.__name__}, got {value!r}")
        if self.choices and value not in self.choices:
            allowed = ", ".join(repr(c) for c in self.choices)
            raise ConfigError(f"{where}: expected one of {allowed}, got {value!r}")
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            unit = self.unit
            if self.above is not None and not value > self.above:
                raise ConfigError(f"{where}: expected more than {self.above:g}{unit}, "
                                  f"got {value!r}")
            if self.minimum is not None and value < self.minimum:
                raise ConfigError(f"{where}: expected at least {self.minimum:g}{unit}, "
                                  f"got {value!r}")
            if self.maximum is not None and value > self.maximum:
                raise ConfigError(f"{where}: expected at most {self.maximum:g}{unit}, "
                                  f"got {value!r}")
        return value


def validate_block(
    raw: object, specs: Mapping[str, OptionSpec], where: str, what: str = "keys"
) -> dict[str, object]:
    """Validate a mapping of keys against their specs and fill in defaults.

    :param raw: the block as loaded from YAML.
    :param specs: the allowed keys.
    :param where: file and key path of the block, for messages.
    :param what: how to name the allowed keys in the unknown-key message.
    :raises ConfigError: for a non-mapping, unknown keys, missing required keys or bad values
        (every one of the block's problems, one line each).
    """
    if not isinstance(raw, Mapping):
        raise ConfigError(f"{where}: expected a mapping, got {raw!r}")
    problems = [str(unknown_key(f"{where}.{key}", key, {what: specs}))
                for key in raw if key not in specs]
    out: dict[str, object] = {}
    for key, spec in specs.items():
        if key in raw:
            try:
                out[key] = spec.validate(raw[key], f"{where}.{key}")
            except ConfigError as err:
                problems += err.problems
        elif spec.default is None:
            hint = f" ({spec.help})" if spec.help else ""
            problems.append(f"{where}.{key}: required key is missing{hint}")
        else:
            out[key] = spec.default
    if problems:
        raise ConfigError.of(problems)
    return out


def unknown_key(where: str, key: object, known: Mapping[str, Iterable[str]]) -> ConfigError:
    """The error for an unknown ``key``: the nearest known key when one is close (a typo such as
    ``inverted`` for ``invert``), then every group of keys that would be accepted there.

    :param where: the key's path, for the message.
    :param known: the accepted keys, by how to name their group (``"motor keys"``).

    >>> print(unknown_key("left.inverted", "inverted", {"motor keys": ["invert", "node_id"],
    ...                                                   "odrive keys": ["firmware"]}))
    left.inverted: unknown key; did you mean 'invert'? (known motor keys: invert, node_id; \
odrive keys: firmware)
    """
    names = sorted({k for keys in known.values() for k in keys})
    import difflib  # noqa: PLC0415 - only where a suggestion is made (start-up)

    close = difflib.get_close_matches(str(key), names, n=1, cutoff=0.7)
    hint = f"; did you mean {close[0]!r}?" if close else ""
    groups = "; ".join(f"{what}: {', '.join(sorted(keys)) or 'none'}"
                       for what, keys in known.items())
    return ConfigError(f"{where}: unknown key{hint} (known {groups})")
