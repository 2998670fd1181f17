"""The seeded strategy of an exploration on a table (`support.seed_exploration`): the viable
poses of a free-object map of the same object, gripper, grid and lattice depth, evaluated
once on the table at this exploration's resting pose. The free map tells where grasps are;
the table changes whether they still form (reached, knocked over, held), so its poses are
simulated again, not copied. Starts whose palm centre lies under the table are skipped
here, without simulation (the workers count the other starts that reach into the table).
The poses are lattice points of this exploration, so its manifolds are grouped as usual."""

from __future__ import annotations

from graspscape.services.coordinator.exploration.strategies.base import Batch, Planned, Stage
from graspscape.services.coordinator.exploration.support import seed_poses
from graspscape.services.coordinator.exploration.tiling import TilePlan, group_tiles
from graspscape.shared.specs.exploration import ExplorationSpec
from sqlalchemy.orm import Session


class SeededStrategy:
    reacts = False
    has_rounds = False

    def __init__(self, spec: ExplorationSpec) -> None:
        self.spec = spec
        self._planned = 0

    def planned_poses(self) -> int:
        """The poses `initial_work` planned (the scheduler asks after it)."""
        return self._planned

    def initial_work(self, session: Session, *, target_poses: int) -> list[TilePlan]:
        poses = seed_poses(session, self.spec)
        self._planned = len(poses)
        return group_tiles(poses, target_poses=target_poses)

    def after_batch(self, batch: Batch) -> list[Planned]:
        return []

    def next_round(self, batch: Batch) -> list[Planned]:
        return []

    def progress(self, batch: Batch, stage: Stage) -> None:
        return None
