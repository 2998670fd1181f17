"""Snapshots of the running maps on disk, so that a restart does not rebuild them from every row.

Rebuilding an exploration's running map (manifolds/running.py) after a restart feeds it every
stored pose: about a minute at 100k poses on a loaded 2-core VM, more than the full recompute
it replaced. Instead, after a refresh has written its table, the map is saved (pickled, with
the rows it has read and the table rows it wrote: `live.MapState`) when the exploration has
grown by SAVE_GROWTH since the last save, and when it is final. After a restart the first
refresh loads it and reads only the rows stored since, as any refresh does; everything it
trusts is checked as before (the rows read must add up to the exploration's `poses_done`,
the table must be as the state last wrote it: live.py), so a stale or foreign snapshot costs
one rebuild, never a wrong table; one written by other code (a digest of the modules whose
objects it holds: `code_version`) is not loaded at all.

Where: the directory in GRASPSCAPE_MANIFOLD_SNAPSHOTS, else, for a SQLite file, a directory
beside it (`<database>.manifold-maps`), else the coordinator's folder
(its state's `snapshot_dir`, which `create_app` sets to `<database.data_dir>/manifold-maps`, a
volume in docker-compose: state.py); none (no
snapshots) where nothing applies, e.g. a PostgreSQL store used outside a coordinator.
Files are written whole (a temporary file, then renamed) and are the coordinator's own: they
are unpickled, so the directory must not be writable by anyone else. Deleting an exploration
removes its file (exploration/service.py).
"""

from __future__ import annotations

import functools
import gc
import hashlib
import logging
import os
import pickle
import time
from collections.abc import Hashable, Iterator
from contextlib import contextmanager
from pathlib import Path

from graspscape.services.coordinator.manifolds.live import MapState
from graspscape.services.coordinator.state import current

log = logging.getLogger("graspscape.coordinator.manifolds")

ENV = "GRASPSCAPE_MANIFOLD_SNAPSHOTS"
FORMAT = 2  # with the code's digest (`code_version`): files of other code are ignored
# (2: lattice.Point a NamedTuple, was a dataclass: a format-1 file must be rebuilt)
SAVE_GROWTH = 1.2  # save when the rows read have grown by this factor since the last save
MIN_ROWS = 5_000  # smaller maps rebuild in a few seconds: not worth a file


@functools.cache
def code_version() -> str:
    """A digest of the source of every module whose classes a snapshot holds: a snapshot
    written by other code (an upgrade) is not loaded, rather than loaded half-compatible."""
    from graspscape.services.coordinator.manifolds import (
        aggregate,
        behaviour,
        exact,
        grouping,
        incremental,
        live,
        pairs,
        robust,
        running,
        specks,
        summary,
    )
    from graspscape.services.coordinator.mapspace import lattice, pose

    digest = hashlib.sha256(str(FORMAT).encode())
    for module in (lattice, pose, aggregate, behaviour, exact, grouping, incremental, live, pairs,
                   robust, running, specks, summary):
        digest.update(Path(module.__file__ or "").read_bytes())
    return digest.hexdigest()[:16]


def directory(url: str) -> Path | None:
    """Where this database's snapshots go (see the module docstring), or None."""
    given = os.environ.get(ENV)
    if given:
        return Path(given)
    if url.startswith("sqlite:///") and not url.endswith(":memory:") and len(url) > 10:
        return Path(url[len("sqlite:///"):] + ".manifold-maps")
    return current().snapshot_dir


def _path(folder: Path, key: Hashable) -> Path:
    return folder / (hashlib.sha256(repr(key).encode()).hexdigest()[:32] + ".pickle")


def load(folder: Path | None, key: Hashable) -> MapState | None:
    """The saved state of this key, or None (none saved, another format or key, unreadable)."""
    if folder is None:
        return None
    path = _path(folder, key)
    try:
        with path.open("rb") as f, _no_gc():
            t = time.perf_counter()
            saved = pickle.load(f)
    except FileNotFoundError:
        return None
    except Exception:  # a torn or foreign file: rebuild from the rows instead
        log.exception("manifold snapshot %s unreadable: rebuilding from the rows", path)
        return None
    if not (isinstance(saved, dict) and saved.get("format") == code_version()
            and saved.get("key") == repr(key)):
        return None
    state = MapState(saved["running"], last_id=saved["last_id"], rows=saved["rows"],
                     mark=saved["mark"], rows_of=saved["rows_of"])
    state.saved_rows = state.rows
    log.info("manifold snapshot %s loaded: %d rows in %.1f s", path, state.rows,
             time.perf_counter() - t)
    return state


def maybe_save(folder: Path | None, key: Hashable, state: MapState, *, final: bool) -> bool:
    """Save the state if it has grown enough since its last save (or is final); call right
    after `live.write` (the table as written, nothing pending). True when saved."""
    if folder is None or state.rows < MIN_ROWS or state.dirty or state.rescored:
        return False
    if state.rows < SAVE_GROWTH * state.saved_rows and not (final and state.rows
                                                             > state.saved_rows):
        return False
    folder.mkdir(parents=True, exist_ok=True)
    path = _path(folder, key)
    tmp = path.with_suffix(f".{os.getpid()}.tmp")
    t = time.perf_counter()
    with tmp.open("wb") as f, _no_gc():
        pickle.dump({"format": code_version(), "key": repr(key), "running": state.running,
                     "last_id": state.last_id, "rows": state.rows, "mark": state.mark,
                     "rows_of": state.rows_of}, f, protocol=pickle.HIGHEST_PROTOCOL)
    os.replace(tmp, path)
    state.saved_rows = state.rows
    log.info("manifold snapshot %s saved: %d rows in %.1f s", path, state.rows,
             time.perf_counter() - t)
    return True


@contextmanager
def _no_gc() -> Iterator[None]:
    """The collector off while millions of objects are made or walked: each full pass would
    scan the map being read (and nothing here makes garbage cycles)."""
    was = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if was:
            gc.enable()


def remove(folder: Path | None, key: Hashable) -> None:
    if folder is not None:
        _path(folder, key).unlink(missing_ok=True)
