"""The best grasps of a stored exploration: /best's rankings, read as index walks, and the
evidence behind a pose's robust score (split from manifolds/service.py, which keeps the table).

`best_poses` ranks by the robust map by default (`Rank.ROBUST`: robust, then uncertain,
fragile, futile; by q_δ) or by one stored metric (`rank=point`: the torque margin ratio);
`robust_evidence` counts what backs a returned pose's s_δ: its N_δ members known, evaluated and
held, and the jitters that certify it.
"""

from __future__ import annotations

import math
from collections.abc import Collection, Mapping
from dataclasses import dataclass
from enum import StrEnum

from graspscape.services.coordinator.errors import NotFound
from graspscape.services.coordinator.manifolds.behaviour import StoredPose
from graspscape.services.coordinator.manifolds.p_success import (
    SuccessOut,
    confirmed,
    estimates,
)
from graspscape.services.coordinator.manifolds.robust import (
    Neighbourhoods,
    RobustLabel,
    RobustScore,
    robust_scores,
    score,
)
from graspscape.services.coordinator.manifolds.summary import (
    LABEL_ORDER,
    robust_order,
)
from graspscape.services.coordinator.mapspace.lattice import Lattice, Point
from graspscape.services.coordinator.mapspace.samples import (
    _SAMPLE_COLUMNS as SAMPLE_COLUMNS,
)
from graspscape.services.coordinator.mapspace.samples import lattice_of, load_samples
from graspscape.services.coordinator.mapspace.specs import spec_of
from graspscape.services.coordinator.store import queries
from graspscape.services.coordinator.store.models import (
    ExplorationRow,
    ManifoldRow,
    PoseRow,
)
from sqlalchemy import select
from sqlalchemy.orm import Session

_KEY_CHUNK = 500


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
    # P(success) under the exploration's uncertainty model (manifolds/p_success.py): poses
    # with draws by the lower bound, then k/n; the others after them in the robust order.
    P_SUCCESS = "p_success"


# The ranking of /best and best_poses when none is asked for: the torque margin, which every
# exploration measures on its held poses by default. μs does not predict the margins (Spearman
# 0.09 with this one, 0.09 with the friction margin over 210 held grasps of 6 objects,
# benchmarks/results/metric_validity.json, docs/concepts/quality.md "What /best ranks by"); it is
# kept, shown beside, and breaks ties — and ranks alone where the margin was not measured.
DEFAULT_RANK = Rank.TORQUE_MARGIN_RATIO
# What /best ranks by when none is asked for: the grasp most likely to succeed under the
# stated errors, by the lower bound of P(success). rank=point gives DEFAULT_RANK.
BEST_DEFAULT_RANK = Rank.P_SUCCESS
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
    pose_keys: Collection[str] | None = None,
    engines: Collection[str] | None = None,
) -> list[PoseRow]:
    """Viable poses, best first by `rank` (then μs desc, then key), optionally inside one
    manifold, an approach cone, below a joint effort, and among `pose_keys`.

    Higher is better except for the LOWER_IS_BETTER ranks; poses without the ranking value
    (NULL: the test was not run) come after every pose that has it. `Rank.ROBUST` ranks by the
    robust map at δ = `coarser` steps: at the finest step by the stored scores (label, then
    robust_q; poses the map has not scored yet last), at a coarser one by scores computed
    here over the stored samples (`robust_scores`). With `engines`, only the poses whose
    draws were simulated and counted in each of them, by P(success)."""
    rank = Rank(rank)
    if rank == Rank.POINT:
        rank = DEFAULT_RANK
    if engines:
        rank = Rank.P_SUCCESS
    if rank == Rank.P_SUCCESS:
        est = None if not engines else confirmed(estimates(session, exploration_id), engines)
        return _best_p_success(session, exploration_id, label=label, cone_axis=cone_axis,
                               cone_half_angle=cone_half_angle, max_effort_nm=max_effort_nm,
                               limit=limit, coarser=coarser, est=est, drawn_only=bool(engines))
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
        limit=limit, pose_keys=pose_keys)


def _ranking(rank: Rank) -> queries.Ranking:
    """The store's description of a /best order (the same order the ranks document)."""
    if rank == Rank.MU_S:
        return queries.MU_S
    if rank == Rank.ROBUST:
        return queries.Ranking("robust_q", group="robust_label",
                               group_order=tuple(label.value for label in
                                                 sorted(RobustLabel, key=LABEL_ORDER.get)))
    return queries.Ranking(rank.value, lower_is_better=rank in LOWER_IS_BETTER)


def best_by_p_success(session: Session, exploration_id: int, est: Mapping[str, SuccessOut],
                      *, label: int | None = None, limit: int = 1) -> list[PoseRow]:
    """`best_poses(rank=p_success)` with the exploration's estimates read once by the caller
    (the manifold table asks it for every large manifold)."""
    return _best_p_success(session, exploration_id, label=label, cone_axis=None,
                           cone_half_angle=None, max_effort_nm=None, limit=limit, coarser=0,
                           est=est)


def _best_p_success(session: Session, exploration_id: int, *, label: int | None,
                    cone_axis: tuple[float, float, float] | None, cone_half_angle: float | None,
                    max_effort_nm: float | None, limit: int, coarser: int,
                    est: Mapping[str, SuccessOut] | None = None,
                    drawn_only: bool = False) -> list[PoseRow]:
    """Poses with draws by the lower bound of P(success) (then k/n, μs, key), then (unless
    `drawn_only`) the rest by the robust order, each passing the filters."""
    if est is None:
        est = estimates(session, exploration_id)
    filters = dict(label=label, cone_axis=cone_axis, cone_half_angle=cone_half_angle,
                   max_effort_nm=max_effort_nm)
    # Only the sampled poses are read for the first part: not every viable pose of the map.
    drawn = best_poses(session, exploration_id, limit=len(est), rank=Rank.MU_S,
                       pose_keys=est.keys(), **filters) if est else []
    drawn.sort(key=lambda r: (-est[r.pose_key].lower, -est[r.pose_key].p, -r.mu_s, r.pose_key))
    if drawn_only:
        return drawn[:limit]
    rest = best_poses(session, exploration_id, limit=limit + len(drawn), rank=Rank.ROBUST,
                      coarser=coarser, **filters)
    keys = {r.pose_key for r in drawn}
    return (drawn + [r for r in rest if r.pose_key not in keys])[:limit]


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


# What a neighbour's part in a robust score needs (manifolds/robust.score: viability, μs, the
# digits in contact from the signature, how it was obtained): not the grasp, the largest JSON.
_EVIDENCE_COLUMNS = tuple(c for c in SAMPLE_COLUMNS if c.key != "grasp")


def _samples_by_key(session: Session, exploration_id: int,
                    point_of_key: dict[str, Point]) -> dict[Point, StoredPose]:
    """The stored samples of the lattice points whose pose keys are given (key → point). A
    row stored under a point's key is that point's pose (the key is made of the pose's
    coordinates), so the point is looked up, not found again from the row (load_samples's
    `point_or_none`, the same point)."""
    out: dict[Point, StoredPose] = {}
    wanted = sorted(point_of_key)
    base = select(*_EVIDENCE_COLUMNS).where(PoseRow.exploration_id == exploration_id)
    for i in range(0, len(wanted), _KEY_CHUNK):
        for row in session.execute(base.where(PoseRow.pose_key.in_(wanted[i:i + _KEY_CHUNK]))):
            out[point_of_key[row.pose_key]] = StoredPose.from_row(row)
    return out


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
                    coarser: int = 0, lattice: Lattice | None = None) -> list[Evidence]:
    """The robust score at δ and its evidence for each of a few poses (/best's answer): their
    neighbourhoods read by key, not the whole exploration (`lattice`: the exploration's, where
    the caller has it)."""
    if not rows:
        return []
    lattice = lattice if lattice is not None else lattice_of_exploration(session, exploration_id)
    hood = Neighbourhoods(lattice, coarser)
    own = load_samples(session, exploration_id, lattice, [r.pose_key for r in rows])
    point_of = {s.key: p for p, s in own.items()}
    hoods = {p: hood(p) for p in own}
    point_of_key = {lattice.pose(q).key(): q for qs in hoods.values() for q in qs}
    samples = {**_samples_by_key(session, exploration_id, point_of_key), **own}
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
