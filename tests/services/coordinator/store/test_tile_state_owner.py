"""The store is a leaf, and one module writes tile state (issue #17): checked on the source and
on what importing the store loads, so a later change cannot quietly undo either."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import graspscape.services.coordinator as coordinator
from graspscape.services.coordinator.store.queue import LeasedTile as QueueLeasedTile
from graspscape.shared.wire.messages import LeasedTile, TileLease

ROOT = Path(coordinator.__file__).parent
OWNER = ROOT / "store" / "tiles.py"
# A statement that writes the tiles table: update(TileRow) / insert(TileRow) / a raw UPDATE.
WRITES_TILES = re.compile(r"(update|insert)\(\s*TileRow\b|UPDATE\s+tiles\b|INSERT\s+INTO\s+tiles\b")


def test_only_store_tiles_writes_tile_rows() -> None:
    writers = sorted(
        str(path.relative_to(ROOT)) for path in ROOT.rglob("*.py")
        if path != OWNER and WRITES_TILES.search(path.read_text())
    )
    assert writers == []
    assert WRITES_TILES.search(OWNER.read_text())


def test_the_store_imports_no_exploration_manifolds_or_dispatch_module() -> None:
    code = (
        "import sys, pkgutil, importlib\n"
        "import graspscape.services.coordinator.store as store\n"
        "for m in pkgutil.iter_modules(store.__path__):\n"
        "    importlib.import_module(f'{store.__name__}.{m.name}')\n"
        "bad = sorted(n for n in sys.modules if n.startswith(tuple("
        "f'graspscape.services.coordinator.{p}' for p in ('exploration', 'manifolds', "
        "'dispatch', 'api', 'maps'))))\n"
        "print(bad)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.strip()
    assert out == "[]"


def test_the_wire_lease_is_the_leased_row_plus_its_context() -> None:
    assert QueueLeasedTile is LeasedTile
    assert issubclass(TileLease, LeasedTile)
    assert set(LeasedTile.model_fields) < set(TileLease.model_fields)
