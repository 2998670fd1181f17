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

from collections.abc import Callable, Mapping
from typing import Any

import numpy as np
from graspscape.services.coordinator.manifolds.aggregate import Stats
from graspscape.services.coordinator.manifolds.behaviour import StoredPose
from graspscape.services.coordinator.manifolds.grouping import (
    FineLabels,
    components,
    exact_volume,
    fine_grid,
    fine_labels,
    label_name,
    volumes,
)
from graspscape.services.coordinator.manifolds.robust import (
    LARGE_SHARE,
    ROBUST_MIN,
    Neighbourhoods,
    RobustLabel,
    RobustScore,
    large_manifolds,
    robust_core,
    robust_scores,
)
from graspscape.services.coordinator.mapspace.lattice import Lattice, Point
from graspscape.services.coordinator.mapspace.maxima import local_maxima
from graspscape.services.coordinator.mapspace.pose import PoseValues
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
# An uncertain pose whose bound s_high is under ROBUST_MIN cannot turn out robust, whatever its
# unknown neighbours hold: it ranks after the poses known to be fragile (a known answer before
# an unknown one that is no better), before the futile ones. Ranked at 1 it was returned as
# the robust best over the evaluated fragile best (mustard bottle: regret 0.34).
CANNOT_BE_ROBUST = 2.5


def robust_order(s: StoredPose, sc: RobustScore) -> tuple[float, float, float, str]:
    """Sort key of the robust ranking, best first: the label's rank (`LABEL_ORDER`, uncertain
    poses that cannot be robust at `CANNOT_BE_ROBUST`), then q_δ, μs and the key."""
    rank: float = LABEL_ORDER[sc.label]
    if sc.label is RobustLabel.UNCERTAIN and sc.s_high < ROBUST_MIN - 1e-12:
        rank = CANNOT_BE_ROBUST
    return (rank, -sc.q, -s.mu_s, s.key)


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


def summary_of(
    label: int, stats: Stats, volume_m3: float, best: StoredPose, mu_min: float,
    maxima: list[StoredPose], core_count: int, core_volume_m3: float,
    robust_top: tuple[StoredPose, RobustScore], large: bool,
) -> ManifoldSummary:
    """A manifold's summary from its sums and extremes (the full recompute's and the running
    map's, manifolds/running.py: the same fields from the same numbers)."""
    return ManifoldSummary(
        label=label,
        name=label_name(label),
        description=stats.description(),
        digits=stats.majority(),
        pose_count=stats.count,
        evaluated_count=stats.evaluated,
        volume_cm3=round(volume_m3 * 1e6, 3),
        mu_s_min=mu_min,
        mu_s_mean=stats.mu_mean(),
        mu_s_max=best.mu_s,
        mu_s_std=stats.mu_std(),
        best=PoseBrief.of(best),
        local_maxima=[PoseBrief.of(m) for m in maxima],
        core_count=core_count,
        core_volume_cm3=round(core_volume_m3 * 1e6, 3),
        robust_best=RobustBrief.of_score(*robust_top),
        large=large,
    )


def label_order(vols: list[float], first_keys: list[str]) -> list[int]:
    """Component indices in label order: by volume (largest first), ties by the key of the
    component's smallest point."""
    return sorted(range(len(vols)), key=lambda i: (-round(vols[i], 12), first_keys[i]))


def build_map(
    lattice: Lattice,
    samples: Mapping[Point, StoredPose],
    radius: Callable[[np.ndarray], np.ndarray],
    *,
    maxima_per_manifold: int = 3,
    comps: list[list[Point]] | None = None,
) -> tuple[ManifoldMap, FineLabels, dict[Point, int]]:
    """The whole map computed at once (the running map, manifolds/running.py, keeps the same
    one up to date batch by batch). `comps`: `grouping.components(lattice, samples)` where
    the caller has it; computed here when not given."""
    if comps is None:
        comps = components(lattice, samples)
    provisional = {p: i for i, comp in enumerate(comps) for p in comp}
    grid = fine_grid(lattice, radius)
    fine = fine_labels(lattice, samples, provisional, radius, grid)
    vols = volumes(fine, len(comps), grid)
    order = label_order(vols, [samples[c[0]].key for c in comps])
    relabel = {old: new for new, old in enumerate(order)}
    label_of = {p: relabel[i] for p, i in provisional.items()}
    fine.labels[:] = [relabel[int(x)] if x >= 0 else -1 for x in fine.labels]

    def lookup(p: Point) -> StoredPose | None:
        return samples.get(p)

    hood = Neighbourhoods(lattice)  # N_δ at the finest step, shared by scores and cores
    scores = robust_scores(lattice, samples, hood=hood)
    viable_volume = exact_volume(grid, np.unique(fine.position_ids[fine.labels >= 0]))
    large = set(large_manifolds([vols[i] for i in order], viable_volume, LARGE_SHARE))
    out = []
    for old in order:
        members = comps[old]
        ss = [samples[p] for p in members]
        core = robust_core(lattice, samples, members, hood=hood)
        top = min(members, key=lambda p: robust_order(samples[p], scores[p]))
        maxima = local_maxima(lattice, members, lookup, top=maxima_per_manifold)
        label = relabel[old]
        out.append(summary_of(
            label, Stats.of(ss), vols[old], min(ss, key=lambda s: (-s.mu_s, s.key)),
            min(s.mu_s for s in ss), [samples[p] for p in maxima], len(core),
            exact_volume(grid, {grid.position(p) for p in core}),
            (samples[top], scores[top]), label in large))
    non_viable = exact_volume(grid, np.unique(fine.position_ids[fine.labels < 0]))
    result = ManifoldMap(
        manifolds=out,
        assignment={samples[p].key: label for p, label in label_of.items()},
        non_viable_volume_cm3=round(non_viable * 1e6, 3),
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
