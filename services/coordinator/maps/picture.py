"""One exploration's map picture and manifold table, straight from the store (used by the
`map.png`/`map.svg` routes, the `map show` command and `explore` when it finishes).

The picture is drawn from the stored manifold table (brought up to date first, as every read
does) and the poses' stored labels (`maps.points`), never by regrouping every pose on read;
the bytes are kept for the last few (exploration, its version, cut) asked for, since a
finished map does not change. A finished map's default picture, and a running map's after a
refresh, are drawn ahead and stored (maps/stored.py), so their first read in a process is a
row read while the version matches.

What a picture is drawn from — the poses' arrays and the manifold table, ~0.2 s of reading at
100k poses and seconds at 1M — is kept for the last two map versions (the coordinator
state's `picture_inputs`: state.py), so another cut, φ0, r or attitude of the same version
reads nothing again (nor derives its directions, trees and 3D markers again:
maps/derived.py); and one drawing per picture at a time: a request
for a picture being drawn waits for it instead of drawing it too (the 8 clients of one page ask
for the same picture at once), and the default picture waits for its draw-ahead in flight.
When a stored default picture is served and its version's inputs are not kept (a restart,
another process), they are read ahead in a background thread (`read_ahead`): a viewer sees
the default picture first, and at 1M poses the read is most of a first cut's cost.
"""

from __future__ import annotations

import json
import logging
import math
import threading
from collections.abc import Hashable
from pathlib import Path
from typing import Any, Literal

from graspscape.services.coordinator.errors import InvalidInput, NotFound
from graspscape.services.coordinator.exploration.lattice import Lattice
from graspscape.services.coordinator.manifolds.summary import ManifoldSummary
from graspscape.services.coordinator.maps.points import MapPoints
from graspscape.services.coordinator.state import Bounded, current
from graspscape.services.coordinator.store.models import ExplorationRow
from sqlalchemy.orm import Session

Cut = Literal["horizontal", "vertical"]
# The state's `drawing`, `reading` (versions whose inputs are being read) and `reading_ahead`
# (read_ahead threads in flight), across the server's threads; its caches lock themselves.
_lock = threading.Lock()
log = logging.getLogger("graspscape.coordinator.maps")


def picture_bytes(session: Session, exploration_id: int, fmt: Literal["png", "svg"], *,
                  cut: Cut = "horizontal", phi0_deg: float = 0.0, attitude: int = 0,
                  title: str | None = None, r_mm: float | None = None, ensure: bool = False,
                  use_stored: bool = True) -> tuple[bytes, int, int]:
    """The map (PNG or SVG) with its manifold and lattice pose counts; `r_mm`: only the cut's
    band at that r (snapped to the nearest level of the finest lattice; None: every r);
    `ensure=True`: the table brought up to date first (writers: the CLI, the atlas; a
    route never does), else drawn as stored;
    `use_stored=False`: the default picture drawn, not read back from its stored row (a
    draw-ahead drawing it again). Raises NotFound, InvalidInput (an attitude or r the grid
    does not have)."""
    from graspscape.services.coordinator.exploration.samples import lattice_of
    from graspscape.services.coordinator.exploration.specs import spec_of
    from graspscape.services.coordinator.manifolds.service import ensure_manifolds
    from graspscape.services.coordinator.maps.render import render_map
    from graspscape.services.coordinator.maps.stored import (
        default_title,
        in_flight,
        stored_default,
        version_text,
    )
    from graspscape.services.coordinator.objects.geometry import object_mesh

    if ensure:
        ensure_manifolds(session, exploration_id)
    waited = False
    if (fmt, cut, phi0_deg, attitude, title, r_mm) == (
            "png", "horizontal", 0.0, 0, default_title(exploration_id), None):
        # The default picture: its draw-ahead in flight (maybe started by the refresh just
        # made) is waited for, not drawn a second time beside it; it is then the stored one.
        thread = in_flight(session.get_bind(), exploration_id)
        if thread is not None and thread is not threading.current_thread():
            thread.join(DRAW_AHEAD_WAIT_S)
            waited = True
    row = session.get(ExplorationRow, exploration_id)
    if row is None:
        raise NotFound(f"exploration {exploration_id} does not exist")
    if waited:
        session.refresh(row)  # the version as the draw-ahead's commit left it
    spec = spec_of(row)
    lattice = lattice_of(spec)
    if attitude >= len(lattice.attitudes):
        raise InvalidInput(
            f"attitude {attitude} out of range: the grid has {len(lattice.attitudes)}",
            loc=("query", "attitude"))
    r_level = None if r_mm is None else r_level_of(lattice, r_mm)
    if title is None:
        title = f"{spec.label or ''}".strip()
    version = _version(session, row)
    key = (*version, fmt, cut, phi0_deg, attitude, title, r_level)
    state = current()
    if (found := state.pictures.get(key)) is not None:
        return found
    with _lock:
        drawing = state.drawing.setdefault(key, threading.Lock())
    with drawing:  # one drawing of a picture at a time; the others then find it kept
        if (found := state.pictures.get(key)) is not None:
            return found
        try:
            # The default picture, drawn ahead (maps/stored.py).
            if use_stored and (fmt, cut, phi0_deg, attitude, title, r_level) == (
                    "png", "horizontal", 0.0, 0, default_title(exploration_id), None) and (
                    stored := stored_default(session, row)) is not None:
                # A viewer shown the default picture asks for other cuts next: their reading
                # starts now, in the background, not at the next request.
                read_ahead(session.get_bind(), version, exploration_id, lattice, row.object_id,
                           version_text(row))
                return state.pictures.put(key, stored)
            points, manifolds = _drawn_from(session, version, exploration_id, lattice,
                                            version_text(row))
            data = render_map(lattice, points, manifolds, object_mesh(session, row.object_id),
                              cut=cut, phi0=math.radians(phi0_deg), attitude=attitude,
                              fmt=fmt, title=title, r_level=r_level, panel_key=version,
                              table=table_of(spec))
            return state.pictures.put(key, (data, len(manifolds), len(points)))
        finally:
            with _lock:
                state.drawing.pop(key, None)


def table_of(spec: Any) -> tuple[Any, float] | None:
    """On a table: (its up in the object frame, the centre of mass's height over it)."""
    resting = spec.support.resting
    return None if resting is None else (resting.up(), float(resting.position[2]))


DRAW_AHEAD_WAIT_S = 60.0


def _version(session: Session, row: ExplorationRow) -> tuple[object, ...]:
    """The version of what is drawn: the poses and the manifold table stored for them."""
    return (str(session.get_bind().url), row.id, row.created_at, row.updated_at,
            row.poses_done, row.manifolds_poses_done, row.manifolds_final)


def version_points(session: Session, exploration_id: int) -> MapPoints:
    """The points of the map's current version, kept or read (what a draw-ahead stores
    beside its picture: maps/stored.py)."""
    from graspscape.services.coordinator.exploration.samples import lattice_of
    from graspscape.services.coordinator.exploration.specs import spec_of
    from graspscape.services.coordinator.maps.stored import version_text

    row = session.get(ExplorationRow, exploration_id)
    if row is None:
        raise NotFound(f"exploration {exploration_id} does not exist")
    return _drawn_from(session, _version(session, row), exploration_id,
                       lattice_of(spec_of(row)), version_text(row))[0]


def _drawn_from(session: Session, version: tuple[object, ...], exploration_id: int,
                lattice: Lattice, stored_version: str) -> tuple[MapPoints, list[ManifoldSummary]]:
    """The poses' arrays and the manifold table at `version`, read once per version: a
    request for a version being read (by a read-ahead) waits for that read. The arrays are
    those stored beside the drawn-ahead picture where it was drawn at this version
    (`stored_version`: maps/stored.version_text), else read from the poses."""
    from graspscape.services.coordinator.manifolds.service import stored_manifolds
    from graspscape.services.coordinator.maps.points import stored_points
    from graspscape.services.coordinator.maps.stored import stored_points_at

    state = current()
    inputs: Bounded[Hashable, tuple[MapPoints, list[ManifoldSummary]]] = state.picture_inputs
    if (found := inputs.get(version)) is not None:
        return found
    with _lock:
        reading = state.reading.setdefault(version, threading.Lock())
    with reading:
        if (found := inputs.peek(version)) is not None:
            return found
        try:
            points = stored_points_at(session, exploration_id, stored_version, lattice)
            if points is None:
                points = stored_points(session, exploration_id, lattice)
            found = inputs.put(version, (points, stored_manifolds(session, exploration_id)))
        finally:
            with _lock:
                state.reading.pop(version, None)
    return found


def read_ahead(bind: Any, version: tuple[object, ...], exploration_id: int, lattice: Lattice,
               object_id: int, stored_version: str) -> threading.Thread | None:
    """Read a version's inputs and derive what every cut needs (maps/derived.py: directions,
    attitude 0's tree, the 3D view's markers) in a background thread, unless kept or being
    read: at 1M poses that is ~3 s of the first cut's ~4 s, paid while the viewer looks at
    the default picture. Not a daemon (a stop waits for it, as for the draw-aheads)."""
    state = current()
    with _lock:
        if (version in state.picture_inputs or version in state.reading
                or version in state.reading_ahead):
            return None
        # Started under the lock (its end waits for it) so that it is noted before it ends.
        thread = state.start_thread(_read_ahead, name=f"map-read-{exploration_id}",
                                    args=(bind, version, exploration_id, lattice, object_id,
                                          stored_version))
        state.reading_ahead[version] = thread
    return thread


def _read_ahead(bind: Any, version: tuple[object, ...], exploration_id: int, lattice: Lattice,
                object_id: int, stored_version: str) -> None:
    from graspscape.services.coordinator.maps import derived
    from graspscape.services.coordinator.maps.render import _COLOURS
    from graspscape.services.coordinator.objects.geometry import object_mesh

    try:
        with Session(bind) as session:
            points, _ = _drawn_from(session, version, exploration_id, lattice, stored_version)
            mesh = object_mesh(session, object_id)
        derived.known(points, lattice, 0)
        derived.markers(lattice, points, mesh, _COLOURS)
    except Exception:  # the next cut reads on demand instead
        log.warning("exploration %s: the map's poses were not read ahead", exploration_id,
                    exc_info=True)
    finally:
        with _lock:
            current().reading_ahead.pop(version, None)


def wait_read_ahead(timeout: float = 120.0) -> None:
    """Wait for the reads ahead in flight (tests, benchmarks)."""
    with _lock:
        threads = list(current().reading_ahead.values())
    for thread in threads:
        thread.join(timeout)


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
                                               r_mm=r_mm, ensure=True)
    picture.write_bytes(data)
    if table is not None:
        items = stored_manifolds(session, exploration_id)
        table.write_text(json.dumps([m.model_dump(mode="json") for m in items], indent=2))
    return n_manifolds, n_poses
