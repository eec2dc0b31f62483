"""A mixin for everything that owns a socket, a bus or a thread: ``with`` closes it."""

from __future__ import annotations

from typing import TYPE_CHECKING, TypeVar

if TYPE_CHECKING:
    from types import TracebackType

_T = TypeVar("_T", bound="Closing")


class Closing:
    """Context-manager support for classes with an idempotent :meth:`close`."""

    def close(self) -> None:
        """Release what the object owns (safe to call twice)."""
        raise NotImplementedError

    def __enter__(self: _T) -> _T:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()
