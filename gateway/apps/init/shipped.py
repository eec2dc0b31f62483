"""The files shipped with the package: the example configurations and the systemd unit.

In the repository they live in ``config/``; the build installs that directory as the package
``gateway.examples`` (``setup.py`` maps it, ``pyproject.toml`` lists its files as package
data), so an installed wheelgate and an editable checkout read the same files the same way,
through the package's loader.
"""

from __future__ import annotations

import importlib.util
import pkgutil
from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING

from gateway.core.errors import GatewayError

if TYPE_CHECKING:
    from contextlib import AbstractContextManager

#: The package the build makes of the repository's ``config/``.
PACKAGE = "gateway.examples"
#: The systemd unit among the shipped files.
UNIT = "wheelgate.service"
#: How an example configuration's file name ends.
SUFFIX = ".yaml"
#: The example ``wheelgate init --drive DRIVE`` starts from, per drive (``--drive NAME``
#: names any example): the simplest of those with that ``drive:``: the fewest motors, on
#: controllers that stop by themselves when wheelgate dies (not DJI ESCs, which need
#: ``--acknowledge-no-controller-stop``), with no DBC file to replace.
BY_DRIVE: dict[str, str] = {
    "ackermann": "ackermann",
    "differential": "turtlebot3_burger",  # not differential_tub (VESC), example_dbc (DBC file)
    "generic": "differential_castor",  # not omni3_swedish (three Swedish wheels)
    "mecanum": "mecanum",
    "omni": "omni3",  # not omni_delta (DJI ESCs)
    "skid_steer": "skid_steer",
    "swerve": "swerve",
    "synchro": "synchro",
    "tricycle": "tricycle",
}

_MISSING = (
    f"the shipped examples are not installed with this wheelgate (no package {PACKAGE}); "
    "expected them beside the code: reinstall it (pip install ., or pip install -e . in a "
    "checkout)"
)


def names() -> tuple[str, ...]:
    """Every shipped file's name (the examples, the DBC files they name, the unit), sorted.

    :raises GatewayError: if the package holds none (an installation without them).
    """
    try:
        found = sorted(
            entry.name for entry in resources.files(PACKAGE).iterdir()
            if entry.is_file() and not entry.name.endswith((".py", ".pyc"))
        )
    except ModuleNotFoundError as err:
        raise GatewayError(_MISSING) from err
    if not found:
        raise GatewayError(_MISSING)
    return tuple(found)


def example_names() -> tuple[str, ...]:
    """The names of the example configurations (their files' names without ``.yaml``)."""
    return tuple(n.removesuffix(SUFFIX) for n in names() if n.endswith(SUFFIX))


def read(name: str) -> bytes:
    """A shipped file's bytes.

    :raises GatewayError: if there is no such file, naming the ones there are.
    """
    try:
        data = pkgutil.get_data(PACKAGE, name)
    except ModuleNotFoundError as err:
        raise GatewayError(_MISSING) from err
    except OSError as err:
        raise GatewayError(
            f"{PACKAGE}: no shipped file {name!r}; expected one of {', '.join(names())}"
        ) from err
    if data is None:  # no such package, or a loader without get_data (not one of Python's)
        if importlib.util.find_spec(PACKAGE) is None:
            raise GatewayError(_MISSING)
        raise GatewayError(f"{PACKAGE}: the package's loader cannot read {name!r}")
    return data


def read_text(name: str) -> str:
    """A shipped file's text (UTF-8)."""
    return read(name).decode("utf-8")


def path_of(name: str) -> AbstractContextManager[Path]:
    """A context manager giving a file-system path of a shipped file (a temporary copy while
    it lasts, if the package is not on the file system)."""
    return resources.as_file(resources.files(PACKAGE) / name)


def example_file(wanted: str) -> Path | None:
    """The file of the shipped example ``wanted`` names (``NAME`` or ``NAME.yaml``), where it
    is installed; ``None`` when there is no such example, or the package is not on the file
    system (a zip: its examples have no path to load, or to find their DBC files beside)."""
    name = wanted.removesuffix(SUFFIX)
    try:
        if name not in example_names():
            return None
        path = resources.files(PACKAGE) / (name + SUFFIX)
    except GatewayError:
        return None
    return path if isinstance(path, Path) and path.is_file() else None
