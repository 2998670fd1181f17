"""The manifold table of one exploration from its samples (pure).

Labels are stable: components are ordered by volume (largest first), ties by their smallest
pose key, then named A, B, C… The best grasp is the member with the highest μs (ties: the
smaller key); local maxima are those of `refine.local_maxima`.

The robust map (manifolds/robust.py) rides along: every sample's robust score over N_δ (the
finest step), per manifold its robust core (count and volume, measured on the finest lattice
like the manifold's own volume) and its robust best grasp (`robust_order`: robust-labelled
members first, then uncertain, fragile, futile; within each the highest q_δ, then μs, then the
smaller key), and whether it is large (≥ 1 % of the viable volume). The table shows the
manifolds that are not large as one dust line (`table_rows_of`).
"""

from __future__ import annotations

import statistics
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np
from graspscape.services.coordinator.exploration.lattice import Lattice, Point
from graspscape.services.coordinator.exploration.refine import local_maxima
from graspscape.services.coordinator.exploration.schemas import PoseValues
from graspscape.services.coordinator.manifolds.behaviour import StoredPose
from graspscape.services.coordinator.manifolds.grouping import (
    FineLabels,
    components,
    describe,
    fine_labels,
    label_name,
    volumes,
)
from graspscape.services.coordinator.manifolds.robust import (
    LARGE_SHARE,
    Neighbourhoods,
    RobustLabel,
    RobustScore,
    large_manifolds,
    robust_core,
    robust_scores,
)
from pydantic import BaseModel, Field


class _Keyed(BaseModel):
    key: str


# Bases in this order put `key` first, as manifold tables have always been written.
class PoseBrief(PoseValues, _Keyed):
    """A pose of the map by its key (the stored pose is GET …/poses?…, the same values)."""

    @staticmethod
    def of(s: StoredPose) -> PoseBrief:
        return PoseBrief(
            key=s.key, theta=s.theta, phi=s.phi, r=s.r, roll=s.roll, pitch=s.pitch, yaw=s.yaw,
            mu_s=s.mu_s, effort_max_nm=s.effort,
        )


class RobustBrief(PoseBrief):
    """A pose with its robust score over N_δ (manifolds/robust.py)."""

    s: float = Field(description="robust success s_δ: share of N_δ ∪ {p} held with its type")
    q: float = Field(description="robust quality q_δ: mean μs over N_δ ∪ {p}, 0 off the type")
    robust_label: str = Field(description="robust, fragile, futile or uncertain")
    known: int = Field(description="members of N_δ ∪ {p} stored")
    total: int = Field(description="members of N_δ ∪ {p}")

    @staticmethod
    def of_score(s: StoredPose, sc: RobustScore) -> RobustBrief:
        return RobustBrief(**PoseBrief.of(s).model_dump(), s=sc.s, q=sc.q,
                           robust_label=sc.label.value, known=sc.known, total=sc.total)


# Where each label ranks when choosing a robust best: a pose known to be robust first, one
# that may be (uncertain) before one known not to be.
LABEL_ORDER = {RobustLabel.ROBUST: 0, RobustLabel.UNCERTAIN: 1, RobustLabel.FRAGILE: 2,
               RobustLabel.FUTILE: 3}


def robust_order(s: StoredPose, sc: RobustScore) -> tuple[int, float, float, str]:
    """Sort key of the robust ranking, best first."""
    return (LABEL_ORDER[sc.label], -sc.q, -s.mu_s, s.key)


class ManifoldSummary(BaseModel):
    label: int
    name: str
    description: str
    digits: list[str]
    pose_count: int
    evaluated_count: int
    volume_cm3: float
    mu_s_min: float
    mu_s_mean: float
    mu_s_max: float
    mu_s_std: float
    best: PoseBrief
    local_maxima: list[PoseBrief]
    # The robust map (defaults: summaries stored before it; migration 0010 recomputes them).
    core_count: int = Field(default=0, description="members in the robust core")
    core_volume_cm3: float | None = Field(
        default=None, description="volume of the robust core (members whose whole N_δ is "
        "stored and in this manifold)")
    robust_best: RobustBrief | None = Field(
        default=None, description="the best member by the robust ranking")
    large: bool = Field(default=True, description="at least 1 % of the viable volume")


class ManifoldMap(BaseModel):
    """Everything the manifold table, the API and the pictures need."""

    model_config = {"arbitrary_types_allowed": True}

    manifolds: list[ManifoldSummary]
    assignment: dict[str, int]  # pose key → label
    non_viable_volume_cm3: float
    viable_volume_cm3: float = 0.0  # every position labelled viable, once
    robust: dict[str, RobustScore] = Field(default_factory=dict)  # pose key → score


def _position_volume(lattice: Lattice, fine: FineLabels, points: set[Point]) -> float:
    """m³ of the finest-lattice positions of `points` (a position once, whatever attitudes):
    the weights `fine_labels` gives them, found by its layout (cells × r indices × attitudes)."""
    if not points:
        return 0.0
    cell = {kj: c for c, kj in enumerate(lattice.cells(lattice.depth))}
    n_i = (lattice.n_r << lattice.depth) + 1
    n_a = len(lattice.attitudes)
    positions = {cell[(p.ring, p.azimuth)] * n_i + p.r_index for p in points}
    return float(sum(fine.weights[pos * n_a] for pos in positions))


def build_map(
    lattice: Lattice,
    samples: Mapping[Point, StoredPose],
    radius: Callable[[np.ndarray], np.ndarray],
    *,
    maxima_per_manifold: int = 3,
    comps: list[list[Point]] | None = None,
) -> tuple[ManifoldMap, FineLabels, dict[Point, int]]:
    """`comps`: `grouping.components(lattice, samples)` where the caller keeps it current
    (manifolds/incremental.py); computed here when not given."""
    if comps is None:
        comps = components(lattice, samples)
    provisional = {p: i for i, comp in enumerate(comps) for p in comp}
    fine = fine_labels(lattice, samples, provisional, radius)
    vols = volumes(fine, len(comps))
    order = sorted(range(len(comps)), key=lambda i: (-round(vols[i], 12), samples[comps[i][0]].key))
    relabel = {old: new for new, old in enumerate(order)}
    label_of = {p: relabel[i] for p, i in provisional.items()}
    fine.labels[:] = [relabel[int(x)] if x >= 0 else -1 for x in fine.labels]

    def lookup(p: Point) -> StoredPose | None:
        return samples.get(p)

    hood = Neighbourhoods(lattice)  # N_δ at the finest step, shared by scores and cores
    scores = robust_scores(lattice, samples, hood=hood)
    viable_mask = fine.labels >= 0
    _, first = np.unique(fine.position_ids[viable_mask], return_index=True)
    viable_volume = float(fine.weights[viable_mask][first].sum())
    large = set(large_manifolds([vols[i] for i in order], viable_volume, LARGE_SHARE))
    out = []
    for old in order:
        members = comps[old]
        ss = [samples[p] for p in members]
        core = robust_core(lattice, samples, members, hood=hood)
        top = min(members, key=lambda p: robust_order(samples[p], scores[p]))
        mus = [s.mu_s for s in ss]
        best = min(ss, key=lambda s: (-s.mu_s, s.key))
        maxima = local_maxima(lattice, members, lookup, top=maxima_per_manifold)
        digit_count: dict[frozenset[str], int] = {}
        for s in ss:
            digit_count[s.digits] = digit_count.get(s.digits, 0) + 1
        digits = sorted(max(digit_count.items(), key=lambda kv: (kv[1], sorted(kv[0])))[0])
        label = relabel[old]
        out.append(
            ManifoldSummary(
                label=label,
                name=label_name(label),
                description=describe(ss),
                digits=digits,
                pose_count=len(ss),
                evaluated_count=sum(1 for s in ss if s.source == "evaluated"),
                volume_cm3=round(vols[old] * 1e6, 3),
                mu_s_min=min(mus),
                mu_s_mean=statistics.fmean(mus),
                mu_s_max=max(mus),
                mu_s_std=statistics.pstdev(mus),
                best=PoseBrief.of(best),
                local_maxima=[PoseBrief.of(samples[p]) for p in maxima],
                core_count=len(core),
                core_volume_cm3=round(_position_volume(lattice, fine, core) * 1e6, 3),
                robust_best=RobustBrief.of_score(samples[top], scores[top]),
                large=label in large,
            )
        )
    mask = fine.labels < 0
    _, first = np.unique(fine.position_ids[mask], return_index=True)
    non_viable = float(fine.weights[mask][first].sum()) * 1e6
    result = ManifoldMap(
        manifolds=out,
        assignment={samples[p].key: label for p, label in label_of.items()},
        non_viable_volume_cm3=round(non_viable, 3),
        viable_volume_cm3=round(viable_volume * 1e6, 3),
        robust={samples[p].key: sc for p, sc in scores.items()},
    )
    return result, fine, label_of


def table_rows(m: ManifoldMap) -> list[dict[str, Any]]:
    """The manifold table as plain rows (docs, JSON export)."""
    return table_rows_of(m.manifolds)


def table_rows_of(manifolds: list[ManifoldSummary]) -> list[dict[str, Any]]:
    """One row per large manifold, then the dust (every manifold under 1 % of the viable
    volume) as one row: how many, their poses and total volume."""
    rows: list[dict[str, Any]] = []
    for s in manifolds:
        if not s.large:
            continue
        rb = s.robust_best
        rows.append({
            "label": s.name,
            "description": s.description,
            "poses": s.pose_count,
            "evaluated": s.evaluated_count,
            "volume_cm3": s.volume_cm3,
            "core_volume_cm3": s.core_volume_cm3,
            "mu_s_mean": round(s.mu_s_mean, 4),
            "mu_s_max": round(s.mu_s_max, 4),
            "best": s.best.key,
            "robust_best": rb.key if rb else None,
            "robust_best_q": round(rb.q, 4) if rb else None,
            "robust_best_s": round(rb.s, 4) if rb else None,
            "robust_best_label": rb.robust_label if rb else None,
        })
    dust = [s for s in manifolds if not s.large]
    if dust:
        rows.append({
            "label": "dust",
            "description": f"{len(dust)} manifolds under {LARGE_SHARE:.0%} of the viable "
                           "volume each",
            "manifolds": len(dust),
            "poses": sum(s.pose_count for s in dust),
            "evaluated": sum(s.evaluated_count for s in dust),
            "volume_cm3": round(sum(s.volume_cm3 for s in dust), 3),
            "core_volume_cm3": round(sum(s.core_volume_cm3 or 0.0 for s in dust), 3),
            "mu_s_max": round(max(s.mu_s_max for s in dust), 4),
        })
    return rows


def dust_line(manifolds: list[ManifoldSummary]) -> dict[str, Any] | None:
    """The manifolds that are not large, as one entry (None where there are none)."""
    small = [m for m in manifolds if not m.large]
    if not small:
        return None
    return {"manifolds": len(small), "poses": sum(m.pose_count for m in small),
            "volume_cm3": round(sum(m.volume_cm3 for m in small), 3)}


def table_text(manifolds: list[ManifoldSummary]) -> str:
    """The manifold table as text lines (`graspscape map show`): one line per large manifold
    with its volume, robust core and robust best, then the dust as one line."""
    lines = []
    for row in table_rows_of(manifolds):
        if row["label"] == "dust":
            lines.append(f"dust: {row['manifolds']} manifolds, {row['poses']} poses, "
                         f"{row['volume_cm3']:.1f} cm³ in all")
            continue
        best = (f"robust best {row['robust_best']} (s {row['robust_best_s']:.2f}, "
                f"q {row['robust_best_q']:.3f}, {row['robust_best_label']})"
                if row["robust_best"] else "no robust best")
        core = row["core_volume_cm3"]
        lines.append(f"{row['label']}: {row['poses']} poses, {row['volume_cm3']:.1f} cm³, "
                     f"core {core if core is not None else float('nan'):.1f} cm³, "
                     f"max μs {row['mu_s_max']:.3f}; {best}")
    return "\n".join(lines)
