"""The random strategy: a seeded uniform sample of the pose space, in rounds.

Directions are uniform on the sphere (z = cos θ uniform in [-1, 1], φ uniform), start gaps
uniform in [r_min, r_max], attitudes uniform over the grid's list. Tiles are what workers
evaluate (cells × r levels × attitudes), so each block of BLOCK directions shares one drawn r
and attitude: every pose is still uniform over the space, the poses of one block are not
independent. The whole sample is a function of the spec alone (seed, budget, grid), drawn
with its own generator, so it is repeatable whatever the workers do; round k
hands out the k-th of `rounds` equal slices once the slices before are stored. The poses are
off the lattice: they are stored and listed, not grouped into manifolds
(docs/design/exploration.md).
"""

from __future__ import annotations

import math
import random

from graspscape.services.coordinator.exploration.strategies.base import Batch, Planned, Stage
from graspscape.services.coordinator.exploration.tiling import TilePlan, group_tiles
from graspscape.services.coordinator.store.models import TileRow
from graspscape.shared.specs.exploration import ExplorationSpec
from graspscape.shared.specs.pose import Pose
from graspscape.shared.specs.strategies import RandomStrategySpec
from sqlalchemy import func, select
from sqlalchemy.orm import Session

# Directions drawn per (r, attitude) draw: a tile's worth at the default tile size. Fixed, so
# the sample does not depend on the coordinator's tile size setting.
BLOCK = 100


def random_poses(spec: ExplorationSpec, strategy: RandomStrategySpec) -> list[Pose]:
    """The whole sample, in drawing order: blocks of BLOCK directions, each sharing one r and
    one attitude."""
    rng = random.Random(strategy.seed)
    grid = spec.grid
    attitudes = grid.attitudes.attitudes()
    poses: list[Pose] = []
    while len(poses) < strategy.poses:
        r = rng.uniform(grid.r_min, grid.r_max)
        roll, pitch, yaw = attitudes[rng.randrange(len(attitudes))]
        for _ in range(min(BLOCK, strategy.poses - len(poses))):
            theta = math.acos(rng.uniform(-1.0, 1.0))
            phi = rng.uniform(0.0, 2 * math.pi)
            poses.append(Pose(theta=theta, phi=phi, r=r, roll=roll, pitch=pitch, yaw=yaw))
    return poses


class RandomStrategy:
    has_rounds = True

    def __init__(self, spec: ExplorationSpec) -> None:
        assert isinstance(spec.strategy, RandomStrategySpec)
        self.spec = spec
        self.strategy = spec.strategy
        # One round: everything is queued at submission, no batch leads to more work.
        self.reacts = self.strategy.rounds > 1

    def planned_poses(self) -> int:
        return self.strategy.poses

    def _round(self, k: int) -> list[Pose]:
        sample = random_poses(self.spec, self.strategy)
        size = math.ceil(len(sample) / self.strategy.rounds)
        return sample[k * size : (k + 1) * size]

    def initial_work(self, session: Session, *, target_poses: int) -> list[TilePlan]:
        return group_tiles(self._round(0), target_poses=target_poses)

    def after_batch(self, batch: Batch) -> list[Planned]:
        return []

    def next_round(self, batch: Batch) -> list[Planned]:
        rounds_done = 1 + (batch.session.scalar(
            select(func.max(TileRow.round)).where(TileRow.exploration_id == batch.exploration_id)
        ) or 0)
        if rounds_done >= self.strategy.rounds:
            return []
        return [Planned(pose, plan_level=0, tile_level=0, reason="random", round=rounds_done,
                        counted=False)
                for pose in self._round(rounds_done)]

    def progress(self, batch: Batch, stage: Stage) -> None:
        return None  # the poses are listed as they arrive; no manifolds to refresh
