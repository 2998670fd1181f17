"""The manifold table of one exploration from its samples (pure).

Labels are stable: components are ordered by volume (largest first), ties by their smallest
pose key, then named A, B, C… The best grasp is the member with the highest μs (ties: the
smaller key); local maxima are those of `refine.local_maxima`.
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
from pydantic import BaseModel


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


class ManifoldMap(BaseModel):
    """Everything the manifold table, the API and the pictures need."""

    model_config = {"arbitrary_types_allowed": True}

    manifolds: list[ManifoldSummary]
    assignment: dict[str, int]  # pose key → label
    non_viable_volume_cm3: float


def build_map(
    lattice: Lattice,
    samples: Mapping[Point, StoredPose],
    radius: Callable[[np.ndarray], np.ndarray],
    *,
    maxima_per_manifold: int = 3,
) -> tuple[ManifoldMap, FineLabels, dict[Point, int]]:
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

    out = []
    for old in order:
        members = comps[old]
        ss = [samples[p] for p in members]
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
            )
        )
    mask = fine.labels < 0
    _, first = np.unique(fine.position_ids[mask], return_index=True)
    non_viable = float(fine.weights[mask][first].sum()) * 1e6
    result = ManifoldMap(
        manifolds=out,
        assignment={samples[p].key: label for p, label in label_of.items()},
        non_viable_volume_cm3=round(non_viable, 3),
    )
    return result, fine, label_of


def table_rows(m: ManifoldMap) -> list[dict[str, Any]]:
    """The manifold table as plain rows (docs, JSON export)."""
    return table_rows_of(m.manifolds)


def table_rows_of(manifolds: list[ManifoldSummary]) -> list[dict[str, Any]]:
    return [
        {
            "label": s.name,
            "description": s.description,
            "poses": s.pose_count,
            "evaluated": s.evaluated_count,
            "volume_cm3": s.volume_cm3,
            "mu_s_mean": round(s.mu_s_mean, 4),
            "mu_s_max": round(s.mu_s_max, 4),
            "best": s.best.key,
        }
        for s in manifolds
    ]
