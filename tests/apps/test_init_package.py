"""The shipped files (``config/``'s examples, the DBC files they name, the systemd unit) are
installed with the package as ``gateway.examples``, and a wheel holds every one of them."""

from __future__ import annotations

import fnmatch
import shutil
import subprocess
import sys
import zipfile
from typing import TYPE_CHECKING

import pytest

from gateway.apps.init import shipped
from gateway.core.errors import GatewayError
from tests.conftest import CONFIG_DIR, REPO
from tests.test_architecture import pyproject

if TYPE_CHECKING:
    from pathlib import Path

#: What ``config/`` holds that is shipped (its ``__init__.py`` only makes it a package).
FILES = sorted(p.name for p in CONFIG_DIR.iterdir() if p.is_file() and p.suffix != ".py")


def test_the_installed_package_holds_every_file_of_config() -> None:
    """Through the package's loader, as ``wheelgate init`` reads them (an editable install maps
    the package to ``config/``, a wheel holds copies)."""
    assert shipped.names() == tuple(FILES)
    assert shipped.UNIT in FILES and "mecanum.yaml" in FILES
    for name in FILES:
        assert shipped.read(name) == (CONFIG_DIR / name).read_bytes(), name
    assert set(shipped.example_names()) == {p.stem for p in CONFIG_DIR.glob("*.yaml")}
    with shipped.path_of("mecanum.yaml") as path:
        assert path.read_bytes() == (CONFIG_DIR / "mecanum.yaml").read_bytes()


def test_a_file_that_is_not_shipped_is_refused_naming_those_that_are() -> None:
    with pytest.raises(GatewayError, match=r"no shipped file 'robot.yaml'; expected one of "
                                           r"ackermann.yaml, "):
        shipped.read("robot.yaml")


def test_an_installation_without_them_says_how_to_get_them(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """An editable install made before the package existed has no mapping for it."""
    monkeypatch.setattr(shipped, "PACKAGE", "gateway.no_examples")
    for call in (shipped.names, lambda: shipped.read("mecanum.yaml")):
        with pytest.raises(GatewayError, match=r"the shipped examples are not installed with "
                                               r"this wheelgate \(no package "):
            call()


def test_the_build_ships_every_file_of_config() -> None:
    """``pyproject.toml`` maps ``gateway.examples`` to ``config/`` and its package data covers
    every file there; ``setup.py`` lists the package (a new kind of file in ``config/`` fails
    here, not in a robot builder's hands)."""
    setuptools = pyproject()["tool"]["setuptools"]
    assert setuptools["package-dir"] == {shipped.PACKAGE: "config"}
    globs = setuptools["package-data"][shipped.PACKAGE]
    left_out = [n for n in FILES if not any(fnmatch.fnmatch(n, g) for g in globs)]
    assert not left_out, f"config/ files no package-data glob of {shipped.PACKAGE} ships"
    assert f'"{shipped.PACKAGE}"' in (REPO / "setup.py").read_text("utf-8")


@pytest.mark.slow
@pytest.mark.timeout(900)
def test_a_wheel_built_from_the_tree_holds_them(tmp_path: Path) -> None:
    """The real build (pip, setuptools from the package index), from a copy of the tree
    without build products (setuptools builds in the tree: a build/ left there would leak
    into later wheels): the wheel's ``gateway/examples/`` is ``config/``."""
    tree = tmp_path / "tree"
    shutil.copytree(REPO, tree, ignore=shutil.ignore_patterns(
        ".git", ".venv", "build", "dist", "*.egg-info", "__pycache__", ".*_cache", ".hypothesis"))
    done = subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "--quiet", "-w", str(tmp_path),
         str(tree)], capture_output=True, text=True, timeout=850, check=False)
    assert done.returncode == 0, done.stderr
    (wheel,) = tmp_path.glob("wheelgate-*.whl")
    with zipfile.ZipFile(wheel) as zf:
        inside = {n.removeprefix("gateway/examples/"): zf.read(n) for n in zf.namelist()
                  if n.startswith("gateway/examples/")}
    assert sorted(n for n in inside if not n.endswith(".py")) == FILES
    for name in FILES:
        assert inside[name] == (CONFIG_DIR / name).read_bytes(), name
