"""Every problem of a configuration file at once, not only the first.

The loader checks a file block by block; :class:`Problems` runs each check, keeps the
:class:`~gateway.core.errors.ConfigError` it raises and goes on with the next block, so a
person fixing a file sees all that is wrong with it in one run.  A check that needs a block
which failed is skipped (its input does not exist), so each problem is reported once, where
it is.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, TypeVar

from gateway.core.errors import ConfigError

if TYPE_CHECKING:
    from collections.abc import Callable

T = TypeVar("T")


class Problems:
    """The problems found so far in one file."""

    def __init__(self) -> None:
        self.found: list[str] = []

    def check(self, step: Callable[[], T]) -> T | None:
        """``step()``, or ``None`` when it raised :class:`ConfigError` (kept)."""
        try:
            return step()
        except ConfigError as err:
            self.found += err.problems
            return None

    def add(self, message: str) -> None:
        """One problem found by the loader itself."""
        self.found.append(message)

    def raise_any(self) -> None:
        """Raise one :class:`ConfigError` with every problem found, if there is one.

        :raises ConfigError: one line per problem, in the file's order of blocks (a problem
            of a block that several inherit, ``motor_defaults:``, once).
        """
        if self.found:
            raise ConfigError.of(list(dict.fromkeys(self.found)))
