"""One exploration's map picture and manifold table, straight from the store (used by the
`map.png`/`map.svg` routes, the `map show` command and `explore` when it finishes).

The picture is drawn from the stored manifold table (brought up to date first, as every read
does) and the poses' stored labels (`maps.points`), never by regrouping every pose on read;
the bytes are kept for the last few (exploration, its version, cut) asked for, since a
finished map does not change. A finished map's default picture is drawn ahead and stored
(maps/stored.py), so its first read in a process is a row read.
"""

from __future__ import annotations

import json
import math
from collections import OrderedDict
from pathlib import Path
from typing import Literal

from graspscape.services.coordinator.errors import InvalidInput, NotFound
from graspscape.services.coordinator.exploration.lattice import Lattice
from graspscape.services.coordinator.store.models import ExplorationRow
from sqlalchemy.orm import Session

Cut = Literal["horizontal", "vertical"]
CACHED_PICTURES = 16
_cache: OrderedDict[tuple[object, ...], tuple[bytes, int, int]] = OrderedDict()


def picture_bytes(session: Session, exploration_id: int, fmt: Literal["png", "svg"], *,
                  cut: Cut = "horizontal", phi0_deg: float = 0.0, attitude: int = 0,
                  title: str | None = None, r_mm: float | None = None
                  ) -> tuple[bytes, int, int]:
    """The map (PNG or SVG) with its manifold and lattice pose counts; `r_mm`: only the cut's
    band at that r (snapped to the nearest level of the finest lattice; None: every r).
    Raises NotFound, InvalidInput (an attitude or r the grid does not have)."""
    from graspscape.services.coordinator.exploration.samples import lattice_of
    from graspscape.services.coordinator.exploration.specs import spec_of
    from graspscape.services.coordinator.manifolds.service import (
        ensure_manifolds,
        stored_manifolds,
    )
    from graspscape.services.coordinator.maps.points import stored_points
    from graspscape.services.coordinator.maps.render import render_map
    from graspscape.services.coordinator.maps.stored import default_title, stored_default
    from graspscape.services.coordinator.objects.geometry import object_mesh

    ensure_manifolds(session, exploration_id)
    row = session.get(ExplorationRow, exploration_id)
    if row is None:
        raise NotFound(f"exploration {exploration_id} does not exist")
    spec = spec_of(row)
    lattice = lattice_of(spec)
    if attitude >= len(lattice.attitudes):
        raise InvalidInput(
            f"attitude {attitude} out of range: the grid has {len(lattice.attitudes)}",
            loc=("query", "attitude"))
    r_level = None if r_mm is None else r_level_of(lattice, r_mm)
    if title is None:
        title = f"{spec.label or ''}".strip()
    # The version of what is drawn: the poses and the manifold table stored for them.
    key = (str(session.get_bind().url), exploration_id, row.created_at, row.updated_at,
           row.poses_done, row.manifolds_poses_done, row.manifolds_final, fmt, cut, phi0_deg,
           attitude, title, r_level)
    if key in _cache:
        _cache.move_to_end(key)
        return _cache[key]
    if (fmt, cut, phi0_deg, attitude, title, r_level) == (
            "png", "horizontal", 0.0, 0, default_title(exploration_id), None):
        # The default picture of a finished map, drawn ahead (maps/stored.py).
        stored = stored_default(session, row)
        if stored is not None:
            _cache[key] = stored
            return stored
    points = stored_points(session, exploration_id, lattice)
    manifolds = stored_manifolds(session, exploration_id)
    data = render_map(lattice, points, manifolds, object_mesh(session, row.object_id),
                      cut=cut, phi0=math.radians(phi0_deg), attitude=attitude, fmt=fmt,
                      title=title, r_level=r_level)
    _cache[key] = (data, len(manifolds), len(points))
    while len(_cache) > CACHED_PICTURES:
        _cache.popitem(last=False)
    return _cache[key]


def r_level_of(lattice: Lattice, r_mm: float) -> float:
    """The finest lattice's r level (m) nearest `r_mm`; InvalidInput beyond the grid's r range
    by more than half a finest step."""
    grid, step = lattice.grid, lattice.dr(lattice.depth)
    r = r_mm / 1000.0
    if not (grid.r_min - step / 2 - 1e-12 <= r <= grid.r_max + step / 2 + 1e-12):
        raise InvalidInput(
            f"r {r_mm:g} mm out of range: the grid's r runs from {grid.r_min * 1000:g} to "
            f"{grid.r_max * 1000:g} mm", loc=("query", "r_mm"))
    if step <= 0:  # one r level only
        return round(grid.r_min, 9)
    index = min(max(round((r - grid.r_min) / step), 0), round((grid.r_max - grid.r_min) / step))
    return round(grid.r_min + index * step, 9)


def write_map_files(session: Session, exploration_id: int, picture: Path,
                    table: Path | None = None, *, cut: Cut = "horizontal", phi0_deg: float = 0.0,
                    attitude: int = 0, r_mm: float | None = None) -> tuple[int, int]:
    """Writes the map (PNG or SVG by suffix) and optionally the manifold table (JSON);
    returns (manifolds, poses)."""
    from graspscape.services.coordinator.manifolds.service import stored_manifolds

    fmt: Literal["png", "svg"] = "svg" if picture.suffix.lower() == ".svg" else "png"
    data, n_manifolds, n_poses = picture_bytes(session, exploration_id, fmt, cut=cut,
                                               phi0_deg=phi0_deg, attitude=attitude,
                                               r_mm=r_mm)
    picture.write_bytes(data)
    if table is not None:
        items = stored_manifolds(session, exploration_id)
        table.write_text(json.dumps([m.model_dump(mode="json") for m in items], indent=2))
    return n_manifolds, n_poses
