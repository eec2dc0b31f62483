"""The rules of the layout that no single module's tests see (README, "Architecture" and
"Development").

* No module of the code (``gateway/``, ``drivers/``, ``tools/``) is longer than
  :data:`MAX_LINES` lines.
* The import-linter contract that keeps the simulators out of the drivers covers every module of
  every protocol, so a new module cannot slip past it.
* The tests mirror the tree: ``tests/<layer>/`` for ``gateway/<layer>/``.
* ``lint-imports`` keeps every contract.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from tests.conftest import REPO

#: The longest a module of the code may be (lines).
MAX_LINES = 400
#: The folders the length rule holds for (the tests too).
CODE = ("gateway", "drivers", "tools", "tests")
#: The import-linter contract that keeps the simulators out of the protocols' drivers.
SIM_CONTRACT = "no-test-devices-in-production"
#: Test folders that stand for something other than a package ``gateway/<name>/``: the
#: protocols (``drivers/``), the benchmarks (``tools/``), and the ``socketcan`` tier (the
#: gateway on a kernel CAN interface, across the layers).
OTHER_TEST_FOLDERS = {"drivers": "drivers/", "tools": "tools/", "socketcan": "the socketcan tier"}


def modules_under(folder: Path) -> list[Path]:
    """The Python modules under ``folder`` (any depth), sorted."""
    return sorted(p for p in folder.rglob("*.py") if "__pycache__" not in p.parts)


def module_name(path: Path) -> str:
    """The dotted name of the module at ``path`` (a package's ``__init__``: the package)."""
    parts = path.relative_to(REPO).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def is_simulator(name: str) -> bool:
    """Whether the module ``drivers.<protocol>.<...>`` is a device simulator (``sim``,
    ``sim_*``), which the drivers never import."""
    leaf = name.rsplit(".", 1)[-1]
    return leaf == "sim" or leaf.startswith("sim_")


def pyproject() -> dict[str, Any]:
    """``pyproject.toml``, parsed."""
    if sys.version_info >= (3, 11):
        import tomllib

        with (REPO / "pyproject.toml").open("rb") as f:
            return tomllib.load(f)
    pytest.skip("tomllib is Python 3.11+")


# ----------------------------------------------------------------------------- module length


def test_no_module_of_the_code_is_longer_than_the_limit() -> None:
    lengths = {
        path.relative_to(REPO).as_posix(): len(path.read_text("utf-8").splitlines())
        for folder in CODE
        for path in modules_under(REPO / folder)
    }
    assert lengths, f"no modules found under {CODE}"
    long = sorted(((n, p) for p, n in lengths.items() if n > MAX_LINES), reverse=True)
    assert not long, f"{len(long)} module(s) longer than {MAX_LINES} lines (split them): " + (
        ", ".join(f"{p} ({n} lines)" for n, p in long)
    )


# ----------------------------------------------------------------------------- the contract


def test_the_simulator_contract_covers_every_module_of_every_protocol() -> None:
    """``no-test-devices-in-production`` lists source modules by name (a protocol's package
    as a whole would take its simulators in), so a module it does not reach is not checked.

    It lists each protocol's ``driver``; as it does not allow indirect imports, import-linter
    also checks every module that a listed one imports, directly or not.  So every module of
    ``drivers/<protocol>/`` but the simulators (``sim``, ``sim_*``) and the package's
    ``__init__`` must be listed or imported by a listed one: a new module that the driver does
    not import (a second entry point, a tool) must be added to the list.  The ``__init__`` of
    a protocol re-exports its public names and cannot be listed without its simulators (it is
    the package); it must reach no simulator either, which this test checks on the same graph.
    """
    grimp = pytest.importorskip("grimp", reason="grimp comes with import-linter")
    config = pyproject()["tool"]["importlinter"]
    contract = next((c for c in config["contracts"] if c["id"] == SIM_CONTRACT), None)
    assert contract is not None, f"pyproject.toml: no import-linter contract {SIM_CONTRACT!r}"
    assert contract["type"] == "forbidden"
    forbidden = contract["forbidden_modules"]
    assert "gateway.sim" in forbidden
    listed = set(contract["source_modules"])
    indirect = str(contract.get("allow_indirect_imports", False)).lower() == "true"

    protocols = sorted(p for p in (REPO / "drivers").iterdir() if (p / "__init__.py").is_file())
    assert protocols, "no protocol packages under drivers/"
    modules = {module_name(path) for p in protocols for path in modules_under(p)}
    # Every simulator module of a protocol is forbidden too (by name, or by drivers.*.sim).
    unforbidden = sorted(
        m for m in modules if is_simulator(m) and m not in forbidden
        and not (m.endswith(".sim") and "drivers.*.sim" in forbidden)
    )
    assert not unforbidden, (
        f"{SIM_CONTRACT}: simulator modules missing from forbidden_modules: {unforbidden}"
    )
    packages = {f"drivers.{p.name}" for p in protocols}
    graph = grimp.build_graph(
        *config["root_packages"],
        exclude_type_checking_imports=config.get("exclude_type_checking_imports", False),
        cache_dir=None,
    )
    covered = set(listed)
    if not indirect:
        for name in listed & modules:
            covered |= graph.find_upstream_modules(name)

    problems = [f"{n}: listed, but there is no such module" for n in sorted(listed - modules)]
    problems += [f"{n}: a simulator is listed" for n in sorted(listed) if is_simulator(n)]
    problems += [
        f"{n}: not listed in its source_modules, and no listed module imports it"
        for n in sorted(modules - packages - covered)
        if not is_simulator(n)
    ]
    problems += [
        f"{package} (its __init__) imports {', '.join(sorted(reached))}"
        for package in sorted(packages)
        if (reached := {n for n in graph.find_upstream_modules(package)
                        if n.startswith("gateway.sim") or is_simulator(n)})
    ]
    assert not problems, f"pyproject.toml, contract {SIM_CONTRACT!r}: " + "; ".join(problems)


# ----------------------------------------------------------------------------- the tests' tree


def test_the_tests_mirror_the_tree() -> None:
    """Every folder of test modules (``test_*.py``) is ``tests/`` itself (rules across the
    layers, like these) or a package ``tests/<name>/`` right under it, where ``<name>`` is a
    layer, a package ``gateway/<name>/`` (its subpackages, such as ``gateway/apps/jog/``, are
    tested in the layer's folder), or one of :data:`OTHER_TEST_FOLDERS`."""
    tests = REPO / "tests"
    layers = {p.name for p in (REPO / "gateway").iterdir() if (p / "__init__.py").is_file()}
    folders = sorted({p.parent for p in tests.rglob("test_*.py") if "__pycache__" not in p.parts})
    assert tests / "drivers" in folders, "no test modules found under tests/drivers/"
    wrong = []
    for folder in folders:
        rel = folder.relative_to(tests)
        if folder == tests:
            continue
        if len(rel.parts) > 1:
            wrong.append(f"tests/{rel.as_posix()}/: nested (the tests of a package of "
                         f"gateway/{rel.parts[0]}/ go in tests/{rel.parts[0]}/)")
        elif rel.name not in layers and rel.name not in OTHER_TEST_FOLDERS:
            wrong.append(f"tests/{rel.name}/: there is no package gateway/{rel.name}/")
        elif not (folder / "__init__.py").is_file():
            wrong.append(f"tests/{rel.name}/: not a package (no __init__.py)")
    assert not wrong, "the tests do not mirror the tree: " + "; ".join(wrong)


# ----------------------------------------------------------------------------- import-linter


def test_lint_imports_keeps_every_contract() -> None:
    beside = Path(sys.executable).with_name("lint-imports")
    exe = str(beside) if beside.is_file() else shutil.which("lint-imports")
    if exe is None:
        pytest.skip("lint-imports (PyPI import-linter) is not installed")
    done = subprocess.run([exe, "--no-cache", "--no-logo"], cwd=REPO, capture_output=True,
                          text=True, timeout=300, check=False)
    assert done.returncode == 0, f"lint-imports failed:\n{done.stdout}{done.stderr}"
