"""What an exploration strategy is: the one interface the scheduler drives.

A strategy decides which poses to evaluate; everything else is shared and stays with the
scheduler and the store: the workers (tiles leased over zenoh or in-process), storage (pose
rows, plans, tiles, counters), determinism (decisions read only stored results, never arrival
order) and progress reporting (poses_total, manifold refreshes). The scheduler calls, all in
the transaction that stores a batch:

- `planned_poses()` and `initial_work()` once, at submission: the pose count for progress
  and limits, and the first tiles;
- `after_batch(batch)` for every stored batch that changed something (when `reacts`):
  poses to evaluate next, decided from what is stored now;
- `next_round(batch)` when that batch finished the exploration's last open tile (when
  `has_rounds`): the next round of work, or nothing when the strategy is finished;
- `progress(batch, stage)` after each finished tile (when `has_rounds`): the strategy's
  report on itself (the adaptive strategy refreshes the manifolds).

A strategy that proposes continuous poses and learns from results in batches (CMA-ES, PPO)
fits the same calls: its `after_batch`/`next_round` read the batch's results (`batch.results`,
typed, as the worker sent them) or the stored poses, update its state, and return `Planned`
poses anywhere in the pose space. Its state must be a function of the stored results (reload
it from the store, or store it), so that a coordinator restart or another interleaving of
workers gives the same exploration.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from datetime import datetime
from enum import StrEnum
from typing import Protocol

from graspscape.services.coordinator.exploration.tiling import TilePlan
from graspscape.shared.specs.exploration import ExplorationSpec
from graspscape.shared.specs.pose import Pose
from graspscape.shared.specs.results import DrawScales, PoseResult
from sqlalchemy.orm import Session


@dataclass(frozen=True)
class Planned:
    """A pose a strategy wants evaluated. `plan_level` is stored with its plan (pose_plans);
    its tile goes to `round` and `tile_level`, which order the queue (tiles are leased by
    round, then level, then id); `reason` is stored with the plan ("refine", "search", …);
    `counted`: whether it adds to the exploration's poses_total (False where
    `planned_poses` counted it already); `draw_engines`: a success probability's draw,
    evaluated outcome only in each of these engines under `draw_scales` (None: a full
    evaluation)."""

    pose: Pose
    plan_level: int
    tile_level: int
    reason: str
    round: int = 0
    counted: bool = True
    draw_engines: tuple[str, ...] | None = None
    draw_scales: DrawScales | None = None


@dataclass(frozen=True)
class Batch:
    """A stored batch, as the scheduler hands it to the strategy (inside its transaction)."""

    session: Session
    exploration_id: int
    spec: ExplorationSpec
    results: Sequence[PoseResult]
    tile_moved: bool
    now: datetime
    target_poses: int


class Stage(StrEnum):
    RUNNING = "running"  # tiles are still open
    NEW_ROUND = "new_round"  # none was open; next_round queued more work
    FINISHED = "finished"  # none is open and next_round had nothing more


class Strategy(Protocol):
    reacts: bool  # a stored batch can lead to more work or a report
    has_rounds: bool  # next_round and progress are called when tiles finish

    def planned_poses(self) -> int: ...

    def initial_work(self, session: Session, *, target_poses: int) -> list[TilePlan]: ...

    def after_batch(self, batch: Batch) -> list[Planned]: ...

    def next_round(self, batch: Batch) -> list[Planned]: ...

    def progress(self, batch: Batch, stage: Stage) -> None: ...
