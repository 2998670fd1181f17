"""The layers as the tree draws them: shared/ imports neither side, and services/ imports the
workers only from the composing package (graspscape.services.local).

Each check imports every module of a folder in a fresh interpreter and looks at what got
loaded, so an import hidden in a package's __init__ or pulled in transitively counts too.
Imports inside functions are not seen; the composing package is where they belong anyway.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _modules(folder: str, skip: str | None = None) -> list[str]:
    names = []
    for path in sorted((ROOT / folder).rglob("*.py")):
        parts = path.relative_to(ROOT).with_suffix("").parts
        if parts[-1] == "__init__":
            parts = parts[:-1]
        name = ".".join(("graspscape", *parts))
        if skip is None or not (name == skip or name.startswith(skip + ".")):
            names.append(name)
    return names


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
    modules = _modules("services", skip="graspscape.services.local")
    assert "graspscape.services.coordinator.app" in modules
    loaded = _loaded_after_importing(modules)
    assert _under(loaded, "graspscape.workers") == []


@pytest.mark.slow  # a subprocess
def test_shared_imports_neither_side() -> None:
    loaded = _loaded_after_importing(_modules("shared"))
    assert _under(loaded, "graspscape.workers") == []
    assert _under(loaded, "graspscape.services") == []
