"""Configuration values out of a fixed set: :class:`Choice` enums and :func:`choice`.

Each member of a :class:`Choice` is equal to, hashes as and prints as its YAML value, as
Python 3.11's ``enum.StrEnum`` does (https://docs.python.org/3/library/enum.html#enum.StrEnum).
"""

from __future__ import annotations

import enum
from typing import TypeVar

from gateway.core.errors import ConfigError

__all__ = ["Choice", "choice"]

_C = TypeVar("_C", bound=enum.Enum)


class Choice(str, enum.Enum):
    """A configuration value out of a fixed set: a ``str`` whose ``str()`` and ``format()``
    are its value (``enum.StrEnum`` needs Python 3.11; wheelgate supports 3.10)."""

    def __str__(self) -> str:
        return str(self.value)

    def __format__(self, spec: str) -> str:
        return format(str(self.value), spec)



def choice(kind: type[_C], value: object, where: str) -> _C:
    """``value`` as a member of ``kind`` (a member, or its value).

    :raises ConfigError: naming ``where``, the choices and what came.
    """
    if isinstance(value, kind):
        return value
    try:
        return kind(value)
    except ValueError:
        allowed = ", ".join(repr(m.value) for m in kind)
        raise ConfigError(f"{where}: expected one of {allowed}, got {value!r}") from None
