"""The grid strategy: every pose of the dense lattice at its finest level, nothing adaptive.

The reference an adaptive exploration is measured against (benchmarks/
bench_exploration_accuracy.py): with `refinement.levels` = D, Δθ and Δr halved D times
everywhere. Batches lead to no more work; the manifolds are computed on request, as for a
coarse-only adaptive exploration. Shortcuts are not applied.
"""

from __future__ import annotations

from graspscape.services.coordinator.exploration.samples import lattice_of
from graspscape.services.coordinator.exploration.strategies.base import Batch, Planned, Stage
from graspscape.services.coordinator.exploration.tiling import TilePlan, dense_tiles
from graspscape.shared.specs.exploration import ExplorationSpec
from sqlalchemy.orm import Session


class GridStrategy:
    reacts = False
    has_rounds = False

    def __init__(self, spec: ExplorationSpec) -> None:
        self.lattice = lattice_of(spec)

    def planned_poses(self) -> int:
        lattice = self.lattice
        return (len(lattice.cells(lattice.depth)) * (lattice.n_r * lattice.scale(0) + 1)
                * len(lattice.attitudes))

    def initial_work(self, session: Session, *, target_poses: int) -> list[TilePlan]:
        return dense_tiles(self.lattice, target_poses=target_poses)

    def after_batch(self, batch: Batch) -> list[Planned]:
        return []

    def next_round(self, batch: Batch) -> list[Planned]:
        return []

    def progress(self, batch: Batch, stage: Stage) -> None:
        return None
