"""Simulator lookup: a device simulator for a motor, registered apart from its driver.

A driver never imports its simulator: production code carries no test devices, and a
third-party driver may ship none.  Simulators are found by driver name in the built-in table
(:data:`drivers.BUILTIN_SIMULATORS`) and in the ``gateway.simulators`` entry-point group, whose
entries name a function ``simulator_for(motor: MotorConfig) -> DeviceSimulator``::

    [project.entry-points."gateway.simulators"]
    mydriver = "mypackage.sim:simulator_for"

A plugin that fails to load is an error naming the plugin and the exception.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

from drivers import BUILTIN_SIMULATORS
from gateway.core.errors import DriverNotFoundError
from gateway.sim.device import DeviceSimulator, spread_phase

if TYPE_CHECKING:
    from collections.abc import Callable, Iterable

    from gateway.core.types import MotorConfig

ENTRY_POINT_GROUP = "gateway.simulators"


def _factory(driver: str) -> Callable[[MotorConfig], DeviceSimulator]:
    if driver in BUILTIN_SIMULATORS:
        module_name, func_name = BUILTIN_SIMULATORS[driver]
        what = f"{module_name}.{func_name}"
        try:
            module = importlib.import_module(module_name)
            func = getattr(module, func_name)
        except (ImportError, AttributeError) as err:
            raise DriverNotFoundError(
                f"Simulator of driver {driver!r} ({what}) failed to load: {err}"
            ) from err
    else:
        from importlib.metadata import entry_points  # noqa: PLC0415 - only for a plugin

        plugins = {ep.name: ep for ep in entry_points(group=ENTRY_POINT_GROUP)}
        plugin = plugins.get(driver)
        if plugin is None:
            known = ", ".join(sorted(set(BUILTIN_SIMULATORS) | set(plugins)))
            raise DriverNotFoundError(
                f"No simulator for driver {driver!r}: --sim and the tests need one registered "
                f"in the {ENTRY_POINT_GROUP!r} entry-point group (simulators exist for: {known})"
            )
        what = plugin.value
        try:
            func = plugin.load()
        except Exception as err:  # a plugin may raise anything while importing
            raise DriverNotFoundError(
                f"Simulator plugin {driver!r} ({what}) failed to load: {err!r}"
            ) from err
    if not callable(func):
        raise DriverNotFoundError(f"Simulator of driver {driver!r} ({what}) is not callable")
    return func  # type: ignore[no-any-return]


def simulator_for(motor: MotorConfig) -> DeviceSimulator:
    """A device simulator that speaks the device side of ``motor``'s protocol, at the settings
    its motor block states (factory settings otherwise).

    :raises DriverNotFoundError: if no simulator is registered for its driver, or it fails.
    """
    sim = _factory(motor.driver)(motor)
    if not isinstance(sim, DeviceSimulator):
        raise DriverNotFoundError(
            f"Simulator of driver {motor.driver!r} returned {type(sim).__name__}, expected a "
            f"DeviceSimulator"
        )
    return sim


def simulators_for(motors: Iterable[MotorConfig]) -> list[DeviceSimulator]:
    """A device simulator for every motor, in order, each sending its cyclic frames at a phase
    of its own (:func:`~gateway.sim.device.spread_phase`), as the controllers of a robot do,
    each timed from its own power-up."""
    sims = [simulator_for(m) for m in motors]
    for k, sim in enumerate(sims):
        sim.phase = spread_phase(k)
    return sims
