"""The layers as the tree draws them: shared/ imports neither side, workers/ never imports
services/, and services/ imports the workers only from the composing package
(graspscape.services.local).

The default checks read every module's source (`ast.walk`: imports inside functions and
`importlib.import_module("graspscape....")` with a literal name count as well as the
top-level ones; relative imports are resolved against the module's package). The slow checks
import every module of a folder in a fresh interpreter and look at what got loaded, so an
import made any other way (a name built at run time) is caught there.
"""

from __future__ import annotations

import ast
import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
COMPOSING = "graspscape.services.local"


def _module_name(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(("graspscape", *parts))


def _modules(folder: str, skip: str | None = None) -> list[str]:
    names = []
    for path in sorted((ROOT / folder).rglob("*.py")):
        name = _module_name(path)
        if skip is None or not (name == skip or name.startswith(skip + ".")):
            names.append(name)
    return names


def imported_names(source: str, module: str, is_package: bool = False) -> set[str]:
    """Every module the source of `module` names in an import, wherever the import stands."""
    package = module if is_package else module.rpartition(".")[0]
    names: set[str] = set()
    for node in ast.walk(ast.parse(source, module)):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")
                anchor = anchor[:len(anchor) - (node.level - 1)]
                base = ".".join(anchor + ([base] if base else []))
            names.add(base)
            names.update(f"{base}.{alias.name}" for alias in node.names)
        elif (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
              and node.func.attr == "import_module" and node.args
              and isinstance(node.args[0], ast.Constant) and isinstance(node.args[0].value, str)):
            names.add(node.args[0].value)
    return names


def _offenders(folder: str, forbidden: tuple[str, ...], skip: str | None = None) -> list[str]:
    found = []
    for path in sorted((ROOT / folder).rglob("*.py")):
        name = _module_name(path)
        if skip is not None and (name == skip or name.startswith(skip + ".")):
            continue
        source = path.read_text()
        for imported in sorted(imported_names(source, name, path.name == "__init__.py")):
            if any(imported == f or imported.startswith(f + ".") for f in forbidden):
                found.append(f"{path.relative_to(ROOT)} imports {imported}")
    return found


def test_the_reader_sees_imports_inside_functions_and_relative_ones() -> None:
    # The check must be able to fail: a module written like an offender is seen as one.
    source = ("def f():\n    from graspscape.workers.sim import evaluate\n"
              "    from ..local import compose\n"
              "    import importlib\n"
              "    importlib.import_module('graspscape.workers.runtime')\n")
    names = imported_names(source, "graspscape.services.coordinator.probe")
    assert {"graspscape.workers.sim.evaluate", "graspscape.services.local.compose",
            "graspscape.workers.runtime"} <= names


def test_services_name_the_workers_only_in_the_composing_package() -> None:
    assert _offenders("services", ("graspscape.workers", "workers"), skip=COMPOSING) == []


def test_workers_never_name_services() -> None:
    assert _offenders("workers", ("graspscape.services", "services")) == []


def test_shared_names_neither_side() -> None:
    forbidden = ("graspscape.workers", "graspscape.services", "workers", "services")
    assert _offenders("shared", forbidden) == []


def test_only_the_composing_package_is_named_by_no_other_service_module() -> None:
    # services.local composes the rest; nothing in the coordinator reaches back into it.
    assert _offenders("services/coordinator", (COMPOSING,)) == []


def test_the_map_floors_have_no_package_cycle() -> None:
    # mapspace/ (the lattice, the stored pose, samples, specs) is the floor below both;
    # exploration/ (strategies, scheduler) stands on manifolds/ (the map), never the reverse.
    coordinator = "graspscape.services.coordinator"
    exploration, manifolds = f"{coordinator}.exploration", f"{coordinator}.manifolds"
    assert _offenders("services/coordinator/mapspace", (exploration, manifolds)) == []
    assert _offenders("services/coordinator/manifolds", (exploration,)) == []


def _loaded_after_importing(modules: list[str]) -> set[str]:
    code = (
        "import importlib, json, sys\n"
        f"for name in {modules!r}:\n"
        "    importlib.import_module(name)\n"
        "print(json.dumps(sorted(sys.modules)))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         cwd=ROOT, timeout=120)
    assert out.returncode == 0, out.stderr
    return set(json.loads(out.stdout.splitlines()[-1]))


def _under(loaded: set[str], package: str) -> list[str]:
    return sorted(m for m in loaded if m == package or m.startswith(package + "."))


@pytest.mark.slow  # imports every module in a subprocess
def test_services_import_the_workers_only_from_the_composing_package() -> None:
    modules = _modules("services", skip=COMPOSING)
    assert "graspscape.services.coordinator.app" in modules
    loaded = _loaded_after_importing(modules)
    assert _under(loaded, "graspscape.workers") == []


@pytest.mark.slow  # a subprocess
def test_shared_imports_neither_side() -> None:
    loaded = _loaded_after_importing(_modules("shared"))
    assert _under(loaded, "graspscape.workers") == []
    assert _under(loaded, "graspscape.services") == []


@pytest.mark.slow  # a subprocess
def test_workers_import_no_service() -> None:
    loaded = _loaded_after_importing(_modules("workers"))
    assert _under(loaded, "graspscape.services") == []
