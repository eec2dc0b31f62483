"""Driver lookup: the built-in table plus the ``gateway.drivers`` entry-point group.

Built-ins are imported lazily, and the installed packages' entry points are read only when a
name is not built in (reading them scans every installed distribution's metadata, a good part
of the CLI's start-up).  A plugin that fails to load becomes a warning naming the plugin and
the exception; it never empties the registry.
"""

from __future__ import annotations

import importlib
import logging
from typing import TYPE_CHECKING, Any

from drivers import BUILTIN_DRIVERS
from gateway.core.errors import DriverNotFoundError
from gateway.drive.driver import MotorDriver

if TYPE_CHECKING:
    from importlib.metadata import EntryPoint

log = logging.getLogger(__name__)

ENTRY_POINT_GROUP = "gateway.drivers"


def _plugins() -> dict[str, EntryPoint]:
    from importlib.metadata import entry_points  # noqa: PLC0415 - see the module's doc

    return {ep.name: ep for ep in entry_points(group=ENTRY_POINT_GROUP)}


def valid_drivers() -> frozenset[str]:
    """Every driver name that can be asked for (built-ins and installed plugins)."""
    return frozenset(BUILTIN_DRIVERS) | frozenset(_plugins())


#: Built-in driver names, for ``click.Choice``.
VALID_DRIVERS: frozenset[str] = frozenset(BUILTIN_DRIVERS)


def get_driver_class(name: str) -> type[MotorDriver[Any]]:
    """The driver class registered under ``name``.

    :raises DriverNotFoundError: if no driver has that name, or it cannot be loaded.
    """
    if name in BUILTIN_DRIVERS:
        module_name, class_name = BUILTIN_DRIVERS[name]
        try:
            cls = getattr(importlib.import_module(module_name), class_name)
        except (ImportError, AttributeError) as err:
            raise DriverNotFoundError(
                f"Driver {name!r} ({module_name}.{class_name}) failed to load: {err}"
            ) from err
    else:
        plugins = _plugins()
        plugin = plugins.get(name)
        if plugin is None:
            known = ", ".join(sorted(BUILTIN_DRIVERS.keys() | plugins.keys()))
            raise DriverNotFoundError(f"Unknown driver {name!r}; expected one of: {known}")
        try:
            cls = plugin.load()
        except Exception as err:  # a plugin may raise anything while importing
            log.warning("driver plugin %r (%s) failed to load: %r", name, plugin.value, err)
            raise DriverNotFoundError(
                f"Driver plugin {name!r} ({plugin.value}) failed to load: {err!r}"
            ) from err
    if not (isinstance(cls, type) and issubclass(cls, MotorDriver)):
        raise DriverNotFoundError(f"Driver {name!r} is not a MotorDriver subclass: {cls!r}")
    return cls
