"""Manifolds in the store: kept up to date with the stored poses, saved, and queried.

`refresh_manifolds` brings the exploration's manifold rows, the poses' manifold column and
robust scores up to date and notes on the exploration row when (poses done, final); the
keeper (manifolds/keeper.py) runs it after committed batches, throttled, and once more,
final, when the exploration completes; reads never run it. The map is the coordinator's
running map of the exploration (its state's `maps`: state.py; manifolds/live.py and
running.py): a refresh reads the rows stored since the last one, updates what they change and
writes only that, so its cost follows the new poses, not the map. The object mesh is needed
only for volumes (surface radius along each approach direction); it is prepared once per
coordinator and object (`objects.geometry`).
The best grasps (/best and its evidence) are read in manifolds/best.py.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property
from typing import Any

import numpy as np
from graspscape.services.coordinator.errors import NotFound
from graspscape.services.coordinator.manifolds import snapshot
from graspscape.services.coordinator.manifolds.behaviour import StoredPose
from graspscape.services.coordinator.manifolds.grouping import (
    FALLBACK_RADIUS,
    FineLabels,
    surface_radii,
)
from graspscape.services.coordinator.manifolds.live import (
    MapState,
    feed,
    fine_labels_of,
    labels_of,
    update_state,
    write,
)
from graspscape.services.coordinator.manifolds.robust import RobustScore
from graspscape.services.coordinator.manifolds.running import RunningMap
from graspscape.services.coordinator.manifolds.summary import ManifoldMap, ManifoldSummary
from graspscape.services.coordinator.mapspace.lattice import Lattice, Point
from graspscape.services.coordinator.mapspace.samples import lattice_of
from graspscape.services.coordinator.mapspace.specs import spec_of
from graspscape.services.coordinator.objects.geometry import object_mesh
from graspscape.services.coordinator.state import current
from graspscape.services.coordinator.store import explorations
from graspscape.services.coordinator.store.models import (
    FINISHED_STATUSES,
    ExplorationRow,
    ManifoldRow,
    PoseRow,
)
from graspscape.shared.specs.exploration import ExplorationSpec
from sqlalchemy import Text, bindparam, cast, select
from sqlalchemy.orm import Session

log = logging.getLogger("graspscape.coordinator.manifolds")

FALLBACK_RADIUS_M = FALLBACK_RADIUS


def radius_function(mesh: Any | None) -> Any:
    def radius(directions: np.ndarray) -> np.ndarray:
        return surface_radii(mesh, directions, FALLBACK_RADIUS_M)

    return radius


class ComputedMap:
    """The manifold map of the stored poses as of this refresh: the table, and on demand
    (a pass over the map each) the pose → label assignment, the robust scores by key and
    the finest lattice's labels. The samples are the running map's own: do not change them,
    and read the lazy parts before the next refresh of the same exploration."""

    def __init__(self, spec: ExplorationSpec, running: RunningMap, mesh: Any | None) -> None:
        self.spec = spec
        self.lattice = running.lattice
        self.samples = running.samples
        self.mesh = mesh
        self._running = running
        self.manifolds = list(running.table.manifolds)

    @cached_property
    def label_of(self) -> dict[Point, int]:
        return labels_of(self._running)

    @cached_property
    def map(self) -> ManifoldMap:
        table = self._running.table
        return ManifoldMap(
            manifolds=self.manifolds,
            assignment={self.samples[p].key: label for p, label in self.label_of.items()},
            non_viable_volume_cm3=round(table.non_viable_volume_m3 * 1e6, 3),
            viable_volume_cm3=round(table.viable_volume_m3 * 1e6, 3),
            robust={self.samples[p].key: sc for p, sc in self._running.scores.items()},
        )

    @cached_property
    def fine(self) -> FineLabels:
        return fine_labels_of(self._running)


def _state(session: Session, exploration_id: int
           ) -> tuple[ExplorationRow, MapState, Callable[[], RunningMap]]:
    row = session.get(ExplorationRow, exploration_id)
    if row is None:
        raise NotFound(f"exploration {exploration_id} does not exist")
    spec = spec_of(row)
    lattice = lattice_of(spec)
    object_id = row.object_id

    def fresh() -> RunningMap:
        return RunningMap(lattice, radius_function(object_mesh(session, object_id)),
                          maxima_per_manifold=spec.refinement.local_search_starts)

    url = str(session.get_bind().url)
    key = (url, exploration_id, row.created_at)
    folder = snapshot.directory(url)
    return row, current().maps.get(key, fresh, lambda: snapshot.load(folder, key)), fresh


def compute_map(
    session: Session, exploration_id: int, *, samples: dict[Point, StoredPose] | None = None
) -> ComputedMap:
    """The manifold map of the stored poses (not stored by this function; what it changed
    is written by the next refresh). `samples`: ignored (the running map reads the rows
    stored since its last read itself), kept for callers that have them."""
    row, state, fresh = _state(session, exploration_id)
    with state.lock:
        update_state(session, exploration_id, state, fresh)
    return ComputedMap(spec_of(row), state.running, object_mesh(session, row.object_id))


def prefeed(session: Session, exploration_id: int) -> None:
    """The computing of a refresh before its lock: the running map fed the rows stored since
    its last read, with no lock on the exploration's row (`refresh_manifolds` then reads only
    what came after, checks the count and writes, under the lock). The session's read is
    rolled back after: the refresh starts a transaction of its own."""
    _, state, _ = _state(session, exploration_id)
    with state.lock:
        feed(session, exploration_id, state)
    session.rollback()


def refresh_manifolds(
    session: Session,
    exploration_id: int,
    spec: ExplorationSpec | None = None,
    lattice: Lattice | None = None,
    *,
    samples: dict[Point, StoredPose] | None = None,
    final: bool = False,
) -> ComputedMap:
    """Bring the stored manifolds (rows, the poses' manifold column and robust scores) up to
    date with the stored poses, writing what changed (manifolds/live.py), and note when on
    the exploration (`manifolds_poses_done`, `manifolds_final`); caller commits. Returns the
    map, so that a caller drawing it does not compute it again."""
    # The exploration's row first (PostgreSQL: its lock; SQLite: the write lock), then the
    # running map's: an ingest refreshing holds the row lock already, so the order is the
    # same everywhere and two refreshes of one exploration cannot deadlock.
    explorations.lock_for_table(session, exploration_id)
    row, state, fresh = _state(session, exploration_id)
    with state.lock:
        update_state(session, exploration_id, state, fresh)
        write(session, exploration_id, state, final=final)
        # On disk every SAVE_GROWTH of growth, so that a restart does not rebuild it.
        url = str(session.get_bind().url)
        snapshot.maybe_save(snapshot.directory(url), (url, exploration_id, row.created_at),
                            state, final=final)
    return ComputedMap(spec_of(row), state.running, object_mesh(session, row.object_id))


def store_robust_scores(session: Session, exploration_id: int,
                        scores: dict[str, RobustScore]) -> int:
    """Write each pose's robust score (robust_s, robust_q, robust_label) where it changed
    since the last refresh: between refreshes only the poses near new ones change, and reading
    the stored scores costs far less than rewriting every row. Returns the rows written."""
    stored = {
        key: (s, q, label) for key, s, q, label in session.execute(
            select(PoseRow.pose_key, PoseRow.robust_s, PoseRow.robust_q, PoseRow.robust_label)
            .where(PoseRow.exploration_id == exploration_id)
            .execution_options(yield_per=5000))
    }
    changed = []
    for key, sc in scores.items():
        new = (sc.s, sc.q, sc.label.value)
        if stored.get(key) != new:
            changed.append({"k": key, "s": new[0], "q": new[1], "l": new[2]})
    if changed:
        poses = PoseRow.__table__
        session.connection().execute(
            poses.update()
            .where(poses.c.exploration_id == exploration_id, poses.c.pose_key == bindparam("k"))
            .values(robust_s=bindparam("s"), robust_q=bindparam("q"),
                    robust_label=bindparam("l")),
            changed,
        )
    return len(changed)


def require(session: Session, exploration_id: int) -> None:
    """NotFound where the exploration does not exist."""
    _freshness(session, exploration_id)


def _freshness(session: Session, exploration_id: int) -> Any:
    """What says whether the stored manifolds are current, as one row of plain columns (the
    ORM row would decode the exploration's spec on every read)."""
    row = session.execute(
        select(ExplorationRow.status, ExplorationRow.poses_done,
               ExplorationRow.manifolds_poses_done, ExplorationRow.manifolds_final)
        .where(ExplorationRow.id == exploration_id)).one_or_none()
    if row is None:
        raise NotFound(f"exploration {exploration_id} does not exist")
    return row


def ensure_manifolds(session: Session, exploration_id: int) -> ComputedMap | None:
    """Bring the stored manifolds up to date with the stored poses (commits if it had to), for
    the writers that want the table current now (the map CLI, the atlas, the local run's map
    files); the routes never call it. Returns the map where it had to compute it, else None
    (the stored one is current)."""
    return _ensure(session, exploration_id)[1]


def _ensure(session: Session, exploration_id: int) -> tuple[bool, ComputedMap | None]:
    """(final, the map where it had to compute it)."""
    row = _freshness(session, exploration_id)
    done = row.status in FINISHED_STATUSES
    if row.manifolds_poses_done is not None:
        if row.manifolds_poses_done == row.poses_done and (row.manifolds_final or not done):
            return bool(row.manifolds_final), None
    elif row.poses_done == 0:
        return bool(row.manifolds_final), None
    computed = refresh_manifolds(session, exploration_id, final=done)
    session.commit()
    return done, computed


# --- queries ---------------------------------------------------------------------------------
def stored_manifolds(session: Session, exploration_id: int) -> list[ManifoldSummary]:
    if session.get(ExplorationRow, exploration_id) is None:
        raise NotFound(f"exploration {exploration_id} does not exist")
    rows = session.scalars(
        select(ManifoldRow).where(ManifoldRow.exploration_id == exploration_id)
        .order_by(ManifoldRow.label)
    ).all()
    return [ManifoldSummary.model_validate(r.summary) for r in rows if r.summary]


def is_final(session: Session, exploration_id: int) -> bool:
    """Whether the stored manifolds are those of the finished exploration."""
    return bool(session.scalar(select(ExplorationRow.manifolds_final)
                               .where(ExplorationRow.id == exploration_id)))


@dataclass(frozen=True)
class StoredText:
    """A stored manifold as its summary's JSON text and the columns of the dust line."""

    label: int
    large: bool
    size: int
    volume_cm3: float
    summary: str


def stored_texts(session: Session, exploration_id: int,
                 label: int | None = None) -> tuple[bool, list[StoredText]]:
    """(final, the manifolds by label) as stored (the keeper keeps them; a read never
    refreshes) without decoding a summary, the text as stored (the routes copy it into their
    answer). One manifold with `label`. NotFound: no exploration."""
    final = bool(_freshness(session, exploration_id).manifolds_final)
    query = (select(ManifoldRow.label, ManifoldRow.large, ManifoldRow.size,
                    ManifoldRow.volume_cm3, cast(ManifoldRow.summary, Text))
             .where(ManifoldRow.exploration_id == exploration_id,
                    ManifoldRow.summary.is_not(None)))
    if label is not None:
        query = query.where(ManifoldRow.label == label)
    rows = session.execute(query.order_by(ManifoldRow.label)).all()
    return final, [StoredText(lab, bool(large), size, volume or 0.0, text)
                   for lab, large, size, volume, text in rows]
