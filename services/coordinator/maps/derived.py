"""What a map picture derives from its points (maps/render.py), kept with the points.

Directions, an attitude's nearest-neighbour tree and the 3D view's markers depend only on the
map version's points (and the lattice, the object's mesh), not on the cut, φ0, r or attitude
asked for. At 1M poses deriving them costs more than drawing a cut (the tree of an attitude's
~250k points, a million directions, the markers' unique positions), so they are computed once
per points and kept in `MapPoints.memo`, which lives as long as picture.py keeps that version's
points: another cut of the version uses them as they are — the same values, so the same
picture. The directions and the markers are also stored beside a drawn-ahead picture's points
(`packed`, `unpack`: maps/stored.py), so a process that loads those points derives neither.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from graspscape.services.coordinator.exploration.lattice import Lattice
from graspscape.services.coordinator.manifolds.grouping import FALLBACK_RADIUS, surface_radii
from graspscape.services.coordinator.maps.points import MapPoints
from scipy.spatial import cKDTree

SCATTER_MAX = 25_000  # markers in the 3D view (`scattered`)


def embed(dirs: np.ndarray, r: np.ndarray, lattice: Lattice) -> np.ndarray:
    scale = lattice.dtheta(0) / lattice.grid.dr if lattice.grid.dr > 0 else 0.0
    return np.column_stack([dirs, (r - lattice.grid.r_min) * scale])


def directions(points: MapPoints, lattice: Lattice) -> np.ndarray:
    """Every point's direction, derived once per points and lattice (`MapPoints.memo`)."""
    key = ("directions", lattice)
    found = points.memo.get(key)
    if found is None:
        found = points.memo[key] = points.directions(lattice)
    return found  # type: ignore[return-value]


def known(points: MapPoints, lattice: Lattice, attitude: int) -> tuple[MapPoints, Any]:
    """The points of one attitude and their nearest-neighbour tree (None without points),
    built once per points, lattice and attitude (`MapPoints.memo`): at 1M poses the tree of an
    attitude's ~250k points costs more than the cut's queries on it."""
    key = ("known", lattice, attitude)
    found = points.memo.get(key)
    if found is None:
        mask = points.attitude == attitude
        of_attitude = points.take(mask)
        tree = cKDTree(embed(directions(points, lattice)[mask], of_attitude.r, lattice)) if len(
            of_attitude) else None
        found = points.memo[key] = (of_attitude, tree)
    return found  # type: ignore[return-value]


def scattered(pts: MapPoints) -> MapPoints:
    """The viable points the 3D view draws: all of them up to SCATTER_MAX; beyond, each
    position once per label (attitudes share positions), then an even subset (every k-th in
    point order) — a million markers in a 600-pixel panel only overdraw one another and cost
    seconds each."""
    return pts if len(pts) <= SCATTER_MAX else pts.take(scattered_index(pts))


def scattered_index(pts: MapPoints) -> np.ndarray:
    """Which of `pts` `scattered` keeps, in point order."""
    if len(pts) <= SCATTER_MAX:
        return np.arange(len(pts))
    # (ring, azimuth, r index, label) as one integer: a 1-D unique is a plain sort, where
    # unique rows of a 4-column array sort a structured view (~10 times slower at 1M poses);
    # the same first occurrences, so the same markers.
    columns = [pts.ring, pts.azimuth, pts.r_index, pts.label + 1]
    spans = [int(c.max()) + 1 for c in columns]
    if math.prod(spans) < 2**62:
        code = np.zeros(len(pts), dtype=np.int64)
        for column, span in zip(columns, spans, strict=True):
            code = code * span + column
        _, first = np.unique(code, return_index=True)
    else:  # too wide for one integer (never at the grid sizes used)
        _, first = np.unique(np.stack(columns, axis=1), axis=0, return_index=True)
    first = np.sort(first)
    step = -(-len(first) // SCATTER_MAX)
    return first[::step] if step > 1 else first


def markers(lattice: Lattice, points: MapPoints, mesh: Any | None,
            palette: Sequence[Any]) -> tuple[np.ndarray, list[Any]]:
    """The 3D view's marker positions and colours, derived once per points, lattice and mesh
    (`MapPoints.memo`; the mesh is the object's cached one, kept with them so its id stays),
    or taken from what `unpack` put back (derived with the map's own mesh)."""
    key = ("markers", lattice, id(mesh))
    found = points.memo.get(key)
    if found is None:
        which, pos = _marker_positions(lattice, points, mesh)
        labels = np.where(points.label[which] >= 0, points.label[which], 0).tolist()
        colours = [palette[i % len(palette)] for i in labels]
        found = points.memo[key] = (pos, colours, mesh)
    return found[0], found[1]  # type: ignore[index]


def _marker_positions(lattice: Lattice, points: MapPoints,
                      mesh: Any | None) -> tuple[np.ndarray, np.ndarray]:
    """Which points the 3D view marks, and where (each direction's surface radius + r)."""
    kept = points.memo.get(("marker positions", lattice))
    if kept is not None:
        return kept  # type: ignore[return-value]
    viable = np.flatnonzero(points.viable)
    which = viable[scattered_index(points.take(viable))]
    pos = np.zeros((0, 3))
    if len(which):
        dirs = directions(points, lattice)[which]
        # One ray per direction, not per pose: many r levels and attitudes share one.
        unique, inverse = np.unique(dirs, axis=0, return_inverse=True)
        rho = surface_radii(mesh, unique, FALLBACK_RADIUS)[inverse.ravel()]
        pos = dirs * (rho + points.r[which])[:, None]
    found = points.memo[("marker positions", lattice)] = (which, pos)
    return found


# What `packed` stores beside the points (maps/points.points_bytes' `extra`).
_PACKED = ("directions", "marker_which", "marker_pos")


def packed(points: MapPoints, lattice: Lattice, mesh: Any | None) -> dict[str, np.ndarray]:
    """The derivations a cold cut would otherwise make (~0.35 s of a first cut at 1M poses:
    a Python call per distinct direction, one ray per marked direction), for storing beside
    the points: each distinct (ring, azimuth)'s direction in point order, and the 3D view's
    marked points and positions. `unpack` puts them back as these very values."""
    first = _runs(points)
    if first is None:  # not in point order (never from the store): nothing to pack
        return {}
    which, pos = _marker_positions(lattice, points, mesh)
    return {"directions": directions(points, lattice)[first], "marker_which": which,
            "marker_pos": pos}


def unpack(points: MapPoints, lattice: Lattice, arrays: dict[str, np.ndarray]) -> None:
    """Put back into `points.memo` what `packed` stored with them (for `lattice`, the map's
    own); arrays that do not fit the points (another version's) are left unused."""
    if set(_PACKED) - arrays.keys():
        return
    first = _runs(points)
    unique = arrays["directions"]
    if first is None or len(first) != len(unique) or unique.shape[1:] != (3,):
        return
    run = np.zeros(len(points), dtype=np.int64)
    if len(points):
        run[first[1:]] = 1
    points.memo[("directions", lattice)] = unique[np.cumsum(run)]
    which, pos = arrays["marker_which"], arrays["marker_pos"]
    if len(which) == len(pos) and (not len(which) or 0 <= which.min() <= which.max() < len(
            points)):
        points.memo[("marker positions", lattice)] = (which.astype(np.int64), pos)


def _runs(points: MapPoints) -> np.ndarray | None:
    """Where each run of one (ring, azimuth) starts, in point order (None: not sorted so)."""
    code = points.ring.astype(np.int64) * (1 << 32) + points.azimuth
    if len(code) and bool((code[1:] < code[:-1]).any()):
        return None
    return np.flatnonzero(np.r_[True, code[1:] != code[:-1]]) if len(code) else np.zeros(
        0, dtype=np.int64)
