"""Certification in the store: a round of it for the adaptive strategy, `poses.certifies`,
and the robust best grasps with their evidence for a finished exploration.

The decisions are exploration/certify.py's (pure); this module reads what they need (the
manifold map, robust scores, what certification planned so far) and writes what they decide
as plans. A certification plan's reason names the pose row it certifies
(`certify.reason_for`); when a jitter's result is stored, `mark_certifies` copies the
centre's key into the jitter's `certifies` column, which `/best` and the exports read.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence

import numpy as np
from graspscape.services.coordinator.exploration import certify, racing
from graspscape.services.coordinator.exploration.lattice import Lattice, Point
from graspscape.services.coordinator.exploration.samples import (
    lattice_of,
    load_samples,
)
from graspscape.services.coordinator.exploration.specs import spec_of
from graspscape.services.coordinator.exploration.strategies.base import Planned
from graspscape.services.coordinator.exploration.symmetry import Orbits
from graspscape.services.coordinator.manifolds.behaviour import StoredPose
from graspscape.services.coordinator.manifolds.grouping import FALLBACK_RADIUS, surface_radii
from graspscape.services.coordinator.manifolds.robust import RobustScore, robust_scores
from graspscape.services.coordinator.manifolds.service import ComputedMap
from graspscape.services.coordinator.mapspace.samples import stored_by_key
from graspscape.services.coordinator.objects.geometry import object_mesh
from graspscape.services.coordinator.store.models import (
    ExplorationRow,
    ManifoldRow,
    PosePlanRow,
    PoseRow,
)
from graspscape.shared.specs.exploration import ExplorationSpec
from graspscape.shared.specs.pose import Pose
from pydantic import BaseModel, Field
from sqlalchemy import bindparam, select
from sqlalchemy.orm import Session

_KEY_CHUNK = 500


def _chunks(items: Sequence[str]) -> list[Sequence[str]]:
    return [items[i : i + _KEY_CHUNK] for i in range(0, len(items), _KEY_CHUNK)]


def certification_plans(session: Session, exploration_id: int) -> dict[str, int | None]:
    """Pose key → the id of the pose row it certifies, for every certification plan (None:
    a core claim's evaluation, `certify.CLAIM_REASON`)."""
    rows = session.execute(
        select(PosePlanRow.pose_key, PosePlanRow.reason).where(
            PosePlanRow.exploration_id == exploration_id,
            PosePlanRow.reason.like(f"{certify.REASON_PREFIX}%")))
    out: dict[str, int | None] = {}
    for key, reason in rows:
        centre = certify.centre_id_of(reason)
        if centre is not None or reason == certify.CLAIM_REASON:
            out[key] = centre
    return out


def _keys_of_ids(session: Session, ids: set[int]) -> dict[int, str]:
    wanted = sorted(ids)
    out: dict[int, str] = {}
    for i in range(0, len(wanted), _KEY_CHUNK):
        out.update(session.execute(select(PoseRow.id, PoseRow.pose_key).where(
            PoseRow.id.in_(wanted[i : i + _KEY_CHUNK]))).all())
    return out


def mark_certifies(session: Session, exploration_id: int, keys: Sequence[str]) -> int:
    """Set `certifies` (the centre's key) on the stored jitters among `keys`; returns how
    many. Only off-lattice poses are jitters; a lattice member of N_δ is evidence for any
    pose it neighbours, so it names none."""
    if not keys:
        return 0
    centre_of: dict[str, int] = {}
    for chunk in _chunks(sorted(set(keys))):
        for key, reason in session.execute(
            select(PosePlanRow.pose_key, PosePlanRow.reason).where(
                PosePlanRow.exploration_id == exploration_id, PosePlanRow.pose_key.in_(chunk),
                PosePlanRow.reason.like(f"{certify.REASON_PREFIX}%"))):
            centre = certify.centre_id_of(reason)
            if centre is not None:
                centre_of[key] = centre
    if not centre_of:
        return 0
    key_of = _keys_of_ids(session, set(centre_of.values()))
    updates = [{"k": key, "c": key_of[c]} for key, c in sorted(centre_of.items()) if c in key_of]
    if updates:
        poses = PoseRow.__table__
        session.connection().execute(
            poses.update()
            .where(poses.c.exploration_id == exploration_id, poses.c.pose_key == bindparam("k"))
            .values(certifies=bindparam("c")),
            updates,
        )
    return len(updates)


def _radius(computed: ComputedMap, p: Point) -> float:
    """Surface radius along p's direction (for the jitters' position error): one ray, asked
    only for the centres that get jitters."""
    direction = np.array([computed.lattice.direction(p)])
    return float(surface_radii(computed.mesh, direction, FALLBACK_RADIUS)[0])


def certification_round(session: Session, exploration_id: int, spec: ExplorationSpec,
                        computed: ComputedMap, orbits: Orbits | None, round_: int
                        ) -> list[Planned]:
    """The next round of certification from the current map (module doc), as plans."""
    cert = spec.certification
    lattice, samples = computed.lattice, computed.samples
    if cert.share <= 0:
        return []
    members: dict[int, list[Point]] = {}
    for p, label in computed.label_of.items():
        members.setdefault(label, []).append(p)
    manifolds = [certify.Manifold(m.label, tuple(sorted(members.get(m.label, []))))
                 for m in computed.map.manifolds if m.large]
    plans = certification_plans(session, exploration_id)
    row = session.get(ExplorationRow, exploration_id)
    total = certify.budget(cert, (row.poses_total if row is not None else 0) - len(plans))
    if not manifolds or total <= len(plans):
        return []
    scores = robust_scores(lattice, samples, [p for m in manifolds for p in m.members])
    taken = {s.key for s in samples.values()} | set(session.scalars(
        select(PosePlanRow.pose_key).where(PosePlanRow.exploration_id == exploration_id)))
    # The best grasps may spend all but the core claims' share; the claims get the rest of the
    # budget, so what the grasps leave is not lost. The claims start new candidates until half
    # of what they have left is planned (all of it in the last round), so a later round can
    # move them where the results of the earlier ones showed the map to hold.
    grasps_spent = sum(1 for c in plans.values() if c is not None)
    grasps_room = total - math.ceil(cert.core_share * total - 1e-9) - grasps_spent
    race = _race(session, exploration_id, spec, computed, scores)
    work = certify.plan(lattice, samples, manifolds, scores, cert,
                        budget_left=max(0, grasps_room), taken=taken,
                        radius_m=lambda p: _radius(computed, p), race=race)
    claims_left = total - len(plans) - len(work) if cert.core_share > 0 else 0
    last = round_ >= spec.refinement.local_search_rounds + certify.MAX_ROUNDS
    work += certify.claims(
        lattice, samples, _labels_at(computed), manifolds, room=claims_left,
        start_below=claims_left if last else -(-claims_left // 2),
        taken=taken | {w.pose.key() for w in work})
    if orbits is not None:
        # A member is evaluated as its orbit's representative, mirrored onto it on arrival.
        work = [w if w.point is None else certify.Work(
            lattice.pose(orbits.representative(w.point)), orbits.representative(w.point),
            w.centre, w.label, w.claim) for w in work]
    ids = {k: i for i, k in _ids_of_keys(session, exploration_id,
                                         {samples[w.centre].key for w in work
                                          if not w.claim}).items()}
    out: list[Planned] = []
    seen: set[str] = set()
    for w in work:
        key = w.pose.key()
        if key in seen or key in taken:
            continue
        seen.add(key)
        drawn = w.point is None and not w.claim  # a draw of the uncertainty model
        out.append(Planned(
            w.pose, plan_level=lattice.depth if w.point is None else lattice.birth(w.point),
            tile_level=lattice.depth, round=round_,
            reason=certify.CLAIM_REASON if w.claim
            else certify.reason_for(ids[samples[w.centre].key]),
            draw_engines=spec.draw_engines() if drawn else None,
            draw_scales=w.scales if drawn else None))
    return out


def _race(session: Session, exploration_id: int, spec: ExplorationSpec, computed: ComputedMap,
          scores: Mapping[Point, RobustScore]
          ) -> Callable[[certify.Manifold], list[certify.Work]]:
    """The race of each large manifold's candidates (exploration/racing.py) as plan work."""
    samples = computed.samples

    def race(m: certify.Manifold) -> list[certify.Work]:
        cands = _candidates(session, exploration_id, spec, samples, m.members, scores,
                            lambda p: _radius(computed, p))
        model = spec.uncertainty
        return [certify.Work(q, None, p, m.label,
                             scales=racing.scales_of(samples[p].key, model, i))
                for p, drawn in racing.race_draws(cands) for i, q in drawn]
    return race


def _candidates(session: Session, exploration_id: int, spec: ExplorationSpec,
                samples: Mapping[Point, StoredPose], members: Sequence[Point],
                scores: Mapping[Point, RobustScore], radius: Callable[[Point], float]
                ) -> list[racing.Candidate]:
    """A manifold's race candidates with their stored draws' estimates: the best members by
    the robust order, and every member drawn for already. The map can change after a round
    (refinement, local search): a candidate it no longer ranks first keeps its draws in the
    race and in the answer, as /best's ranking keeps them."""
    points = racing.candidates(members, samples, scores, max(1, spec.certification.candidates))
    drawn = set(session.scalars(select(PoseRow.certifies).where(
        PoseRow.exploration_id == exploration_id, PoseRow.certifies.is_not(None)).distinct()))
    chosen = set(points)
    points += [p for p in members
               if samples[p].key in drawn and samples[p].viable and p not in chosen]
    seqs = {p: racing.draw_poses(samples[p], spec.uncertainty, radius(p),
                                 racing.success.LOOKS[-1]) for p in points}
    stored = stored_by_key(session, exploration_id, [q.key() for s in seqs.values() for q in s])
    return racing.assess(points, samples, seqs.__getitem__, stored,
                         level=spec.certification.level, engines=spec.draw_engines())


def _labels_at(computed: ComputedMap) -> dict[Point, int]:
    """The map's label of every finest point: a stored pose's manifold (−1 where it did not
    hold), else the interpolated fine label."""
    out = {p: int(x) for p, x in zip(computed.fine.points, computed.fine.labels, strict=True)}
    for p, s in computed.samples.items():
        if p in out:
            out[p] = computed.label_of.get(p, -1) if s.viable else -1
    return out


def _ids_of_keys(session: Session, exploration_id: int, keys: set[str]) -> dict[int, str]:
    out: dict[int, str] = {}
    for chunk in _chunks(sorted(keys)):
        out.update(session.execute(select(PoseRow.id, PoseRow.pose_key).where(
            PoseRow.exploration_id == exploration_id, PoseRow.pose_key.in_(chunk))).all())
    return out


# --- what a finished exploration claims ------------------------------------------------------
class CertifiedBest(BaseModel):
    """The pick of one large manifold by P(success) (its raced candidate with the highest
    lower bound; the robust best where none has draws), with what backs it."""

    label: str = Field(description="the manifold's name (A, B, …)")
    volume_cm3: float
    volume_share: float = Field(description="share of the viable volume")
    core_volume_cm3: float | None = Field(description="its robust core's volume, where stored")
    pose: Pose
    key: str
    s: float | None = Field(description="s_δ: share of N_δ ∪ {p} held with p's grasp type")
    q: float | None = Field(description="q_δ: mean μs over N_δ ∪ {p}, 0 where not so held")
    mu_s: float
    robust_label: str | None
    neighbours: int = Field(description="|N_δ|")
    known: int = Field(description="members of N_δ stored (evaluated or inferred)")
    held: int = Field(description="known members held with p's grasp type")
    jitters: int = Field(description="n: draws of the uncertainty model evaluated around p")
    jitters_held: int = Field(description="k: of those, held with p's grasp type")
    p_success: float | None = Field(default=None, description="k / n")
    lower: float | None = Field(
        default=None, description="anytime-valid 95 % lower bound of P(success)")
    upper: float | None = Field(
        default=None, description="anytime-valid 95 % upper bound of P(success)")
    level: float = Field(default=0.9, description="the certification level")
    model: str = Field(default="", description="the uncertainty model the numbers are under")
    certified: bool = Field(
        description="lower bound ≥ level at 95 % confidence under the stated model")


def jitter_samples(session: Session, exploration_id: int, centres: Sequence[str]
                   ) -> dict[str, list[StoredPose]]:
    """Stored jitters by the key of the pose they certify."""
    out: dict[str, list[StoredPose]] = {}
    for chunk in _chunks(sorted(set(centres))):
        for row in session.scalars(select(PoseRow).where(
                PoseRow.exploration_id == exploration_id, PoseRow.certifies.in_(chunk))):
            out.setdefault(row.certifies, []).append(StoredPose.from_row(row))
    return out


class RobustSummary(BaseModel):
    """The large manifolds' picks, and the rest of the map as one line."""

    bests: list[CertifiedBest]
    dust_count: int = Field(description="manifolds under 1 % of the viable volume")
    dust_volume_cm3: float


def robust_summary(session: Session, exploration_id: int) -> RobustSummary:
    bests, dust_count, dust_volume = _bests(session, exploration_id)
    return RobustSummary(bests=bests, dust_count=dust_count, dust_volume_cm3=dust_volume)


def certified_bests(session: Session, exploration_id: int,
                    samples: Mapping[Point, StoredPose] | None = None) -> list[CertifiedBest]:
    """The pick of every large manifold of the stored manifold table, largest first, with
    its evidence (the manifold table must be current: manifolds.service.ensure_manifolds)."""
    return _bests(session, exploration_id, samples)[0]


def _bests(session: Session, exploration_id: int,
           samples: Mapping[Point, StoredPose] | None = None
           ) -> tuple[list[CertifiedBest], int, float]:
    row = session.get(ExplorationRow, exploration_id)
    if row is None:
        return [], 0, 0.0
    spec = spec_of(row)
    lattice: Lattice = lattice_of(spec)
    samples = samples if samples is not None else load_samples(session, exploration_id, lattice)
    rows = session.scalars(select(ManifoldRow).where(
        ManifoldRow.exploration_id == exploration_id).order_by(ManifoldRow.label)).all()
    point_of = {s.key: p for p, s in samples.items()}
    members: dict[int, list[Point]] = {}
    for key, mid in session.execute(select(PoseRow.pose_key, PoseRow.manifold_id).where(
            PoseRow.exploration_id == exploration_id, PoseRow.manifold_id.is_not(None))):
        if key in point_of:
            members.setdefault(mid, []).append(point_of[key])
    volume = {r.id: float((r.summary or {}).get("volume_cm3", 0.0)) for r in rows}
    chosen = [certify.Manifold(r.id, tuple(sorted(members.get(r.id, [])))) for r in rows
              if r.large]
    viable_volume = sum(volume.values())
    large_ids = {m.label for m in chosen}
    dust = [v for mid, v in volume.items() if mid not in large_ids]
    scores = robust_scores(lattice, samples, [p for m in chosen for p in m.members])
    mesh = object_mesh(session, row.object_id)

    def radius(p: Point) -> float:
        return float(surface_radii(mesh, np.array([lattice.direction(p)]), FALLBACK_RADIUS)[0])

    by_id = {r.id: r for r in rows}
    out = []
    for m in chosen:
        cands = _candidates(session, exploration_id, spec, samples, m.members, scores, radius)
        pick = racing.best(cands)
        stored = by_id[m.label].robust_best_key
        p = pick.point if pick is not None else point_of.get(stored) if stored else None
        p = p if p is not None else certify.robust_best(m.members, samples, scores)
        if p is None:
            continue
        out.append(_best(lattice, samples, p, scores.get(p), pick, by_id[m.label],
                         volume[m.label], viable_volume, spec))
    return out, len(dust), sum(dust)


def _best(lattice: Lattice, samples: Mapping[Point, StoredPose], p: Point,
          score: RobustScore | None,
          pick: racing.Candidate | None, mrow: ManifoldRow, volume: float,
          viable_volume: float, spec: ExplorationSpec) -> CertifiedBest:
    s = samples[p]
    ev = certify.evidence(lattice, samples, p, score, [], jitters_asked=False)
    e = pick.estimate if pick is not None and pick.point == p else None
    model = spec.uncertainty
    clears = e is not None and e.certified
    core = mrow.core_volume_cm3
    return CertifiedBest(
        label=(mrow.summary or {}).get("name", str(mrow.label)), volume_cm3=volume,
        volume_share=volume / viable_volume if viable_volume else 0.0,
        core_volume_cm3=None if core is None else float(core),
        pose=Pose(theta=s.theta, phi=s.phi, r=s.r, roll=s.roll, pitch=s.pitch, yaw=s.yaw),
        key=s.key, s=None if score is None else score.s,
        q=None if score is None else score.q, mu_s=s.mu_s, robust_label=ev.label,
        neighbours=ev.neighbours, known=ev.known, held=ev.held,
        jitters=0 if e is None else e.n, jitters_held=0 if e is None else e.k,
        p_success=None if e is None or not e.n else e.p,
        lower=None if e is None else e.lower, upper=None if e is None else e.upper,
        level=spec.certification.level, model=model.describe(),
        certified=clears)


def format_best(b: CertifiedBest) -> str:
    """One line of `graspscape explore`'s closing table."""
    core = "?" if b.core_volume_cm3 is None else f"{b.core_volume_cm3:.1f}"
    s = "?" if b.s is None else f"{b.s:.2f}"
    where = (f"θ {math.degrees(b.pose.theta):.1f}° φ {math.degrees(b.pose.phi):.1f}° "
             f"r {1000 * b.pose.r:.1f} mm roll {math.degrees(b.pose.roll):.0f}°")
    if b.lower is None or b.upper is None or not b.jitters:
        chance = "P(success) not sampled"
    else:
        chance = (f"P(success) {b.jitters_held}/{b.jitters} = {b.p_success:.2f}, 95 % bounds "
                  f"[{b.lower:.2f}, {b.upper:.2f}]")
    return (f"  {b.label}: {b.volume_cm3:.1f} cm³ ({100 * b.volume_share:.0f} %), core {core} "
            f"cm³; s {s}, μs {b.mu_s:.3f} at {where}; {chance}; {_claim(b)}")


def _claim(b: CertifiedBest) -> str:
    if b.certified:
        return f"certified: P ≥ {b.level:g} at 95 % under {b.model}"
    if b.upper is not None and b.upper < b.level:
        return f"not certified: P < {b.level:g} at 95 %"
    return f"not certified: undecided at P ≥ {b.level:g}"
