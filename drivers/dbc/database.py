"""Where a motor block's DBC file is and its loaded database, shared by the motors that name it.

:func:`resolve_path` finds the file a block names; a :class:`DatabaseCache` (one per driver,
never global) parses each file once.  :mod:`drivers.dbc.binding` looks the names up in it.
"""

from __future__ import annotations

import logging
import os
from typing import TYPE_CHECKING, Any

import cantools

from gateway.core.errors import ConfigError

if TYPE_CHECKING:
    from drivers.dbc.options import DbcOptions

log = logging.getLogger(__name__)


class DatabaseCache:
    """Loads DBC files once per resolved path (one cache per driver, never global)."""

    def __init__(self) -> None:
        self._dbs: dict[str, Any] = {}

    def load(self, path: str, where: str) -> Any:
        """The cantools database in ``path``.

        :raises ConfigError: if the file cannot be read or is not a valid DBC file.
        """
        if path not in self._dbs:
            try:
                self._dbs[path] = cantools.database.load_file(
                    path, database_format="dbc", strict=True
                )
            except OSError as err:
                raise ConfigError(
                    f"{where}.dbc: cannot read DBC file {path!r}: {err.strerror or err}"
                ) from err
            except (cantools.database.errors.Error, ValueError) as err:
                raise ConfigError(f"{where}.dbc: {path!r} is not a valid DBC file: {err}") from err
            log.debug("loaded DBC %s", path)
        return self._dbs[path]


def resolve_path(opts: DbcOptions) -> str:
    """The DBC path: absolute as given, else relative to ``config_dir`` (or the cwd)."""
    path = os.path.expanduser(opts.dbc)
    if not os.path.isabs(path) and opts.config_dir:
        path = os.path.join(opts.config_dir, path)
    return os.path.normpath(path)
