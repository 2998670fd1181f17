"""Manifolds in the store: recompute from the stored poses, save, and query.

`refresh_manifolds` replaces the exploration's manifold rows and the poses' manifold column
with what `summary.build_map` computes from every stored pose, and notes on the exploration
row when (poses done, final); it runs as results arrive (throttled geometrically:
`maybe_refresh`) and once more, final, when the exploration completes. The grouping comes
from the process's incremental state (`GROUPINGS`, manifolds/incremental.py): a refresh links
in only the poses stored since the last one; the rest of the map is recomputed. The
object mesh is needed only for volumes (surface radius along each approach direction); it is
prepared once per process and object (`objects.geometry`).
The best grasps (/best and its evidence) are read in manifolds/best.py.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Any

import numpy as np
from graspscape.services.coordinator.errors import NotFound
from graspscape.services.coordinator.exploration.lattice import Lattice, Point
from graspscape.services.coordinator.exploration.samples import lattice_of, load_samples
from graspscape.services.coordinator.exploration.specs import spec_of
from graspscape.services.coordinator.manifolds.behaviour import StoredPose
from graspscape.services.coordinator.manifolds.grouping import (
    FALLBACK_RADIUS,
    FineLabels,
    surface_radii,
)
from graspscape.services.coordinator.manifolds.incremental import GroupingCache
from graspscape.services.coordinator.manifolds.robust import (
    RobustScore,
)
from graspscape.services.coordinator.manifolds.summary import (
    ManifoldMap,
    ManifoldSummary,
    build_map,
)
from graspscape.services.coordinator.objects.geometry import object_mesh
from graspscape.services.coordinator.store.models import (
    FINISHED_STATUSES,
    ExplorationRow,
    ManifoldRow,
    PoseRow,
)
from graspscape.shared.specs.exploration import ExplorationSpec
from sqlalchemy import Text, bindparam, cast, delete, select, update
from sqlalchemy.orm import Session

log = logging.getLogger("graspscape.coordinator.manifolds")

REFRESH_EVERY_TILES = 10  # the first incremental refresh: at the 10th finished tile
# Later ones once the stored poses have grown by a quarter since the last refresh: a refresh
# recomputes the whole map, so refreshing every few tiles made the refreshes' total cost grow
# with the square of the exploration's size (measured: 53 of the 61 s of coordinator time on
# the cube at 4 rolls); geometric steps keep it a small multiple of one final refresh.
REFRESH_GROWTH = 0.25
FALLBACK_RADIUS_M = FALLBACK_RADIUS
_KEY_CHUNK = 500
# Grouping states of the explorations this process refreshes (the coordinator's, the local
# runner's): after a restart the first refresh groups the whole map once.
GROUPINGS = GroupingCache()


def radius_function(mesh: Any | None) -> Any:
    def radius(directions: np.ndarray) -> np.ndarray:
        return surface_radii(mesh, directions, FALLBACK_RADIUS_M)

    return radius


@dataclass(frozen=True)
class ComputedMap:
    spec: ExplorationSpec
    lattice: Lattice
    samples: dict[Point, StoredPose]
    map: ManifoldMap
    fine: FineLabels
    label_of: dict[Point, int]
    mesh: Any | None


def compute_map(
    session: Session, exploration_id: int, *, samples: dict[Point, StoredPose] | None = None
) -> ComputedMap:
    """The manifold map of the stored poses (not stored by this function)."""
    row = session.get(ExplorationRow, exploration_id)
    if row is None:
        raise NotFound(f"exploration {exploration_id} does not exist")
    spec = spec_of(row)
    lattice = lattice_of(spec)
    samples = samples if samples is not None else load_samples(session, exploration_id, lattice)
    mesh = object_mesh(session, row.object_id)
    # Grouping from the process's incremental state: only the poses stored since the last
    # refresh are linked in (manifolds/incremental.py); the rest of the map is recomputed.
    key = (str(session.get_bind().url), exploration_id, row.created_at)
    comps = GROUPINGS.components(key, lattice, samples)
    mmap, fine, label_of = build_map(
        lattice, samples, radius_function(mesh),
        maxima_per_manifold=spec.refinement.local_search_starts, comps=comps,
    )
    return ComputedMap(spec, lattice, samples, mmap, fine, label_of, mesh)


def refresh_manifolds(
    session: Session,
    exploration_id: int,
    spec: ExplorationSpec | None = None,
    lattice: Lattice | None = None,
    *,
    samples: dict[Point, StoredPose] | None = None,
    final: bool = False,
) -> ComputedMap:
    """Recompute and store the manifolds (rows and pose assignment) and when, on the
    exploration (`manifolds_poses_done`, `manifolds_final`); caller commits. Returns the map
    it computed, so that a caller drawing it does not compute it again."""
    computed = compute_map(session, exploration_id, samples=samples)
    samples, mmap, label_of = computed.samples, computed.map, computed.label_of
    exploration = session.get(ExplorationRow, exploration_id)
    if exploration is not None:
        exploration.manifolds_poses_done = exploration.poses_done
        exploration.manifolds_final = final
    session.execute(
        update(PoseRow).where(PoseRow.exploration_id == exploration_id)
        .values(manifold_id=None).execution_options(synchronize_session=False)
    )
    session.execute(delete(ManifoldRow).where(ManifoldRow.exploration_id == exploration_id))
    keys_of: dict[int, list[str]] = {}
    for p, label in label_of.items():
        keys_of.setdefault(label, []).append(samples[p].key)
    # A few statements per refresh, not a few per manifold: a cube map has hundreds.
    best_keys = sorted({m.best.key for m in mmap.manifolds})
    signature_of: dict[str, Any] = {}
    for i in range(0, len(best_keys), _KEY_CHUNK):
        signature_of.update((key, signature) for key, signature in session.execute(
            select(PoseRow.pose_key, PoseRow.signature).where(
                PoseRow.exploration_id == exploration_id,
                PoseRow.pose_key.in_(best_keys[i : i + _KEY_CHUNK]))))
    rows = [
        ManifoldRow(
            exploration_id=exploration_id, label=m.label, signature=signature_of.get(m.best.key),
            size=m.pose_count, best_pose_key=m.best.key, best_mu_s=m.best.mu_s,
            summary=m.model_dump(mode="json"), core_volume_cm3=m.core_volume_cm3,
            volume_cm3=m.volume_cm3,
            robust_best_key=m.robust_best.key if m.robust_best else None,
            robust_best_q=m.robust_best.q if m.robust_best else None, large=m.large,
        )
        for m in mmap.manifolds
    ]
    session.add_all(rows)
    session.flush()
    assignments = [{"m": row.id, "k": key}
                   for row, m in zip(rows, mmap.manifolds, strict=True)
                   for key in sorted(keys_of.get(m.label, []))]
    if assignments:
        poses = PoseRow.__table__
        session.connection().execute(
            poses.update()
            .where(poses.c.exploration_id == exploration_id, poses.c.pose_key == bindparam("k"))
            .values(manifold_id=bindparam("m")),
            assignments,
        )
    store_robust_scores(session, exploration_id, mmap.robust)
    return computed


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
    """Bring the stored manifolds up to date with the stored poses (commits if it had to).
    Returns the map where it had to compute it, else None (the stored one is current)."""
    row = _freshness(session, exploration_id)
    done = row.status in FINISHED_STATUSES
    if row.manifolds_poses_done is not None:
        if row.manifolds_poses_done == row.poses_done and (row.manifolds_final or not done):
            return None
    elif row.poses_done == 0:
        return None
    computed = refresh_manifolds(session, exploration_id, final=done)
    session.commit()
    return computed


def maybe_refresh(session: Session, exploration_id: int, spec: ExplorationSpec,
                  lattice: Lattice) -> None:
    """Incremental refresh as tiles finish: first at the REFRESH_EVERY_TILES-th finished
    tile, then whenever the stored poses have grown by REFRESH_GROWTH since the last one."""
    row = session.get(ExplorationRow, exploration_id)
    if row is None:
        return
    refreshed_at = row.manifolds_poses_done
    if refreshed_at:
        due = row.poses_done >= refreshed_at * (1.0 + REFRESH_GROWTH)
    else:  # never refreshed yet: count finished tiles
        from graspscape.services.coordinator.store.models import TileRow, TileState
        from sqlalchemy import func

        done = session.scalar(
            select(func.count()).select_from(TileRow).where(
                TileRow.exploration_id == exploration_id, TileRow.state == TileState.DONE)
        ) or 0
        due = done % REFRESH_EVERY_TILES == 0
    if due:
        refresh_manifolds(session, exploration_id, spec, lattice, final=False)


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
    """(final, the manifolds by label) without decoding a summary: the text as stored (the
    routes copy it into their answer). One manifold with `label`. NotFound: no exploration."""
    final = _freshness(session, exploration_id).manifolds_final
    query = (select(ManifoldRow.label, ManifoldRow.large, ManifoldRow.size,
                    ManifoldRow.volume_cm3, cast(ManifoldRow.summary, Text))
             .where(ManifoldRow.exploration_id == exploration_id,
                    ManifoldRow.summary.is_not(None)))
    if label is not None:
        query = query.where(ManifoldRow.label == label)
    rows = session.execute(query.order_by(ManifoldRow.label)).all()
    return bool(final), [StoredText(lab, bool(large), size, volume or 0.0, text)
                         for lab, large, size, volume, text in rows]
