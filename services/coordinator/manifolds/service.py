"""Manifolds in the store: recompute from the stored poses, save, and query.

`refresh_manifolds` replaces the exploration's manifold rows and the poses' manifold column
with what `summary.build_map` computes from every stored pose, and notes on the exploration
row when (poses done, final); it runs as results arrive (throttled geometrically:
`maybe_refresh`) and once more, final, when the exploration completes. The grouping comes
from the process's incremental state (`GROUPINGS`, manifolds/incremental.py): a refresh links
in only the poses stored since the last one; the rest of the map is recomputed. The
object mesh is needed only for volumes (surface radius along each approach direction); it is
prepared once per process and object (`objects.geometry`).
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from enum import StrEnum
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
    Neighbourhoods,
    RobustLabel,
    RobustScore,
    robust_scores,
    score,
)
from graspscape.services.coordinator.manifolds.summary import (
    LABEL_ORDER,
    ManifoldMap,
    ManifoldSummary,
    build_map,
    robust_order,
)
from graspscape.services.coordinator.objects.geometry import object_mesh
from graspscape.services.coordinator.store import queries
from graspscape.services.coordinator.store.models import (
    FINISHED_STATUSES,
    ExplorationRow,
    ManifoldRow,
    PoseRow,
)
from graspscape.shared.specs.exploration import ExplorationSpec
from sqlalchemy import bindparam, delete, select, update
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


def ensure_manifolds(session: Session, exploration_id: int) -> ComputedMap | None:
    """Bring the stored manifolds up to date with the stored poses (commits if it had to).
    Returns the map where it had to compute it, else None (the stored one is current)."""
    row = session.get(ExplorationRow, exploration_id)
    if row is None:
        raise NotFound(f"exploration {exploration_id} does not exist")
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
    row = session.get(ExplorationRow, exploration_id)
    return bool(row is not None and row.manifolds_final)


def approach_vector(theta: float, phi: float) -> tuple[float, float, float]:
    """Direction the gripper moves in to approach (from its start toward the object)."""
    st = math.sin(theta)
    return (-st * math.cos(phi), -st * math.sin(phi), -math.cos(theta))


class Rank(StrEnum):
    """What `best_poses` ranks by: μs, a static grasp metric, or a stored robustness margin or
    grasp test (the poses' columns of the same name)."""

    MU_S = "mu_s"
    MU_G = "mu_g"
    MU_F = "mu_f"
    MU_M = "mu_m"
    TORQUE_MARGIN_NM = "torque_margin_nm"
    TORQUE_MARGIN_RATIO = "torque_margin_ratio"
    FRICTION_MARGIN = "friction_margin"
    GRAVITY_TEST_SHARE = "gravity_test_share"
    FORCE_TEST_SHARE = "force_test_share"
    TUG_FORCE_N = "tug_force_n"
    SHAKE_SURVIVAL_S = "shake_survival_s"
    # The robust ranking (manifolds/robust.py): robust-labelled poses first, then uncertain,
    # fragile, futile; within each the highest robust quality q_δ, then μs.
    ROBUST = "robust"
    # The pointwise ranking: DEFAULT_RANK below, the pose's own value.
    POINT = "point"


# The ranking of /best and best_poses when none is asked for: the torque margin, which every
# exploration measures on its held poses by default. μs does not predict the margins (Spearman
# 0.09 with this one, 0.09 with the friction margin over 210 held grasps of 6 objects,
# benchmarks/results/metric_validity.json, docs/metrics.md "What /best ranks by"); it is kept,
# shown beside, and breaks ties — and ranks alone where the margin was not measured.
DEFAULT_RANK = Rank.TORQUE_MARGIN_RATIO
# What /best ranks by when none is asked for: the grasp that survives the robot's pose error
# (issue 18). rank=point gives DEFAULT_RANK, the pose's own value.
BEST_DEFAULT_RANK = Rank.ROBUST
# Where a lower value is the better grasp: it still holds with less friction or less effort.
LOWER_IS_BETTER = frozenset({Rank.FRICTION_MARGIN, Rank.TORQUE_MARGIN_NM})


def lattice_of_exploration(session: Session, exploration_id: int) -> Lattice:
    """The lattice of an exploration's spec."""
    row = session.get(ExplorationRow, exploration_id)
    if row is None:
        raise NotFound(f"exploration {exploration_id} does not exist")
    return lattice_of(spec_of(row))


def best_poses(
    session: Session,
    exploration_id: int,
    *,
    label: int | None = None,
    cone_axis: tuple[float, float, float] | None = None,
    cone_half_angle: float | None = None,
    max_effort_nm: float | None = None,
    limit: int = 1,
    rank: Rank | str = DEFAULT_RANK,
    coarser: int = 0,
) -> list[PoseRow]:
    """Viable poses, best first by `rank` (then μs desc, then key), optionally inside one
    manifold, an approach cone, and below a joint effort.

    Higher is better except for the LOWER_IS_BETTER ranks; poses without the ranking value
    (NULL: the test was not run) come after every pose that has it. `Rank.ROBUST` ranks by the
    robust map at δ = `coarser` steps: at the finest step by the stored scores (label, then
    robust_q; poses the map has not scored yet last), at a coarser one by scores computed
    here over the stored samples (`robust_scores`)."""
    rank = Rank(rank)
    if rank == Rank.POINT:
        rank = DEFAULT_RANK
    if rank == Rank.ROBUST and coarser > 0:
        return _best_robust_coarser(session, exploration_id, label=label, cone_axis=cone_axis,
                                    cone_half_angle=cone_half_angle,
                                    max_effort_nm=max_effort_nm, limit=limit, coarser=coarser)
    if session.get(ExplorationRow, exploration_id) is None:
        raise NotFound(f"exploration {exploration_id} does not exist")
    manifold_id = None
    if label is not None:
        manifold_id = session.scalar(select(ManifoldRow.id).where(
            ManifoldRow.exploration_id == exploration_id, ManifoldRow.label == label))
        if manifold_id is None:
            raise NotFound(f"exploration {exploration_id} has no manifold {label}")
    # An index walk in the ranking's order that stops at `limit` (store/queries.py,
    # migration 0011): no sort of the exploration's poses, no JSON decoded but the winners'.
    return queries.best_pose_rows(
        session, exploration_id, ranking=_ranking(rank), manifold_id=manifold_id,
        cone_axis=cone_axis, cone_half_angle=cone_half_angle, max_effort_nm=max_effort_nm,
        limit=limit)


def _ranking(rank: Rank) -> queries.Ranking:
    """The store's description of a /best order (the same order the ranks document)."""
    if rank == Rank.MU_S:
        return queries.MU_S
    if rank == Rank.ROBUST:
        return queries.Ranking("robust_q", group="robust_label",
                               group_order=tuple(label.value for label in
                                                 sorted(RobustLabel, key=LABEL_ORDER.get)))
    return queries.Ranking(rank.value, lower_is_better=rank in LOWER_IS_BETTER)


def _best_robust_coarser(session: Session, exploration_id: int, *, label: int | None,
                         cone_axis: tuple[float, float, float] | None,
                         cone_half_angle: float | None, max_effort_nm: float | None,
                         limit: int, coarser: int) -> list[PoseRow]:
    """The robust ranking at δ = 2^coarser finest steps: every candidate passing the filters
    (best_poses by μs, no limit), scored over the stored samples, sorted by `robust_order`."""
    candidates = best_poses(session, exploration_id, label=label, cone_axis=cone_axis,
                            cone_half_angle=cone_half_angle, max_effort_nm=max_effort_nm,
                            limit=2**62, rank=Rank.MU_S)
    if not candidates:
        return []
    lattice = lattice_of_exploration(session, exploration_id)
    samples = load_samples(session, exploration_id, lattice)
    point_of = {s.key: p for p, s in samples.items()}
    points = [point_of[r.pose_key] for r in candidates if r.pose_key in point_of]
    scores = robust_scores(lattice, samples, points, coarser=coarser)
    ranked = sorted(points, key=lambda p: robust_order(samples[p], scores[p]))[:limit]
    by_key = {r.pose_key: r for r in candidates}
    return [by_key[samples[p].key] for p in ranked]


@dataclass(frozen=True)
class Evidence:
    """What backs a pose's robust score: its N_δ ∪ {p} at the δ asked for, and the evaluations
    made for its certification (poses whose `certifies` is its key)."""

    score: RobustScore | None  # None: the pose is not on the lattice
    neighbours: int  # members of N_δ(p)
    neighbours_known: int  # of them stored (evaluated or shortcut-inferred)
    neighbours_evaluated: int  # of them simulated by a worker
    neighbours_held: int  # of them held with p's target grasp type
    certifying: int  # poses stored for p's certification
    certifying_held: int  # of them held (viable)


def robust_evidence(session: Session, exploration_id: int, rows: list[PoseRow], *,
                    coarser: int = 0) -> list[Evidence]:
    """The robust score at δ and its evidence for each of a few poses (/best's answer): their
    neighbourhoods read by key, not the whole exploration."""
    if not rows:
        return []
    lattice = lattice_of_exploration(session, exploration_id)
    hood = Neighbourhoods(lattice, coarser)
    own = load_samples(session, exploration_id, lattice, [r.pose_key for r in rows])
    point_of = {s.key: p for p, s in own.items()}
    hoods = {p: hood(p) for p in own}
    keys = {lattice.pose(q).key() for qs in hoods.values() for q in qs}
    samples = {**load_samples(session, exploration_id, lattice, keys), **own}
    wanted = [r.pose_key for r in rows]
    cert: dict[str, list[bool]] = {}
    for i in range(0, len(wanted), _KEY_CHUNK):
        for key, viable in session.execute(
            select(PoseRow.certifies, PoseRow.viable).where(
                PoseRow.exploration_id == exploration_id,
                PoseRow.certifies.in_(wanted[i : i + _KEY_CHUNK]))):
            cert.setdefault(key, []).append(bool(viable))
    out = []
    for row in rows:
        held_cert = cert.get(row.pose_key, [])
        p = point_of.get(row.pose_key)
        if p is None:
            out.append(Evidence(None, 0, 0, 0, 0, len(held_cert), sum(held_cert)))
            continue
        members = [samples.get(q) for q in hoods[p]]
        sc = score(samples[p], members)
        known = [m for m in members if m is not None]
        target = frozenset(sc.target) if sc.target is not None else None
        out.append(Evidence(
            score=sc, neighbours=len(members), neighbours_known=len(known),
            neighbours_evaluated=sum(1 for m in known if m.source == "evaluated"),
            neighbours_held=sum(1 for m in known if m.viable and m.digits == target),
            certifying=len(held_cert), certifying_held=sum(held_cert),
        ))
    return out
