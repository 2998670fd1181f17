"""The object's mesh in its centre-of-mass frame, for the coordinator's geometry (symmetry
detection, manifold volumes, map pictures), without importing the workers.

Preparing an object (resolving built-in and catalogue names, closing holes, moving to the
centre of mass and principal axes) is the workers' code; the coordinator must see exactly the
mesh the workers simulate, so it does not reimplement it. The composing entry point
(`graspscape.services.local`) hands that preparation in with `use_mesh_source`; a coordinator
embedded without it has no mesh: symmetry is not detected and volumes use a fixed radius.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from graspscape.services.coordinator.state import current
from graspscape.services.coordinator.store.models import ObjectRow
from graspscape.shared.specs.objects import ObjectSpec
from sqlalchemy.orm import Session

log = logging.getLogger("graspscape.coordinator.objects")


@dataclass(frozen=True)
class MeshSource:
    """How the coordinator gets an object's COM-frame mesh (a trimesh.Trimesh)."""

    prepare: Callable[[ObjectSpec], Any]
    cache_dir: Path  # uploaded meshes are written here for `prepare` to read


_source: MeshSource | None = None


def use_mesh_source(source: MeshSource | None) -> None:
    """Set (or with None, clear) the process's mesh source. The meshes prepared are kept on
    the coordinator's state (state.py), keyed by the source that prepared them."""
    global _source
    _source = source


def object_spec(row: ObjectRow, cache_dir: Path) -> ObjectSpec:
    """The stored object as a spec: its name, or its uploaded mesh written under cache_dir."""
    props = dict(row.properties or {})
    if row.mesh is not None and row.content_hash:
        path = cache_dir / "coordinator-meshes" / f"{row.content_hash}.{row.mesh_format}"
        if not path.is_file():
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_bytes(row.mesh)
        return ObjectSpec(mesh_path=str(path), **props)
    return ObjectSpec(name=row.name, **props)


# The meshes below are cached and shared by every thread of the process, and trimesh builds a
# mesh's spatial index (rtree / libspatialindex) lazily and queries it without a lock: two
# threads querying one mesh at once crashed the process inside rtree (a map picture drawn ahead
# beside one drawn on read, 2026-12-03). Every ray or proximity query of a cached mesh in the
# coordinator holds this lock (manifolds/grouping.surface_radii, exploration/symmetry.detect).
MESH_QUERIES = threading.Lock()


def spec_mesh(spec: ObjectSpec) -> Any:
    """The mesh of an object spec (prepared once per coordinator and spec)."""
    source = _source
    if source is None:
        raise LookupError("no mesh source: the coordinator runs without the workers' "
                          "object preparation (graspscape.services.local wires it)")
    meshes = current().meshes
    key = (source, spec.model_dump_json())
    mesh = meshes.get(key)
    if mesh is None:
        # Two threads preparing one spec at once keep the first: one mesh object per spec.
        mesh = meshes.setdefault(key, source.prepare(spec))
    return mesh


def object_mesh(session: Session, object_id: int) -> Any | None:
    """The object's mesh in its centre-of-mass frame, or None where it cannot be prepared.
    The same object gives the same mesh object (cached), which callers may key by id."""
    row = session.get(ObjectRow, object_id)
    if row is None:
        return None
    if _source is None:
        log.warning("object %s: no mesh source, so no symmetry and volumes at a fixed radius",
                    object_id)
        return None
    try:
        return spec_mesh(object_spec(row, _source.cache_dir))
    except Exception:  # volumes fall back to a fixed radius; the map itself does not need it
        log.exception("object %s: mesh unavailable, so no symmetry and volumes at a fixed "
                      "radius", object_id)
        return None
