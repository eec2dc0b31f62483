"""The one build setting pyproject.toml cannot state: the package list.

Every package under gateway/ and drivers/ (as ``packages.find`` would give), plus
``gateway.examples``, which pyproject.toml maps to the repository's config/ directory: so the
example configurations, the DBC files they name and the systemd unit are installed with the
code, by ``pip install .`` and ``pip install -e .`` alike, while config/ stays their one copy.
"""

from setuptools import find_namespace_packages, setup

setup(packages=[*find_namespace_packages(include=["gateway*", "drivers*"]), "gateway.examples"])
